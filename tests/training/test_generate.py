"""The dataset command end to end on Ray: a tiny run from the command line, resuming (nothing made
again, a corrupt shard made again, rooms of an unfinished shard kept), determinism, the manifest; and
the physical truth it stores."""

from __future__ import annotations

import io
import json
import zipfile

import numpy as np
import pytest

pytest.importorskip("ray", reason="the dataset command runs on Ray (pip install ray)")

from viewer.physical import gi  # noqa: E402
from viewer.training import dataset, dataset_cli, generate, shards, truth  # noqa: E402

ARGS = ["--train", "3", "--val", "1", "--splits", "val,train", "--seed", "3", "--probes", "8,4", "--voxels", "16",
        "--directions", "32", "--shard-size", "2", "--workers", "2"]


def room_arrays(ref: str) -> dict[str, np.ndarray]:
    path, _, room = ref.partition("#")
    with zipfile.ZipFile(path) as archive, np.load(io.BytesIO(archive.read(f"{room}.npz"))) as data:
        return {k: data[k] for k in data.files if k != "seconds"}


@pytest.fixture(scope="module")
def made(tmp_path_factory):
    """The command, run once: 1 val room and 3 train rooms in shards of 2, on two local Ray workers."""
    root = tmp_path_factory.mktemp("gi-v2-tiny")
    assert dataset_cli.main(["--out", str(root), *ARGS]) == 0
    return root, {ref.partition("#")[2]: room_arrays(ref) for split in ("val", "train")
                  for ref in dataset.room_refs(root, split)}


def settings_of(root) -> shards.Settings:
    """The settings of ARGS (the manifest's)."""
    fingerprint = json.loads((root / "manifest.json").read_text())["settings"]
    return shards.Settings(**{k: v for k, v in fingerprint.items() if k not in ("format", "probes")},
                           probes=tuple(fingerprint["probes"]), counts={"paper": 7, "val": 1, "train": 3})


def test_the_command_writes_shards_and_a_manifest(made):
    root, rooms = made
    assert sorted(p.name for p in (root / "train").iterdir()) == ["shard-00000.zip", "shard-00001.zip"]
    assert sorted(rooms) == ["train-00000", "train-00001", "train-00002", "val-00000"]
    manifest = json.loads((root / "manifest.json").read_text())
    assert manifest["settings"] == {"format": 2, "seed": 3, "ranges": "v2", "truth": "physical", "directions": 32,
                                    "probes": [8, 4], "voxels": 16, "mitsuba_directions": 0,
                                    "mitsuba_every": 1, "shard_size": 2}
    assert manifest["splits"]["train"]["count"] == manifest["splits"]["train"]["done"] == 3
    assert manifest["splits"]["val"]["done"] == 1 and manifest["splits"]["paper"]["done"] == 0
    assert manifest["ranges"]["albedo"] == [0.01, 0.95] and manifest["versions"]["ray"]
    assert manifest["timing"]["rooms_made"] == 4 and manifest["timing"]["rooms_per_hour"] > 0
    assert manifest["command"].startswith("python -m viewer.training.dataset --out")
    for shard in manifest["splits"]["train"]["shards"].values():
        assert shard["failed"] == 0 and shard["bytes"] > 0
    # every room as the training code reads it: the scene of its seed, targets at both resolutions
    for example in dataset.iter_split(root, "train"):
        index = int(example.name.split("-")[1])
        expected, params = dataset.make_scene("train", index, 3, "v2")
        assert np.array_equal(example.scene.vertices, expected.vertices) and example.params == params
        assert sorted(example.targets) == [4, 8] and example.targets[8].dtype == np.float32
        assert example.generator["index"] == index and example.generator["ranges"] == "v2"


def test_a_second_run_makes_nothing(made):
    root, _ = made
    before = {p: p.stat().st_mtime_ns for p in root.glob("*/*.zip")}
    result = generate.run(root, settings_of(root), ("val", "train"), workers=2, stream=io.StringIO())
    assert result.made == 0 and result.skipped == 4 and result.workers == 0  # Ray was never started
    assert {p: p.stat().st_mtime_ns for p in root.glob("*/*.zip")} == before


def test_resume_remakes_a_corrupt_shard_and_keeps_pending_rooms(made, tmp_path):
    """A truncated shard is made again, bit for bit the same (rooms are deterministic per seed); the rooms
    of a shard that was never packed are taken from pending/ without being made again."""
    import shutil

    source, rooms = made
    root = tmp_path / "copy"
    shutil.copytree(source, root)
    broken = root / "train" / "shard-00000.zip"
    broken.write_bytes(broken.read_bytes()[:5000])
    # an interrupted run: train-00002 finished (pending) but its shard was not packed yet
    unpacked = root / "train" / "shard-00001.zip"
    with zipfile.ZipFile(unpacked) as archive:
        payload = archive.read("train-00002.npz")
    unpacked.unlink()
    (root / "train" / "pending").mkdir()
    (root / "train" / "pending" / "train-00002.npz").write_bytes(payload)
    result = generate.run(root, settings_of(root), ("val", "train"), workers=2, stream=io.StringIO())
    assert result.made == 2 and result.skipped == 2 and not result.failed
    assert not (root / "train" / "pending").exists()
    again = {ref.partition("#")[2]: room_arrays(ref) for ref in dataset.room_refs(root, "train")}
    assert sorted(again) == ["train-00000", "train-00001", "train-00002"]
    for name, arrays in again.items():
        assert sorted(arrays) == sorted(rooms[name])
        for key, value in arrays.items():
            assert np.array_equal(value, rooms[name][key]), f"{name} {key}"
    manifest = json.loads((root / "manifest.json").read_text())
    assert manifest["timing"]["rooms_made"] == 6 and len(manifest["commands"]) == 3


def test_resume_remakes_a_shard_with_a_flipped_bit_without_being_asked_to_verify(made, tmp_path):
    """One bit flipped inside a room of a finished shard keeps the shard's size and index; the resume's own
    check (each member's CRC-32) finds it and makes the shard again, the same bits as before, so training
    never meets the damaged room."""
    import shutil

    source, rooms = made
    root = tmp_path / "copy"
    shutil.copytree(source, root)
    damaged = root / "train" / "shard-00000.zip"
    with zipfile.ZipFile(damaged) as archive:
        member = archive.getinfo("train-00001.npz")
    data = bytearray(damaged.read_bytes())
    header = member.header_offset
    name_length, extra_length = int.from_bytes(data[header + 26:header + 28], "little"), \
        int.from_bytes(data[header + 28:header + 30], "little")
    data[header + 30 + name_length + extra_length + member.compress_size // 2] ^= 0x10
    damaged.write_bytes(bytes(data))
    result = generate.run(root, settings_of(root), ("val", "train"), workers=2, stream=io.StringIO())
    assert result.made == 2 and result.skipped == 2 and not result.failed
    for ref in dataset.room_refs(root, "train"):
        name = ref.partition("#")[2]
        for key, value in room_arrays(ref).items():
            assert np.array_equal(value, rooms[name][key]), f"{name} {key}"


def test_other_settings_are_refused(made, tmp_path):
    import shutil

    root = tmp_path / "copy"
    shutil.copytree(made[0], root)
    assert dataset_cli.main(["--out", str(root), *ARGS, "--ranges", "v1"]) == 2


def test_physical_targets_are_the_solvers_probes():
    """What the dataset stores for the physical truth is what viewer.physical.gi's solver gives the renderer: the
    filled probes of `solve_parts`, and direct = all light - reflected light."""
    scene, _ = dataset.make_scene("train", 1, 3, "v2")
    lo, hi = scene.bounds
    arrays = truth.targets(scene, lo, hi, (8, 4), "physical", directions=32, seed=0, solver_voxels=16)
    for m in (8, 4):
        total, reflected = gi.solve_parts(scene, gi.GISettings(voxels=16, probes=m, directions=32))
        np.testing.assert_allclose(arrays[f"sh_{m}_filled"], total.coefficients, rtol=1e-5, atol=1e-6)
        valid = arrays[f"valid_{m}"]
        np.testing.assert_array_equal(valid, total.valid)
        np.testing.assert_allclose((arrays[f"sh_{m}"] - arrays[f"sh_{m}_direct"])[valid],
                                   reflected.coefficients[valid], rtol=1e-4, atol=1e-5)
        assert np.all(arrays[f"sh_{m}_direct"][..., 0, :] >= -1e-6)


def test_float16_targets_keep_their_precision():
    big = np.full((2, 2, 2, 9, 3), 7e4, np.float32)
    small = np.random.default_rng(0).uniform(-3, 3, (2, 2, 2, 9, 3)).astype(np.float32)
    stored = dataset.target_arrays({"sh_2": small, "sh_2_filled": small, "sh_3": big, "valid_2": np.ones(8, bool)})
    assert stored["sh_2"].dtype == np.float16 and stored["sh_3"].dtype == np.float32  # past float16's range
    assert "sh_2_filled" not in stored
    np.testing.assert_allclose(stored["sh_2"].astype(np.float32), small, rtol=5e-4, atol=1e-7)


def test_a_room_can_carry_mitsubas_unbiased_probes_beside_the_solvers():
    """--mitsuba-directions: the finest grid also gets Mitsuba's probes at few directions (noisy but
    unbiased); on a room's mean they agree with the solver's (the solver is 4-30% off per probe)."""
    if not truth.mitsuba_available():
        pytest.skip("Mitsuba 3 is not installed")
    settings = shards.Settings(seed=3, ranges="v2", truth="physical", directions=32, probes=(8, 4), voxels=16,
                               mitsuba_directions=16, mitsuba_every=2)
    assert [settings.unbiased("train", i) for i in range(4)] == [True, False, True, False]
    assert settings.unbiased("val", 1) and settings.unbiased("paper", 3)
    name, payload, _ = generate.make_room(settings, "train", 2)
    assert generate.room_ok(payload, settings.generator("train", 2), settings.probes)
    with np.load(io.BytesIO(payload)) as data:
        assert "sh_8_mitsuba" in data.files and "sh_4_mitsuba" not in data.files
        example = dataset.example_from(data, dataset.Path("x"))
    assert sorted(example.mitsuba) == [8] and example.mitsuba[8].shape == (8, 8, 8, 9, 3)
    valid = example.valid[8]
    mean_mitsuba = example.mitsuba[8][valid][:, 0].mean()
    mean_solver = example.raw[8][valid][:, 0].mean()
    assert abs(mean_mitsuba / mean_solver - 1) < 0.25
    reflected = (example.mitsuba[8] - example.mitsuba_direct[8])[valid][:, 0].mean()
    assert 0 < reflected < mean_mitsuba

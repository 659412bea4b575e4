"""The neural GI dataset: procedural rooms are valid scenes, files round-trip, runs resume, and the
ground truth sees the sun through a window."""

from __future__ import annotations

import json

import numpy as np
import pytest

from viewer.scene import meshes
from viewer.probes import sh
from viewer.evaluation import procedural
from viewer.training import dataset, dataset_cli, generate, shards, truth
from viewer.evaluation.procedural import CORNELL_POWER, OBJECT_KINDS, WALL_NAMES, Ranges, random_scene
from scenes import assert_same_room, covered, group_faces, wall_samples
from viewer.rays.voxels import voxelize

SEEDS = range(40)
needs_mitsuba = pytest.mark.skipif(not truth.mitsuba_available(), reason="Mitsuba 3 is not installed")


def scene_for(seed: int, ranges: Ranges = Ranges()):
    return random_scene(np.random.default_rng([7, seed]), f"test-{seed}", ranges)


# ---- procedural scenes ---------------------------------------------------------------------------------

def test_rooms_are_closed_except_the_front_and_the_window():
    """Points spread over the five walls of the box lie on the wall meshes, unless they are in the
    window's hole; walls face into the room."""
    for seed in SEEDS:
        scene, params = scene_for(seed)
        for name in WALL_NAMES:
            f, points, hole = wall_samples(params, name, 24)
            mask = group_faces(scene, name)
            on_wall = covered(points, scene.triangles[mask])
            if params["window"] is not None and params["window"]["wall"] == name:
                assert hole.any(), f"seed {seed}: the window on the {name} is smaller than the test grid"
            np.testing.assert_array_equal(on_wall, ~hole, err_msg=f"seed {seed} {name}")
            inward = scene.face_normals[mask] @ f.normal
            assert np.all(inward > 0.999), f"seed {seed}: {name} faces out"
        # the front (z = +hz) is open: no face lies in that plane
        assert not np.any(np.all(np.isclose(scene.triangles[..., 2], params["room_half"][2]), axis=1))


def test_emitters_face_into_the_room_with_the_power_in_range():
    ranges = Ranges()
    for seed in SEEDS:
        scene, params = scene_for(seed)
        half = np.array(params["room_half"])
        emitting = np.any(scene.emission > 0, axis=1)
        assert 1 <= len(params["lights"]) <= 2
        centroids = scene.triangles[emitting].mean(axis=1)
        assert np.all(np.abs(centroids) < half), f"seed {seed}: a light outside the room"
        # the front face points at the room's centre: the light goes in, not into the wall behind it
        assert np.all(np.einsum("ij,ij->i", scene.face_normals[emitting], -centroids) > 0), f"seed {seed}"
        power = np.pi * np.sum(scene.face_areas[emitting] * scene.emission[emitting].mean(axis=1))
        lo, hi = ranges.light_power
        assert lo * CORNELL_POWER * 0.999 <= power <= hi * CORNELL_POWER * 1.001, f"seed {seed}"
        for light in params["lights"]:
            assert all(ranges.light_half_extent[0] <= h <= ranges.light_half_extent[1] for h in light["half"])


def test_objects_are_closed_inside_the_room_and_apart():
    kinds, stacked = set(), 0
    for seed in SEEDS:
        scene, params = scene_for(seed)
        half = np.array(params["room_half"])
        assert Ranges().objects[0] <= len(params["objects"]) <= Ranges().objects[1]
        solids = []
        for name in scene.groups:
            if name in WALL_NAMES or name.startswith("light"):
                continue
            mask = group_faces(scene, name)
            vertices = np.unique(scene.triangles[mask].reshape(-1, 3), axis=0)
            assert meshes.signed_volume((scene.vertices, scene.faces[mask])) > 0, f"{name} faces inwards"
            assert np.all(np.abs(vertices[:, [0, 2]]) <= half[[0, 2]] - procedural.OBJECT_GAP + 1e-9)
            assert vertices[:, 1].min() >= -half[1] - 1e-9
            assert vertices[:, 1].max() < half[1] - procedural.WALL_GAP
            albedo = scene.albedo[mask]
            assert np.all((albedo >= 0.05) & (albedo <= 0.9))
            solids.append((name, vertices))
        for i, (a, va) in enumerate(solids):
            for b, vb in solids[i + 1:]:
                assert not meshes.overlap(va, vb), f"seed {seed}: {a} overlaps {b}"
        for obj in params["objects"]:
            kinds.add(obj["kind"])
            stacked += "stacked" in obj
    assert kinds == set(OBJECT_KINDS)
    assert stacked > 0


def test_walls_mostly_grey_albedo_in_range_and_rooms_scaled():
    ranges = Ranges()
    saturated = 0
    for seed in SEEDS:
        scene, params = scene_for(seed)
        assert all(ranges.room_scale[0] <= h <= ranges.room_scale[1] for h in params["room_half"])
        for name in WALL_NAMES:
            colour = np.array(params["walls"][name])
            assert np.all((colour >= ranges.albedo[0]) & (colour <= ranges.albedo[1]))
            np.testing.assert_allclose(scene.albedo[group_faces(scene, name)], colour[None].repeat(
                group_faces(scene, name).sum(), 0))
            saturated += np.ptp(colour) > 2 * ranges.grey_tint
    share = saturated / (len(SEEDS) * len(WALL_NAMES))
    assert 0.1 < share < 0.45  # ranges.saturated_wall_probability = 0.25


def test_scenes_voxelize_and_every_object_is_its_own_group():
    for seed in range(8):
        scene, params = scene_for(seed)
        assert len(scene.groups) == len(set(scene.groups)) == 5 + len(params["objects"]) + len(params["lights"])
        grid = voxelize(scene, 16)
        assert grid.count > 0 and grid.lights.count > 0
        assert np.all(np.isfinite(grid.position)) and np.all(np.isfinite(grid.emission))


def test_seeds_reproduce_bit_identically_and_differ():
    a, pa = scene_for(3)
    b, pb = scene_for(3)
    c, pc = scene_for(4)
    assert_same_room(a, pa, b, pb)
    assert a.vertices.shape != c.vertices.shape or not np.array_equal(a.vertices, c.vertices)
    assert pa["room_half"] != pc["room_half"]


def test_ranges_outside_the_training_ones_are_honoured():
    """The out-of-distribution study draws with other Ranges: every field it changes must show."""
    wide = Ranges(room_scale=(1.4, 1.6), objects=(3, 3), object_half_width=(0.1, 0.15),
                  window_probability=1.0, wall_light_probability=1.0, lights=(2, 2), object_kinds=("cone",))
    for seed in range(6):
        scene, params = scene_for(seed, wide)
        assert all(1.4 <= h <= 1.6 for h in params["room_half"])
        assert [o["kind"] for o in params["objects"]] == ["cone"] * 3
        assert all(light["wall"] != "ceiling" for light in params["lights"]) and len(params["lights"]) == 2
        assert params["window"] is not None and scene.sun is not None


def test_sun_enters_only_through_the_window():
    """The sun shines from behind the open front (so the window is its only way in), and the ray from
    its target on the floor towards the sun leaves the room through the window."""
    found = 0
    for seed in range(60):
        scene, params = scene_for(seed, Ranges(window_probability=1.0))
        if params["window"] is None:
            continue
        found += 1
        d = scene.sun.direction
        assert d[2] <= 0 and d[1] > 0
        target = np.array(params["window"]["sun"]["target"])
        half = np.array(params["room_half"])
        assert np.isclose(target[1], -half[1]) and np.all(np.abs(target[[0, 2]]) < half[[0, 2]])
        assert exits_through_window(target[None], d, params)[0]
        window = params["window"]
        assert window["wall"] in ("ceiling", "back", "left-wall", "right-wall")
        assert all(Ranges().window_half_extent[0] <= h <= Ranges().window_half_extent[1] for h in window["half"])
    assert found > 50


# ---- the dataset ---------------------------------------------------------------------------------------

def test_shards_make_the_paper_split_first_with_fixed_names():
    settings = shards.Settings(counts={"paper": 7, "val": 80, "train": 720}, shard_size=200)
    plan = shards.plan(settings, dataset.SPLITS)
    assert [(s.split, s.name, len(s.indices)) for s in plan] == [
        ("paper", "shard-00000.zip", 7), ("val", "shard-00000.zip", 80), ("train", "shard-00000.zip", 200),
        ("train", "shard-00001.zip", 200), ("train", "shard-00002.zip", 200), ("train", "shard-00003.zip", 120)]
    assert plan[0].rooms() == list(dataset.PAPER_SCENES)
    assert plan[-1].rooms()[-1] == "train-00719"


@pytest.fixture(scope="module")
def tiny(tmp_path_factory):
    """Three v1 rooms with Mitsuba truth, made on Ray (two workers) in shards of two."""
    if not truth.mitsuba_available():
        pytest.skip("Mitsuba 3 is not installed")
    root = tmp_path_factory.mktemp("gi-tiny")
    settings = shards.Settings(seed=5, ranges="v1", truth="mitsuba", directions=64, probes=(4,),
                               counts={"paper": 7, "val": 1, "train": 2}, shard_size=2)
    result = generate.run(root, settings, ("val", "train"), workers=2, stream=open("/dev/null", "w"))
    return root, result, settings


@needs_mitsuba
def test_tiny_dataset_round_trips(tiny):
    root, result, _ = tiny
    assert result.made == 3 and result.skipped == 0 and not result.failed
    manifest = json.loads((root / "manifest.json").read_text())
    assert manifest["splits"]["train"]["count"] == 2 and manifest["splits"]["train"]["done"] == 2
    assert manifest["splits"]["val"]["count"] == 1 and manifest["splits"]["val"]["done"] == 1
    assert manifest["settings"]["truth"] == "mitsuba" and manifest["versions"]["mitsuba"]
    examples = list(dataset.iter_split(root, "train")) + list(dataset.iter_split(root, "val"))
    assert [e.name for e in examples] == ["train-00000", "train-00001", "val-00000"]
    for example, (split, index) in zip(examples, [("train", 0), ("train", 1), ("val", 0)]):
        expected, params = dataset.make_scene(split, index, 5, "v1")
        for name in ("vertices", "faces", "albedo", "emission", "face_group"):
            assert np.array_equal(getattr(example.scene, name), getattr(expected, name)), name
        assert example.scene.groups == expected.groups and example.params == params
        assert (example.scene.sun is None) == (expected.sun is None)
        np.testing.assert_array_equal(example.lo, expected.bounds[0])
        np.testing.assert_array_equal(example.hi, expected.bounds[1])
        raw, filled, valid = example.raw[4], example.targets[4], example.valid[4]
        assert raw.shape == filled.shape == example.direct[4].shape == (4, 4, 4, 9, 3)
        assert valid.shape == (4, 4, 4) and valid.dtype == bool and valid.sum() > 32
        assert raw.dtype == np.float32 and np.all(np.isfinite(raw)) and np.all(np.isfinite(filled))
        np.testing.assert_array_equal(filled[valid], raw[valid])
        # a lit room: every valid probe receives light, and the light straight from the emitters is
        # part of the total (the reflected rest carries positive L00 too)
        assert np.all(raw[valid][:, 0].mean(axis=-1) > 0)
        assert np.all(raw[valid][:, 0].mean(axis=-1) >= example.direct[4][valid][:, 0].mean(axis=-1) - 1e-3)


def test_format_1_files_still_read(tmp_path):
    """A one-room file of the first dataset (gi-v1: float32 targets with their filled copy) loads."""
    scene, params = dataset.make_scene("train", 0, 1)
    lo, hi = scene.bounds
    arrays = truth.targets(scene, lo, hi, (4,), "physical", directions=32, seed=0, solver_voxels=8)
    arrays.update(dataset.scene_arrays(scene), lo=lo, hi=hi, params=np.array(json.dumps(params)),
                  generator=np.array(json.dumps({"format": 1})), seconds=np.array(1.0))
    (tmp_path / "train").mkdir()
    np.savez_compressed(tmp_path / "train" / "00000.npz", **arrays)
    (example,) = dataset.iter_split(tmp_path, "train")
    assert example.name == scene.name and example.generator == {"format": 1}
    np.testing.assert_array_equal(example.targets[4], arrays["sh_4_filled"])
    np.testing.assert_array_equal(example.raw[4], arrays["sh_4"])


def test_a_coarser_lattice_is_read_out_of_a_finer_one():
    """A room stored at 12^3 probes also answers at 4^3 (every third probe, from the second: the
    centres of the coarse cells), with the numbers the truth computes at 4^3 directly."""
    import io

    assert dataset.coarser_lattices(24) == [(8, slice(1, None, 3))] and dataset.coarser_lattices(16) == []
    scene, params = dataset.make_scene("train", 0, 1)
    lo, hi = scene.bounds
    arrays = truth.targets(scene, lo, hi, (12, 4), "physical", directions=32, seed=0, solver_voxels=8)
    stored = {k: v for k, v in arrays.items() if k.endswith("_12") or "_12_" in k}
    stored.update(dataset.scene_arrays(scene), lo=lo, hi=hi, params=np.array(json.dumps(params)),
                  generator=np.array(json.dumps({"format": 2})))
    buffer = io.BytesIO()
    np.savez(buffer, **stored)
    buffer.seek(0)
    with np.load(buffer) as data:
        example = dataset.example_from(data, "room.npz")
    assert sorted(example.raw) == [4, 12]
    np.testing.assert_allclose(example.raw[4], arrays["sh_4"], atol=1e-5)
    np.testing.assert_allclose(example.direct[4], arrays["sh_4_direct"], atol=1e-5)
    np.testing.assert_array_equal(example.valid[4], arrays["valid_4"])
    np.testing.assert_allclose(example.targets[4], arrays["sh_4_filled"], atol=1e-5)


def test_the_stored_scene_is_what_the_truth_saw():
    scene, _ = dataset.make_scene("train", 2, 1)
    arrays = dataset.scene_arrays(scene)
    again = dataset.scene_from_arrays(arrays)
    for name in ("vertices", "albedo", "emission"):
        assert np.array_equal(getattr(again, name), getattr(scene, name)), name
    assert again.camera == scene.camera


def test_write_obj_loads_back_to_the_same_scene(tmp_path):
    from viewer.scene import load
    from viewer.scene.obj import write as write_obj

    for index in range(3):
        scene, _ = dataset.make_scene("train", index, 1)
        write_obj(scene, tmp_path / f"{scene.name}.obj")
        again = load(tmp_path / f"{scene.name}.obj")
        assert again.groups == scene.groups and again.camera == scene.camera
        for name in ("vertices", "faces", "albedo", "emission", "face_group"):
            assert np.array_equal(getattr(again, name), getattr(scene, name)), name


# ---- the truth -----------------------------------------------------------------------------------------

def sunny_room():
    """A room with a window and no objects (nothing else in the beam)."""
    for seed in range(20):
        scene, params = scene_for(seed, Ranges(window_probability=1.0, objects=(0, 0)))
        if params["window"] is not None:
            return dataset.quantized(scene), params
    raise AssertionError("no window drawn")


def exits_through_window(points, direction, params) -> np.ndarray:
    """Whether rays from points towards the sun leave the room through the window (by 0.05 margin)."""
    frames = procedural.room_frames(np.array(params["room_half"]))
    f = frames[params["window"]["wall"]]
    t = ((f.centre - points) @ f.normal) / (direction @ f.normal)
    hit = points + t[:, None] * direction
    (a, b), (ha, hb) = params["window"]["uv"], params["window"]["half"]
    return (np.abs((hit - f.centre) @ f.u - a) < ha - 0.05) & (np.abs((hit - f.centre) @ f.v - b) < hb - 0.05)


@needs_mitsuba
def test_sunlight_comes_in_through_the_window():
    from viewer.reference import mitsuba as reference

    scene, params = sunny_room()
    sun = scene.sun
    target = np.array(params["window"]["sun"]["target"])
    centre = np.array(params["window"]["centre"])
    in_beam = target + 0.5 * (centre - target)
    lo, hi = scene.bounds
    candidates = lo + (hi - lo) * np.random.default_rng(0).uniform(0.15, 0.85, (200, 3))
    shade = candidates[~exits_through_window(candidates, sun.direction, params)]
    shadowed = shade[np.argmax(np.linalg.norm(shade - target, axis=1))]  # far from the sunlit patch
    assert exits_through_window(in_beam[None], sun.direction, params)[0]
    points = np.stack([in_beam, shadowed])
    with_sun = reference.probe_sh(scene, points, directions=256, seed=1, cache=False)
    without = reference.probe_sh(scene.with_sun(None), points, directions=256, seed=1, cache=False)
    delta = sh.project_delta(sun.direction, sun.irradiance)[0]  # L00 of the sun seen directly (RGB)
    gain = with_sun[:, 0] - without[:, 0]
    assert np.all(gain[0] > 0.9 * delta) and np.all(gain[0] < 1.3 * delta)  # the sun, plus its bounce light
    assert np.all(gain[1] < 0.2 * delta)  # in the shade: only light bounced off the sunlit patch


def test_solver_truth_splits_direct_and_reflected_light():
    scene, _ = dataset.make_scene("train", 0, 1)
    lo, hi = scene.bounds
    arrays = truth.targets(scene, lo, hi, (4,), "solver", directions=32, seed=0, solver_voxels=8)
    total, direct, valid = arrays["sh_4"], arrays["sh_4_direct"], arrays["valid_4"]
    assert total.shape == direct.shape == (4, 4, 4, 9, 3) and valid.shape == (4, 4, 4)
    np.testing.assert_array_equal(arrays["sh_4_filled"], total)  # the solver's probes come filled
    reflected_l00 = (total - direct)[..., 0, :]
    assert np.all(direct[..., 0, :] >= -1e-6) and np.all(reflected_l00 > 0)


def test_command_line_help_and_bad_input(capsys):
    with pytest.raises(SystemExit) as exit_info:
        dataset_cli.main(["--help"])
    assert exit_info.value.code == 0
    assert "--probes" in capsys.readouterr().out
    assert dataset_cli.main(["--out", "/tmp/never", "--probes", "8,x"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--probes" in err[0]

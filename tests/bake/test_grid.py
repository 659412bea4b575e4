"""`gi-viewer bake`: the converged probe grid for other tools (.npz with documented keys, a DDS volume
texture), and `gi-viewer FILE.npz` / `capture FILE.npz`, which show the scene lit by the baked probes.

What must hold: the file carries the same light that `sample` reports, the texture carries the same
numbers as the file, a baked grid renders exactly as the live solve it came from, and a bad file is
one line on stderr with exit status 2.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import zipfile
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from baked_files import rewritten

from viewer.bake import grid as baked
from viewer.bake import dds
from viewer.probes.grid import ProbeGrid

ROOT = Path(__file__).resolve().parents[2]
SMALL = ("--voxels", "12", "--probes", "6", "--directions", "128")


def run(*args, cwd=None, env=None):
    environment = dict(os.environ, PYTHONPATH=str(ROOT), **(env or {}))
    return subprocess.run([sys.executable, "-m", "viewer", *map(str, args)], capture_output=True, text=True,
                          cwd=cwd or ROOT, env=environment, timeout=600)


@pytest.fixture(scope="module")
def cornell_bake(tmp_path_factory):
    folder = tmp_path_factory.mktemp("bake")
    result = run("bake", "cornell", "--out", folder / "cornell.npz", "--dds", folder / "cornell.dds", *SMALL)
    assert result.returncode == 0, result.stderr
    return folder, result


def test_bake_reports_one_line_of_seconds(cornell_bake):
    _, result = cornell_bake
    assert result.stderr.count("\n") == 1 and result.stderr.startswith("bake:") and "total" in result.stderr


def test_the_npz_holds_every_documented_key_and_sample_sees_the_same_light(cornell_bake, tmp_path):
    folder, _ = cornell_bake
    with np.load(folder / "cornell.npz", allow_pickle=False) as data:
        assert set(baked.KEYS) <= set(data.files)
        m = int(data["resolution"])
        assert m == 6 and int(data["sh_order"]) == 2 and str(data["scene"]) == "cornell"
        assert data["radiance"].shape == data["indirect"].shape == (m, m, m, 9, 3)
        assert data["valid"].shape == (m, m, m) and data["valid"].dtype == bool
        assert json.loads(str(data["settings"]))["voxels"] == 12
        radiance, lo, hi = data["radiance"], data["lo"], data["hi"]
    # at the probe centres `sample` interpolates nothing: it must read back the baked radiance
    centres = ProbeGrid.positions_for(lo, hi, m).reshape(-1, 3)
    np.save(tmp_path / "points.npy", centres.astype(np.float32))
    result = run("sample", "cornell", "--points", tmp_path / "points.npy", "--out", tmp_path / "sh.npy", *SMALL)
    assert result.returncode == 0, result.stderr
    np.testing.assert_allclose(np.load(tmp_path / "sh.npy"), radiance.reshape(-1, 9, 3), rtol=1e-4, atol=1e-5)
    # the lamp's own light is in `radiance` and not in `indirect`: never less, and more on the whole
    grid = baked.read_npz(folder / "cornell.npz")
    total, indirect = grid.radiance.coefficients[..., 0, :], grid.indirect.coefficients[..., 0, :]
    assert np.all(total >= indirect - 1e-6) and total.mean() > 1.5 * indirect.mean()


def test_the_dds_texture_is_a_float_volume_holding_the_indirect_coefficients_and_validity(cornell_bake):
    folder, _ = cornell_bake
    data = (folder / "cornell.dds").read_bytes()
    header = dds.read_header(data)
    assert (header.width, header.height, header.depth) == (6, 6, 7 * 6)
    assert header.dxgi_format == 2 and header.dimension == 4 and header.array_size == 1  # RGBA32F, 3D
    assert len(data) == 148 + 6 * 6 * 42 * 16
    texels = dds.read_volume(folder / "cornell.dds").reshape(7, 6, 6, 6, 4)   # [slab, z, y, x, rgba]
    grid = baked.read_npz(folder / "cornell.npz")
    numbers = texels.transpose(0, 4, 3, 2, 1).reshape(28, 6, 6, 6)      # [number, x, y, z]
    np.testing.assert_array_equal(numbers[:27].transpose(1, 2, 3, 0).reshape(6, 6, 6, 9, 3),
                                  grid.indirect.coefficients)
    np.testing.assert_array_equal(numbers[27], grid.indirect.valid.astype(np.float32))


def test_half_precision_dds_rounds_the_same_numbers_to_float16(tmp_path):
    tiny = ("--voxels", "8", "--probes", "4", "--directions", "64")
    result = run("bake", "cornell", "--out", tmp_path / "grid.npz", "--dds", tmp_path / "half.dds",
                 "--dds-precision", "16", *tiny)
    assert result.returncode == 0, result.stderr
    assert dds.read_header((tmp_path / "half.dds").read_bytes()).dxgi_format == 10   # R16G16B16A16_FLOAT
    expected = baked.texture_volumes(baked.read_npz(tmp_path / "grid.npz").indirect)
    np.testing.assert_array_equal(dds.read_volume(tmp_path / "half.dds"), expected.astype(np.float16))


def test_a_baked_grid_renders_exactly_as_the_live_solve_it_came_from(cornell_bake, tmp_path):
    folder, _ = cornell_bake
    common = ("--size", "96x72", "--msaa", "1", "--light-samples", "8")
    live = run("capture", "cornell", "--gi", "solver", "--out", tmp_path / "live.png", *common, *SMALL)
    from_file = run("capture", folder / "cornell.npz", "--out", tmp_path / "baked.png", *common)
    assert live.returncode == 0 and from_file.returncode == 0, live.stderr + from_file.stderr
    images = [np.asarray(Image.open(tmp_path / f"{n}.png"), np.float64) for n in ("live", "baked")]
    assert np.abs(images[0] - images[1]).max() <= 1


def test_opening_a_baked_file_without_a_display_renders_it_headless(cornell_bake, tmp_path):
    folder, _ = cornell_bake
    result = run(folder / "cornell.npz", "--size", "96x72", cwd=tmp_path, env={"DISPLAY": "", "WAYLAND_DISPLAY": ""})
    assert result.returncode == 0, result.stderr
    image = np.asarray(Image.open(tmp_path / "cornell.png"), np.float64)
    assert image.shape[:2] == (72, 96) and image.mean() > 20


def test_a_baked_scene_file_moved_with_its_grid_is_found_beside_it(tmp_path):
    scene = tmp_path / "made" / "room.obj"
    scene.parent.mkdir()
    scene.write_text((ROOT / "assets" / "scenes" / "cornell.obj").read_text().replace("mtllib", "# mtllib"))
    out = tmp_path / "made" / "room.npz"
    assert run("bake", scene, "--out", out, "--voxels", "8", "--probes", "4", "--directions", "64").returncode == 0
    assert baked.read_npz(out).scene == str(scene.resolve())
    moved = tmp_path / "moved"
    (tmp_path / "made").rename(moved)
    grid = baked.read_npz(moved / "room.npz")
    assert baked.scene_source(grid, moved / "room.npz") == str((moved / "room.obj").resolve())
    (moved / "room.obj").unlink()
    with pytest.raises(baked.BakedError, match="is gone"):
        baked.scene_source(grid, moved / "room.npz")


# ---- bad input ---------------------------------------------------------------------------------------------

def text_file(path: Path, text: str) -> Path:
    path.write_text(text)
    return path


def empty_zip(path: Path) -> Path:
    zipfile.ZipFile(path, "w").close()
    return path


BAD_FILES = {
    "missing": lambda src, d: d / "nope.npz",
    "not a zip": lambda src, d: text_file(d / "text.npz", "hello"),
    "empty zip": lambda src, d: empty_zip(d / "empty.npz"),
    "no radiance": lambda src, d: rewritten(src, d / "x.npz", radiance=None),
    "newer version": lambda src, d: rewritten(src, d / "x.npz", version=np.int64(99)),
    "other format": lambda src, d: rewritten(src, d / "x.npz", format=np.str_("something else")),
    "NaN radiance": lambda src, d: rewritten(src, d / "x.npz", radiance=np.full((6, 6, 6, 9, 3), np.nan, np.float32)),
    "wrong shape": lambda src, d: rewritten(src, d / "x.npz", indirect=np.zeros((6, 6, 6, 27), np.float32)),
    "empty box": lambda src, d: rewritten(src, d / "x.npz", hi=np.zeros(3), lo=np.zeros(3)),
    "resolution an array": lambda src, d: rewritten(src, d / "x.npz", resolution=np.arange(3)),
    "sh order an array": lambda src, d: rewritten(src, d / "x.npz", sh_order=np.arange(3)),
    "zero sun": lambda src, d: rewritten(src, d / "x.npz", sun=np.zeros(6)),
    "settings not json": lambda src, d: rewritten(src, d / "x.npz", settings=np.str_("{")),
    "pickled object": lambda src, d: rewritten(src, d / "x.npz", scene=np.array([{"a": 1}], dtype=object)),
    "unknown scene": lambda src, d: rewritten(src, d / "x.npz", scene=np.str_("no-such-builtin")),
}


@pytest.mark.parametrize("case", sorted(BAD_FILES))
def test_a_bad_baked_file_is_refused_in_one_line(cornell_bake, tmp_path, case):
    folder, _ = cornell_bake
    path = BAD_FILES[case](folder / "cornell.npz", tmp_path)
    with pytest.raises(ValueError) as refused:   # BakedError, or SceneError for the scene it names
        baked.load_scene(baked.read_npz(path), path)
    assert "\n" not in str(refused.value) and len(str(refused.value)) < 300, str(refused.value)


@pytest.mark.parametrize("case", ["not a zip", "newer version", "unknown scene"])
def test_a_bad_baked_file_exits_2_with_one_line(cornell_bake, tmp_path, case):
    folder, _ = cornell_bake
    path = BAD_FILES[case](folder / "cornell.npz", tmp_path)
    for args in ([path], ["capture", path, "--out", tmp_path / "x.png"]):
        result = run(*args, cwd=tmp_path, env={"DISPLAY": "", "WAYLAND_DISPLAY": ""})
        assert result.returncode == 2, (case, args, result.stderr)
        lines = [line for line in result.stderr.splitlines() if not line.startswith("viewer: no display")]
        assert len(lines) == 1 and lines[0].startswith("error:"), (case, result.stderr)


@pytest.mark.parametrize("args", [["--out", "grid.png"], ["--out", "grid.npz", "--dds", "grid.ktx2"],
                                  ["--out", "no/such/folder/grid.npz"], ["--out", "grid.npz", "--probes", "1"]])
def test_bad_bake_options_exit_2_with_one_line(tmp_path, args):
    result = run("bake", "cornell", *args, cwd=tmp_path)
    assert result.returncode == 2 and result.stderr.count("\n") == 1 and result.stderr.startswith("error:"), \
        result.stderr


def test_capture_of_a_baked_file_refuses_another_sun(cornell_bake, tmp_path):
    folder, _ = cornell_bake
    result = run("capture", folder / "cornell.npz", "--out", tmp_path / "x.png", "--sun", "0,1,0,1,1,1")
    assert result.returncode == 2 and "sun" in result.stderr


# ---- in the window: a GI source of its own -------------------------------------------------------------------

def test_the_viewer_shows_a_baked_grid_until_another_scene_is_opened():
    from scenes import box
    from viewer.ui.gi_sources import GIController

    grid = ProbeGrid(np.zeros(3), np.ones(3), np.ones((2, 2, 2, 9, 3), np.float32), np.ones((2, 2, 2), bool))
    assert "baked" in GIController(ctx=None, source="off").unavailable   # nothing baked: not offered
    gi = GIController(ctx=None, source="baked", baked=grid)
    gi.unavailable["compute"] = "no GL in this test"
    gi.set_scene(box(), version=1, new_scene=True)
    assert gi.update() == (True, grid) and not gi.busy and "Baked" in gi.status()[0]
    gi.set_source("off")
    assert gi.update() == (True, None)
    gi.set_source("baked")
    assert gi.update() == (True, grid)
    gi.set_scene(box(half_size=2.0), version=2)                 # an edit: the baked probes stay
    assert gi.update() == (True, grid)
    gi.set_scene(box(half_size=3.0), version=3, new_scene=True)  # another scene: they fit no more
    assert gi.source == "off" and "baked" in gi.unavailable and gi.update() == (True, None)


def test_the_window_opens_a_baked_file_on_its_scene_with_the_baked_probes(cornell_bake, tmp_path):
    from conftest import missing
    from pictures import CEILING, assert_cornell_box, region
    from viewer.bench.x11 import Viewer, start_xvfb, xvfb_available

    if not xvfb_available():
        missing("Xvfb is not installed (apt-get install xvfb): the window tests need an X server")
    folder, _ = cornell_bake
    view, stats = tmp_path / "view.png", tmp_path / "stats.json"
    server, display = start_xvfb()
    viewer = Viewer(display, [str(folder / "cornell.npz"), "--screenshot", str(view), "--stats", str(stats),
                              "--quit-after", "600"], tmp_path)
    try:
        assert viewer.wait_exit() == 0, viewer.log
    finally:
        viewer.kill()
        server.terminate()
        server.wait(timeout=10)
    info = json.loads(stats.read_text())
    assert info["gi_source"] == "baked" and info["source"] == "cornell", info
    image = np.asarray(Image.open(view))
    assert_cornell_box(image)
    assert region(image, CEILING).mean() > 30   # lit by the baked indirect light alone

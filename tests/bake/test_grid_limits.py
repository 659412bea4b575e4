"""A baked grid is read within limits and opens only its own folder: every entry's declared size is checked
before it is decompressed (a 1.7 MB file unpacked to 3.8 GB), the resolution is at most what a solve makes,
a hostile box prints no numpy warning, and the scene a grid names resolves inside the grid's folder and is
a regular file; anything else is one line."""

import io
import os
import warnings
import zipfile
from pathlib import Path

import numpy as np
import pytest

from baked_files import rewritten

from viewer.bake import grid as baked
from viewer.physical.work import MAX_PROBES
from viewer.probes.grid import ProbeGrid

ROOT = Path(__file__).resolve().parents[2]
CORNELL = (ROOT / "assets" / "scenes" / "cornell.obj").read_text().replace("mtllib", "# mtllib")


def small_grid(scene: str = "cornell", m: int = 2) -> baked.BakedGrid:
    grid = ProbeGrid(np.zeros(3), np.ones(3), np.ones((m, m, m, 9, 3), np.float32), np.ones((m, m, m), bool))
    return baked.BakedGrid(grid, grid, scene, None, {"voxels": 8})


def written(path: Path, scene: str = "cornell", **changes) -> Path:
    baked.write_npz(small_grid(scene), path)
    return rewritten(path, path, **changes) if changes else path


def refused(path: Path, match: str) -> str:
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        with pytest.raises(baked.BakedError, match=match) as error:
            baked.load_scene(baked.read_npz(path), path)
    assert not [str(w.message) for w in caught if issubclass(w.category, RuntimeWarning)]
    message = str(error.value)
    assert "\n" not in message and len(message) < 400, message
    return message


def test_a_small_file_that_unpacks_to_gigabytes_is_refused_unread(tmp_path):
    good = written(tmp_path / "good.npz")
    bomb = tmp_path / "bomb.npz"
    with zipfile.ZipFile(good) as source, zipfile.ZipFile(bomb, "w", zipfile.ZIP_DEFLATED) as out:
        for info in source.infolist():
            if info.filename != "radiance.npy":
                out.writestr(info.filename, source.read(info))
        with out.open("radiance.npy", "w", force_zip64=True) as fh:   # 1 GiB of zeros, about 1 MB packed
            header = io.BytesIO()
            np.lib.format.write_array_header_1_0(header, {"descr": "<f4", "fortran_order": False,
                                                          "shape": (2, 2, 2, 9, 3)})
            fh.write(header.getvalue())
            zeros = bytes(1 << 20)
            for _ in range(1024):
                fh.write(zeros)
    assert bomb.stat().st_size < 8 << 20
    assert "unpacks to 1024 MiB" in refused(bomb, "'radiance'")


def test_an_array_header_past_the_limit_is_refused_before_its_data_is_read(tmp_path):
    path = tmp_path / "lying.npz"
    written(path)
    values = {}
    with np.load(path, allow_pickle=False) as data:
        values = {k: data[k] for k in data.files}
    with zipfile.ZipFile(path, "w") as out:
        for key, value in values.items():
            if key == "indirect":   # a header that declares 2^40 floats, with 8 bytes of data after it
                header = io.BytesIO()
                np.lib.format.write_array_header_1_0(header, {"descr": "<f4", "fortran_order": False,
                                                              "shape": (1 << 40,)})
                out.writestr("indirect.npy", header.getvalue() + bytes(8))
            else:
                buffer = io.BytesIO()
                np.lib.format.write_array(buffer, np.asanyarray(value), allow_pickle=False)
                out.writestr(f"{key}.npy", buffer.getvalue())
    refused(path, "'indirect' declares")


def test_the_resolution_is_at_most_what_a_solve_makes(tmp_path):
    m = MAX_PROBES + 1
    path = written(tmp_path / "big.npz", resolution=np.int64(m))
    refused(path, f"resolution must be an integer 1..{MAX_PROBES}")


def test_a_box_at_the_ends_of_float64_is_refused_without_numpy_warnings(tmp_path):
    path = written(tmp_path / "box.npz", lo=np.full(3, -1e308), hi=np.full(3, 1e308))
    refused(path, "probe box reaches beyond")


def test_settings_nested_past_the_json_parser_are_refused_in_one_line(tmp_path):
    path = written(tmp_path / "deep.npz", settings=np.str_("[" * 100000 + "]" * 100000))
    refused(path, "settings are not a JSON object")


def test_a_grid_opens_a_scene_only_inside_its_own_folder(tmp_path, monkeypatch):
    (tmp_path / "elsewhere").mkdir()
    (tmp_path / "elsewhere" / "room.obj").write_text(CORNELL)
    grids = tmp_path / "grids"
    grids.mkdir()
    monkeypatch.chdir(tmp_path / "elsewhere")   # a relative name resolved against the current folder found it
    for name in ("room.obj", "../elsewhere/room.obj", str(tmp_path / "elsewhere" / "room.obj")):
        path = written(grids / "g.npz", scene=name)
        message = refused(path, "outside the baked file's folder|is gone")
        assert "room.obj" in message
    (grids / "sub").mkdir()
    (grids / "sub" / "room.obj").write_text(CORNELL)
    path = written(grids / "g.npz", scene="sub/room.obj")
    assert baked.scene_source(baked.read_npz(path), path) == str((grids / "sub" / "room.obj").resolve())
    assert len(baked.load_scene(baked.read_npz(path), path).faces) > 0


def test_a_grid_s_scene_beside_it_that_links_elsewhere_is_refused(tmp_path):
    (tmp_path / "elsewhere").mkdir()
    (tmp_path / "elsewhere" / "room.obj").write_text(CORNELL)
    grids = tmp_path / "grids"
    grids.mkdir()
    (grids / "room.obj").symlink_to(tmp_path / "elsewhere" / "room.obj")
    path = written(grids / "g.npz", scene="room.obj")
    message = refused(path, "links to .*outside the baked file's folder")
    assert "room.obj" in message


def test_a_grid_s_scene_that_is_not_a_built_in_name_is_refused(tmp_path):
    path = written(tmp_path / "g.npz", scene="..")
    refused(path, "not a built-in scene")


def test_a_grid_or_its_scene_that_is_a_pipe_is_refused_without_opening_it(tmp_path):
    os.mkfifo(tmp_path / "room.obj")
    path = written(tmp_path / "g.npz", scene="room.obj")
    refused(path, "not a regular file")
    os.mkfifo(tmp_path / "pipe.npz")
    refused(tmp_path / "pipe.npz", "not a regular file")


def test_a_grid_is_held_to_the_memory_limit_of_every_request(tmp_path, monkeypatch):
    path = written(tmp_path / "g.npz")
    monkeypatch.setenv("GI_VIEWER_MAX_GIB", "1e-6")   # about 1 KiB: less than two 2^3 grids of probes
    refused(path, "resolution 2: its probes would take")
    monkeypatch.setenv("GI_VIEWER_MAX_GIB", "1")
    assert baked.read_npz(path).radiance.resolution == 2

"""Drag and drop onto the real viewer window under Xvfb: a real XDND drop (viewer/bench/x11.py) of
scene files. A good file replaces the scene; a broken or unsupported one is reported in the window and
on stderr, and the scene shown before stays."""

from __future__ import annotations

import json
import shutil

import numpy as np
import pytest
from PIL import Image

from viewer.bench.x11 import REPO, Viewer

trimesh = pytest.importorskip("trimesh")


def test_dropped_files_load_in_the_background_and_bad_ones_leave_the_scene(display, x11, tmp_path):  # noqa: F811
    for name in ("paper-test.obj", "paper-test.mtl", "paper-test.json"):
        shutil.copy(REPO / "assets" / "scenes" / name, tmp_path / name)
    broken = tmp_path / "broken.obj"
    broken.write_text("v 0 0 0\nv 1 0\nf 1 2 3\n")
    unsupported = tmp_path / "notes.txt"
    unsupported.write_text("not a scene")
    cube = tmp_path / "cube.ply"
    trimesh.creation.box(extents=(1.0, 2.0, 1.0)).export(cube)
    stats = tmp_path / "stats.json"

    viewer = Viewer(display, ["cornell", "--gi", "off", "--stats", str(stats), "--quit-after", "600"], tmp_path)
    try:
        window = viewer.ready()

        def drop(path) -> int:
            count = len(viewer.lines)
            exchange = x11.drop(window, [path])
            assert exchange == {"accepted": True, "requested": True, "finished": True}, exchange
            return count

        start = drop(tmp_path / "paper-test.obj")
        viewer.wait_for(r"loaded .*paper-test\.obj as 'paper-test': 388 triangles", start=start)

        start = drop(broken)
        line = viewer.wait_for(r"cannot load .*broken\.obj: (.*); keeping paper-test", start=start)
        assert "broken.obj:2" in line.group(1)      # says which line of the file is wrong

        start = drop(unsupported)
        viewer.wait_for(r"cannot load .*notes\.txt: .*unsupported format '\.txt'", start=start)

        count = len(viewer.lines)
        x11.key("s")
        path = viewer.wait_for(r"saved screenshot (.*)$", start=count).group(1)
        state = json.loads(stats.read_text())
        assert state["scene"] == "paper-test" and state["loads"] == 1 and state["load_errors"] == 2
        errors = [m["text"] for m in state["messages"] if m["error"]]
        assert any("broken.obj" in e for e in errors) and any("notes.txt" in e for e in errors)
        image = np.asarray(Image.open(path))
        assert image[..., 0].mean() > 5, "the scene kept after the bad drops is not drawn"

        start = drop(cube)
        viewer.wait_for(r"loaded .*cube\.ply as 'cube': 12 triangles", start=start)
        x11.key("Escape")
        assert viewer.wait_exit() == 0
    finally:
        viewer.kill()
    assert json.loads(stats.read_text())["scene"] == "cube"

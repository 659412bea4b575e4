"""The viewer's real window under Xvfb (glfw, GL 4.5 core through Mesa): it opens on the Cornell box and
renders it with indirect light, the panel's text is drawn, keys and the mouse do what the help says, a
broken shader is reported while the old one keeps running, and without a display it renders headless.

Input comes through the XTEST extension (viewer/bench/x11.py), as from a real keyboard and mouse.
Image regions are fractions of the image: (top, bottom, left, right).
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import time

import numpy as np
import pytest

from PIL import Image

from pictures import CEILING, assert_cornell_box, region
from viewer.bench.x11 import REPO, Viewer

VIEW_CENTRE = (400, 360)   # window pixels inside the 3D view (the panel is on the right)


def test_window_renders_the_cornell_box_with_indirect_light_and_the_panel(display, tmp_path):
    view, window, stats = tmp_path / "view.png", tmp_path / "window.png", tmp_path / "stats.json"
    viewer = Viewer(display, ["cornell", "--gi", "compute", "--voxels", "16", "--probes", "8",
                              "--screenshot", str(view), "--screenshot-window", str(window), "--stats", str(stats),
                              "--quit-after", "600"], tmp_path)
    try:
        assert viewer.wait_exit() == 0, viewer.log
    finally:
        viewer.kill()
    assert "GI ready: Compute solver: converged" in viewer.log
    info = json.loads(stats.read_text())
    assert info["window"] == [1280, 720] and "OpenGL 4.5" in info["gl"]
    image = np.asarray(Image.open(view))
    assert image.shape[1] < 1280 and image.shape[0] == 720   # the view, left of the panel
    assert_cornell_box(image)
    # The lamp faces down: the ceiling gets no direct light, only what bounces off the room.
    assert region(image, CEILING).mean() > 30, f"ceiling black: no indirect light {region(image, CEILING)}"
    # The panel (imgui, its font atlas uploaded through the 1.92 texture protocol) shows text: bright
    # glyph pixels on the dark panel background.
    panel = np.asarray(Image.open(window))[:, image.shape[1] + 8:, :3].max(axis=2)
    assert (panel > 200).sum() > 2000, "no text in the panel"
    assert (panel < 60).mean() > 0.5, "the panel background is not dark"


def test_keys_and_mouse(display, x11, tmp_path):
    stats = tmp_path / "stats.json"
    viewer = Viewer(display, ["cornell", "--gi", "off", "--stats", str(stats), "--quit-after", "600"], tmp_path)
    try:
        window = viewer.ready()
        x0, y0 = x11.origin(window)
        centre = (x0 + VIEW_CENTRE[0], y0 + VIEW_CENTRE[1])

        def screenshot() -> tuple[dict, np.ndarray]:
            count = len(viewer.lines)
            x11.key("s")
            path = viewer.wait_for(r"saved screenshot (.*)$", start=count).group(1)
            return json.loads(stats.read_text()), np.asarray(Image.open(path))

        x11.move(*centre)
        home, image = screenshot()
        assert_cornell_box(image)
        assert home["camera"]["origin"] == pytest.approx([0.0, 0.0, 3.9])

        x11.drag(centre, (centre[0] + 150, centre[1]))              # left drag: orbit
        orbited, _ = screenshot()
        origin, target = np.array(orbited["camera"]["origin"]), np.array(orbited["camera"]["target"])
        assert target == pytest.approx([0.0, 0.0, 0.0])
        assert np.linalg.norm(origin - target) == pytest.approx(3.9, rel=1e-6)
        assert origin[0] < -0.5, "dragging right did not swing the camera around"

        for _ in range(2):                                          # wheel up: closer
            x11.button(4, True)
            x11.button(4, False)
            time.sleep(0.2)
        zoomed, _ = screenshot()
        distance = np.linalg.norm(np.subtract(zoomed["camera"]["origin"], zoomed["camera"]["target"]))
        assert distance < 3.5

        x11.key("z")                                                # reset
        x11.key("F1")                                               # help
        reset, image = screenshot()
        assert reset["camera"]["origin"] == pytest.approx([0.0, 0.0, 3.9])
        assert reset["help_shown"]
        assert_cornell_box(image)

        x11.key("Escape")
        assert viewer.wait_exit() == 0
    finally:
        viewer.kill()
    assert "saved screenshot" in viewer.log


def test_a_broken_shader_is_reported_and_the_old_one_keeps_drawing(display, x11, tmp_path):
    shaders = tmp_path / "shaders"
    shutil.copytree(REPO / "shaders", shaders)
    viewer = Viewer(display, ["cornell", "--gi", "off", "--shader-dir", str(shaders), "--quit-after", "600"],
                    tmp_path)
    try:
        window = viewer.ready()
        x0, y0 = x11.origin(window)
        x11.move(x0 + VIEW_CENTRE[0], y0 + VIEW_CENTRE[1])
        present = shaders / "present.glsl"
        good = present.read_text()
        present.write_text(good.replace("frag_color = vec4(", "frag_color = vec5("))
        x11.key("r")
        failure = viewer.wait_for(r"shader reload failed.*")
        assert "present.glsl" in viewer.log[failure.start():]
        count = len(viewer.lines)
        x11.key("s")
        path = viewer.wait_for(r"saved screenshot (.*)$", start=count).group(1)
        assert_cornell_box(np.asarray(Image.open(path)))            # drawn by the previous program
        present.write_text(good)
        x11.key("r")
        viewer.wait_for(r"shaders reloaded")
        x11.key("Escape")
        assert viewer.wait_exit() == 0
    finally:
        viewer.kill()


@pytest.mark.parametrize("display_variable", [None, ":4321"], ids=["no-display", "no-x-server"])
def test_without_a_window_it_says_so_and_renders_headless(tmp_path, display_variable):
    env = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY")}
    env["PYTHONPATH"] = str(REPO)
    if display_variable:
        env["DISPLAY"] = display_variable
    result = subprocess.run([sys.executable, "-m", "viewer.app", "cornell", "--gi", "off", "--size", "160x120"],
                            cwd=tmp_path, env=env, capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stderr
    expected = "no display found" if display_variable is None else "cannot open a window"
    assert expected in result.stderr
    image = np.asarray(Image.open(tmp_path / "cornell.png"))
    assert image.shape == (120, 160, 3)
    assert image.max() > 100

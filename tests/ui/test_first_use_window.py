"""The window on a scene nothing lights: it says so in the middle of the view (which is black), and once
on stderr."""

from __future__ import annotations

import numpy as np
from PIL import Image

from viewer.bench.x11 import Viewer

ROOM_OBJ = "".join(f"v {x} {y} {z}\n" for z in (-1, 1) for y in (-1, 1) for x in (-1, 1)) + (
    "f 1 3 4\nf 1 4 2\nf 5 6 8\nf 5 8 7\nf 1 2 6\nf 1 6 5\nf 3 7 8\nf 3 8 4\nf 1 5 7\nf 1 7 3\nf 2 4 8\nf 2 8 6\n")


def test_an_unlit_scene_is_said_where_the_eye_is(display, tmp_path):
    scene = tmp_path / "unlit.obj"
    scene.write_text(ROOM_OBJ)
    view, window = tmp_path / "view.png", tmp_path / "window.png"
    viewer = Viewer(display, [str(scene), "--gi", "off", "--size", "1280x720", "--screenshot", str(view),
                              "--screenshot-window", str(window)], tmp_path)
    assert viewer.wait_exit() == 0, viewer.log
    assert sum("no emitter and no sun" in line for line in viewer.lines) == 1, viewer.log
    picture = np.asarray(Image.open(window).convert("RGB"))
    assert np.asarray(Image.open(view).convert("RGB")).max() <= 8            # the view is black
    middle = picture[320:400, 300:620]                                       # the view's centre, left of the panel
    assert middle.max() >= 150, "no message over the middle of the view"


def test_the_c_key_gives_the_view_as_captures_flags(display, x11, tmp_path):
    import re
    import subprocess
    import sys

    from viewer.bench.x11 import REPO

    viewer = Viewer(display, ["cornell", "--gi", "off", "--quit-after", "600"], tmp_path)
    try:
        window = viewer.ready()
        x0, y0 = x11.origin(window)
        x11.move(x0 + 300, y0 + 300)
        x11.drag((x0 + 300, y0 + 300), (x0 + 420, y0 + 300))        # orbit: x of the eye turns negative
        count = len(viewer.lines)
        x11.key("c")
        line = viewer.wait_for(r"view: (--camera \S+ --fov \S+)$", start=count).group(1)
    finally:
        viewer.kill()
    assert re.match(r"--camera -", line), line
    out = tmp_path / "kept.png"
    result = subprocess.run([sys.executable, "-m", "viewer", "capture", "cornell", "--gi", "off", "--size", "32x24",
                             "--out", str(out), *line.split()], cwd=REPO, capture_output=True, text=True, timeout=300)
    assert result.returncode == 0 and out.is_file(), result.stderr

"""The soak's window part: files dropped one after another onto the real viewer under Xvfb, a scene
file and a bad one by turns, each drop a real XDND exchange (viewer/bench/x11.py). The viewer runs with
`--resources` and logs its resident memory and live GL objects once the picture has settled after every
load or failed load; those lines are what this reads."""

from __future__ import annotations

import shutil
from pathlib import Path
from typing import Iterator

from viewer.bench.x11 import X11, Viewer, start_xvfb, xvfb_available
from viewer.physical.gi import GISettings
from viewer.memory import Usage

BAD_FILES = {
    # first, so that a warm-up covers it: the first PLY, glTF or GLB file imports trimesh and scipy
    # (tens of MB, once)
    "empty.ply": "ply\nformat ascii 1.0\nelement vertex 3\nend_header\n0 0 0\n",   # truncated body
    "broken.obj": "v 0 0 0\nv 1 0\nf 1 2 3\n",                       # a vertex with two coordinates
    "notes.txt": "not a scene\n",                                   # a format the viewer does not read
}


def bad_files(folder: Path) -> list[Path]:
    """Files a user may drop by mistake, written into `folder`."""
    paths = []
    for name, text in BAD_FILES.items():
        (folder / name).write_text(text)
        paths.append(folder / name)
    return paths


def good_files(folder: Path, scenes: list[Path]) -> list[Path]:
    """The scene files with their material and sidecar files, copied into `folder`."""
    paths = []
    for scene in scenes:
        for sibling in scene.parent.glob(scene.stem + ".*"):
            shutil.copy(sibling, folder / sibling.name)
        paths.append(folder / scene.name)
    return paths


def viewer_arguments(scene: Path, settings: GISettings, gi: str = "compute", held: bool = True) -> list[str]:
    return [str(scene), "--gi", gi, "--voxels", str(settings.voxels), "--probes", str(settings.probes),
            "--directions", str(settings.directions), "--size", "640x360",
            "--resources", "held" if held else "resident", "--quit-after", "36000"]


def drop_files(folder: Path, scenes: list[Path], count: int, settings: GISettings, gi: str = "compute",
               held: bool = True) -> Iterator[tuple[int, str, Usage]]:
    """(step, what was dropped, Usage once settled) for the viewer's start (step 0) and each of `count`
    drops, good files on odd steps and bad ones on even steps."""
    if not xvfb_available():
        raise RuntimeError("Xvfb is not installed (apt-get install xvfb): the drops need an X server")
    good, bad = good_files(folder, scenes), bad_files(folder)
    server, display = start_xvfb()
    x11 = X11(display)
    viewer = Viewer(display, viewer_arguments(good[0], settings, gi, held), folder, timeout=900.0)
    try:
        window = viewer.ready()
        yield 0, f"start: {good[0].name}", _usage(viewer, 0)
        for step in range(1, count + 1):
            path = good[(step // 2) % len(good)] if step % 2 else bad[(step // 2 - 1) % len(bad)]
            start = len(viewer.lines)
            exchange = x11.drop(window, [path])
            if not exchange["finished"]:
                raise RuntimeError(f"the drop of {path.name} did not finish: {exchange}")
            yield step, path.name, _usage(viewer, start)
        x11.key("Escape")
        viewer.wait_exit(120)
    finally:
        viewer.kill()
        x11.close()
        server.terminate()
        server.wait(timeout=10)


def _usage(viewer: Viewer, start: int) -> Usage:
    line = viewer.wait_for(r"resources: (.*)$", start=start).group(1)
    usage = Usage.parse(line)
    if usage is None:
        raise RuntimeError(f"unreadable resources line: {line}")
    return usage

"""What the scene layer opens: regular files only, of a bounded size, checked before a byte is read, and a
scene's companions (its OBJ material libraries) only from inside the scene's own folder.

Opening a FIFO blocks until something writes to it, and a multi-gigabyte file would be read whole before
any parser could refuse it; a material library named `../elsewhere.mtl` or `/etc/passwd` reaches outside
the folder the user pointed at. The scene readers ask here first.
"""

from __future__ import annotations

import os
import stat
import sys
from pathlib import Path

from viewer.scene.types import SceneError

MAX_FILE_BYTES = 1 << 30
"""The largest scene file read (1 GiB): a 1 GiB OBJ holds about 15 M triangles, past what the viewer
voxelizes and traces in a working session on a desktop."""


def check_readable(path: Path, what: str = "scene file", limit: int = MAX_FILE_BYTES) -> None:
    """SceneError unless `path` is a regular file (after links) of at most `limit` bytes: checked with
    stat, before the file is opened."""
    try:
        info = os.stat(path)
    except OSError as exc:
        raise SceneError(f"{path}: cannot read ({exc.strerror or exc})") from None
    if not stat.S_ISREG(info.st_mode):
        kind = "a directory" if stat.S_ISDIR(info.st_mode) else "not a regular file (a pipe or a device)"
        raise SceneError(f"{path}: {kind}, not a {what}")
    if info.st_size > limit:
        raise SceneError(f"{path}: {info.st_size / 2**20:.0f} MiB, more than the {limit / 2**20:.0f} MiB a "
                         f"{what} may have")


def inside(folder: Path, name: str | Path) -> Path | None:
    """`folder / name` with every link followed, or None when it lands outside `folder` (a `..`, an absolute
    name, or a symbolic link that points elsewhere)."""
    folder = folder.resolve()
    try:
        candidate = (folder / name).resolve()
    except (OSError, ValueError, RuntimeError):
        return None
    return candidate if candidate.is_relative_to(folder) else None


def companion(scene_path: Path, name: str) -> Path | None:
    """The file `name` that the scene file names (a material library), resolved in the scene's folder;
    None, with a line on stderr saying what was skipped, when it lies outside that folder."""
    candidate = inside(scene_path.parent, name)
    if candidate is None:
        print(f"{scene_path}: skipped {name!r}: outside the scene's folder {scene_path.parent.resolve()}",
              file=sys.stderr)
    return candidate

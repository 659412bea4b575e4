"""`python -m viewer capture` and the viewer's fallback without a window: a PNG through EGL.

viewer.gpu.offscreen renders; this module adds what the command line means around it: a baked grid
(`capture FILE.npz`) shows the scene it was baked from lit by its probes, and a capture error is bad
input (one line, exit status 2). GL is imported only when a capture runs.
"""

from __future__ import annotations

import sys

from viewer.errors import InputError


def run_capture(args) -> int:
    """The capture args describe (see viewer.gpu.offscreen.run_capture); returns the exit status 0."""
    from viewer.gpu import offscreen

    probe_source = baked_probe_source(args)
    try:
        return offscreen.run_capture(args, probe_source)
    except offscreen.CaptureError as exc:
        raise InputError(str(exc)) from None


def baked_probe_source(args):
    """For `capture FILE.npz` (and the headless `gi-viewer FILE.npz`): point args at the scene the grid was
    baked from, with its sun, and return a probe source that hands over the baked indirect light whatever
    `--gi` names (`--gi off` still shows direct light only). None when args.scene is not a baked file."""
    from viewer.bake import grid as baked

    if not baked.is_baked_file(args.scene):
        return None
    if getattr(args, "sun", None):
        raise InputError("--sun: a baked grid keeps the sun it was baked with")
    grid, path = baked.read_npz(args.scene), args.scene
    args.scene, args.sun = baked.scene_source(grid, path), grid.sun

    def probe_source(scene, gi, ctx):
        print(f"capture: the probes baked in {path} stand in for --gi {gi}", file=sys.stderr)
        return grid.indirect
    return probe_source

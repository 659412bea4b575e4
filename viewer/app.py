"""`python -m viewer`: the viewer on a scene (the built-in Cornell box by default).

The interactive window (moderngl-window, imgui) is the next piece of work; until it lands, and always
where there is no display, this renders the scene headless through EGL to a PNG and says where it went.
"""

from __future__ import annotations

import os
import sys
from types import SimpleNamespace

from viewer.gi import GISettings


def run(args) -> int:
    from viewer.cli import run_capture

    out = getattr(args, "out", None) or f"{os.path.splitext(os.path.basename(str(args.scene)))[0]}.png"
    if not os.environ.get("DISPLAY") and not os.environ.get("WAYLAND_DISPLAY"):
        print(f"viewer: no display found; rendering {args.scene} headless to {out}", file=sys.stderr)
    else:
        print(f"viewer: the interactive window is not built yet; rendering {args.scene} to {out}",
              file=sys.stderr)
    d = GISettings()
    capture = SimpleNamespace(scene=args.scene, out=out, size="1280x720", gi="solver", view="final",
                              camera=None, fov=None, exposure=0.0, sun=None, voxels=d.voxels,
                              probes=d.probes, kernel=d.kernel, bounces=d.bounces,
                              directions=d.directions, dering=d.dering)
    status = run_capture(capture)
    if status == 0:
        print(f"viewer: wrote {os.path.abspath(out)}", file=sys.stderr)
    return status

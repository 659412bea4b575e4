"""`python -m viewer capture` and the viewer's fallback without a window: a PNG through EGL.

viewer.gpu.offscreen renders a CaptureRequest; this module adds what the command line means around it:
`capture_request` builds the request from the flags, a baked grid (`capture FILE.npz`) shows the scene it
was baked from lit by its probes, and a capture error is bad input (one line, exit status 2). GL is
imported only when a capture runs.
"""

from __future__ import annotations

import sys
from dataclasses import replace
from types import SimpleNamespace

from viewer.cli_parsing import CAPTURE_SIZES, dataclass_from_args, gi_settings, parse_camera, parse_size
from viewer.errors import InputError
from viewer.gpu.capture_request import CaptureError, CaptureRequest
from viewer.gpu.render_settings import RenderSettings

RENDER_FIELDS = ("exposure", "tonemap", "light_samples", "voxel_color")
"""The RenderSettings a capture has flags for (`--exposure`, `--tonemap`, `--light-samples`, `--voxel-color`)."""


def capture_request(args, **changes) -> CaptureRequest:
    """The CaptureRequest of the capture flags on args (`python -m viewer capture`, or the viewer's own
    flags for its picture without a window); a flag missing from args takes its default, `changes`
    replace what args say. Bad values are bad input (InputError)."""
    args = SimpleNamespace(**{**vars(args), **changes})
    value = lambda name, default=None: default if getattr(args, name, None) is None else getattr(args, name)
    size = value("size", CaptureRequest.size)
    if isinstance(size, str):
        size = parse_size(size, *CAPTURE_SIZES, example="640x480")
    camera = value("camera")
    if isinstance(camera, str):
        camera = parse_camera(camera)
    sun = value("sun")
    if isinstance(sun, str):
        from viewer.scene import parse_sun

        sun = parse_sun(sun)
    try:
        render = dataclass_from_args(RenderSettings, args, RENDER_FIELDS)
    except ValueError as exc:
        raise InputError(f"capture: {exc}") from None
    return CaptureRequest(out=value("out"), scene=str(value("scene", CaptureRequest.scene)), size=size,
                          gi=value("gi", CaptureRequest.gi), view=value("view", CaptureRequest.view),
                          camera=camera, fov=value("fov"), render=render,
                          msaa=int(value("msaa", CaptureRequest.msaa)), sun=sun, gi_settings=gi_settings(args),
                          model=value("model"))


def run_capture(request: CaptureRequest) -> int:
    """Render the request (see viewer.gpu.offscreen.run_capture); returns the exit status 0."""
    from viewer.gpu import offscreen

    request, probe_source = baked_probe_source(request)
    try:
        return offscreen.run_capture(request, probe_source)
    except CaptureError as exc:
        raise InputError(str(exc)) from None


def baked_probe_source(request: CaptureRequest):
    """For `capture FILE.npz` (and the headless `gi-viewer FILE.npz`): the request pointed at the scene the
    grid was baked from, with its sun, and a probe source that hands over the baked indirect light whatever
    `--gi` names (`--gi off` still shows direct light only). The request as it is and None when its scene
    is not a baked file."""
    from viewer.bake import grid as baked

    if not baked.is_baked_file(request.scene):
        return request, None
    if request.sun is not None:
        raise InputError("--sun: a baked grid keeps the sun it was baked with")
    grid, path = baked.read_npz(request.scene), request.scene
    request = replace(request, scene=baked.scene_source(grid, path), sun=grid.sun)

    def probe_source(scene, gi, ctx):
        print(f"capture: the probes baked in {path} stand in for --gi {gi}", file=sys.stderr)
        return grid.indirect
    return request, probe_source

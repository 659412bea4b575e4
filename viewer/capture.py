"""`python -m viewer capture` and the viewer's fallback without a window: a PNG through EGL.

viewer.gpu.offscreen renders a scene and its probes; this module adds what the command line means around
it: `capture_request` builds a CaptureRequest from the flags, `render` checks it, solves the GI source it
names (viewer.sources) and renders it, a baked grid (`capture FILE.npz`) shows the scene it was baked from
lit by its probes, and a capture error is bad input (one line, exit status 2). GL is imported only when a
capture runs.
"""

from __future__ import annotations

import sys
import time
from dataclasses import replace
from pathlib import Path
from types import SimpleNamespace
from typing import TYPE_CHECKING, Callable

from viewer import sources
from viewer.cli_parsing import CAPTURE_SIZES, dataclass_from_args, gi_settings, parse_camera, parse_size
from viewer.errors import InputError
from viewer.gpu.capture_request import MAX_SIZE, CaptureError, CaptureRequest
from viewer.gpu.render_settings import RenderSettings
from viewer.progress import step

if TYPE_CHECKING:  # types only: GL is imported when a capture runs
    import moderngl

    from viewer.probes.grid import ProbeGrid
    from viewer.scene import Scene

ProbeSource = Callable[["Scene", str, "moderngl.Context"], "ProbeGrid | None"]
"""(scene, gi mode, GL context) -> the indirect-light ProbeGrid for that mode (None: GI off). The
context lets a GPU solver run on the same context the renderer uses."""

RENDER_FIELDS = ("exposure", "tonemap", "light_samples", "voxel_color", "lightmap_faces")
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
                          msaa=int(value("msaa", CaptureRequest.msaa)), sun=sun,
                          gi_settings=gi_settings(args, size, int(value("msaa", CaptureRequest.msaa)),
                                                  max(1, int(value("turntable", 1)))),
                          model=value("model"), turntable=int(value("turntable", 0)),
                          supersample=int(value("supersample", CaptureRequest.supersample)))


def run_capture(request: CaptureRequest) -> int:
    """Render the request (`render`), a baked grid's probes standing in for its GI source when its scene
    is a baked .npz; bad input is InputError. Returns the exit status 0."""
    request, probe_source = baked_probe_source(request)
    try:
        return render(request, probe_source)
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
    probe_source.label = "baked"
    return request, probe_source


def solver_probes(request: CaptureRequest) -> ProbeSource:
    """The probe source for a `gi` source of viewer.sources that solves (the compute-shader solver on the
    capture's own context, the numpy solver, the network of the request's model), with the request's GI
    settings, indirect light only."""
    def source(scene, gi: str, ctx):
        settings = request.gi_settings
        spec = sources.SOURCES.get(gi)
        if spec is None or spec.solve is None:
            raise CaptureError(f"--gi {gi}: unknown GI source")
        options = sources.SolveOptions(include_emitted=False, ctx=ctx, model=request.model)
        try:
            return spec.solve(scene, settings, options)[0]
        except sources.SourceError as exc:
            raise CaptureError(f"--gi {gi}: {exc}") from None
    return source


def render(request: CaptureRequest, probe_source: ProbeSource | None = None) -> int:
    """Render `request` and write its picture.

    probe_source builds the ProbeGrid for a `gi` mode other than off (default: `solver_probes`).
    Bad input raises CaptureError or scene.SceneError (both ValueErrors) with a one-line message.
    Returns the exit status 0.
    """
    from viewer.gpu.camera import look_at
    from viewer.gpu.context import create_context
    from viewer.gpu.offscreen import capture
    from viewer.gpu.renderer import VIEWS
    from viewer.gpu.shadows import MAX_LIGHT_SAMPLES
    from viewer.scene import Camera, load, note, unlit_warning

    out = request.out
    if not out:
        raise CaptureError("capture needs --out FILE.png")
    scene = load(request.scene, sun=request.sun)
    size = (int(request.size[0]), int(request.size[1]))
    if not (0 < size[0] <= MAX_SIZE and 0 < size[1] <= MAX_SIZE):
        raise CaptureError(f"--size {size[0]}x{size[1]}: each side must be 1..{MAX_SIZE}")
    gi = request.gi
    if gi not in sources.chosen_by_name():
        raise CaptureError(f"--gi {gi!r}: expected one of {', '.join(sources.chosen_by_name())}")
    view = request.view
    if view not in VIEWS:
        raise CaptureError(f"--view {view!r}: expected one of {', '.join(VIEWS)}")
    fov = request.fov
    if fov is not None and not 0.0 < float(fov) < 180.0:
        raise CaptureError(f"--fov {fov}: expected degrees between 0 and 180")
    camera = request.camera
    if camera is not None and not isinstance(camera, Camera):   # (origin, target)
        try:
            camera = look_at(*camera, float(fov) if fov is not None else scene.camera.fov)
        except ValueError as exc:
            raise CaptureError(str(exc)) from None
    elif camera is None:  # the viewer's opening view: the file's camera, else one framing the scene
        from viewer.scene.camera import home_camera

        camera = home_camera(scene, request.scene, aspect=size[0] / size[1])
        if fov is not None:
            camera = replace(camera, fov=float(fov))
    settings = replace(request.render)   # the renderer may change its settings: not the request's
    if settings.lightmap_faces < 0:
        raise CaptureError(f"--lightmap-faces {settings.lightmap_faces}: expected 0 or more")
    if not 0 <= settings.light_samples <= MAX_LIGHT_SAMPLES:
        raise CaptureError(f"--light-samples {settings.light_samples}: expected 0..{MAX_LIGHT_SAMPLES}")
    suffix = Path(out).suffix.lower()
    if request.turntable and (suffix != ".gif" or not 2 <= request.turntable <= 720):
        raise CaptureError(f"--turntable {request.turntable}: expected 2..720 frames written to a .gif --out")
    if suffix not in (".png", ".jpg", ".jpeg", ".npy") and not request.turntable:
        raise CaptureError(f"--out {out}: expected a .png (or .jpg, or .npy for linear HDR radiance)")
    if not Path(out).resolve().parent.is_dir():
        raise CaptureError(f"--out {out}: the folder {Path(out).parent} does not exist")

    unlit = unlit_warning(scene)
    if unlit:   # every light the solve and the final gather could find is black: neither runs
        note(unlit)
    start = time.perf_counter()
    ctx = create_context()
    try:
        probes = None
        if sources.SOURCES[gi].solve is not None and not unlit:   # off solves nothing: direct light only
            if probe_source is None:
                with step(f"capture: solving the indirect light ({sources.SOURCES[gi].label})"):
                    probes = solver_probes(request)(scene, gi, ctx)
            else:
                probes = probe_source(scene, gi, ctx)
        solved = time.perf_counter()
        voxels, radiance = _debug_voxels(scene, view, settings, request.gi_settings.voxels)
        gathers = (probes is not None and view in ("final", "indirect") and settings.final_gather and settings.baked
                   and int((scene.face_areas > 0).sum()) <= settings.lightmap_faces)
        with step(f"capture: rendering {size[0]}x{size[1]}"
                  + (" (the lightmap's final gather traces its rays)" if gathers else "")):
            if request.turntable:
                turntable(scene, probes, out, size, view, camera, settings, voxels, radiance, request, ctx)
            else:
                capture(scene, probes, out, size=size, view=view, camera=camera, settings=settings,
                        voxels=voxels, voxel_radiance=radiance, samples=int(request.msaa), ctx=ctx,
                        supersample=int(request.supersample))
    finally:
        ctx.release()
    shown = (getattr(probe_source, "label", None) if probes is not None else None) or gi
    if unlit and sources.SOURCES[gi].solve is not None:
        shown += ", not solved: nothing emits"
    print(f"capture: {out} ({size[0]}x{size[1]}, view {view}, gi {shown}); probes {solved - start:.2f} s, "
          f"render {time.perf_counter() - solved:.2f} s", file=sys.stderr)
    return 0


def turntable(scene, probes, out, size, view, camera, settings, voxels, radiance, request, ctx) -> None:
    """`capture --turntable N`: N frames of the camera turned about the vertical axis through the scene's
    centre (its height and distance kept), as a looping animated GIF of 25 frames a second. The scene,
    its probes and its lightmap are set up once; each frame is one more draw."""
    import math

    import numpy as np
    from PIL import Image

    from viewer.gpu.offscreen import OffscreenRenderer
    from viewer.output import replacing
    from viewer.scene import Camera

    lo, hi = scene.bounds
    centre = 0.5 * (np.asarray(lo) + np.asarray(hi))
    offset = np.asarray(camera.origin, np.float64) - centre
    target = np.asarray(camera.target, np.float64) - centre
    offscreen = OffscreenRenderer(size, settings, int(request.msaa), ctx)
    frames = []
    try:
        offscreen.renderer.set_scene(scene)
        offscreen.renderer.set_probes(probes)
        if view == "voxels":
            offscreen.renderer.set_voxels(voxels, radiance)
        for index in range(request.turntable):
            angle = 2.0 * math.pi * index / request.turntable
            c, s = math.cos(angle), math.sin(angle)
            turn = np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])
            frame = Camera(tuple(centre + turn @ offset), tuple(centre + turn @ target), camera.up, camera.fov)
            frames.append(Image.fromarray(offscreen.render(frame, view, int(request.supersample))))
    finally:
        offscreen.release()
    with replacing(out) as file:   # whole or not at all, as every picture
        frames[0].save(file, format="GIF", save_all=True, append_images=frames[1:], duration=40, loop=0)


def _debug_voxels(scene, view: str, settings: RenderSettings, resolution: int):
    """Voxels (and their solved radiance, when the view colours by it) for the `voxels` view."""
    if view != "voxels":
        return None, None
    from viewer.rays.voxels import voxelize

    voxels = voxelize(scene, int(resolution))
    if settings.voxel_color != "radiance":
        return voxels, None
    from viewer.physical import transport

    return voxels, transport.solve(voxels, scene.sun).radiance

"""Headless rendering: a Scene (+ ProbeGrid) -> an image array or a PNG, through an EGL context.

    image = capture(scene, probes, "out.png", size=(640, 480), view="final")

`capture` is what `python -m viewer capture` runs (via `run_capture`), and what tests and benchmarks use.
An `.npy` output path saves the linear HDR radiance (H, W, 3) float32 instead of a PNG, for numeric
comparisons with the path-traced reference.
"""

from __future__ import annotations

import sys
import time
from dataclasses import replace
from pathlib import Path
from typing import Callable

import moderngl
import numpy as np

from viewer.gpu.camera import parse_camera
from viewer.gpu.context import create_context
from viewer.gpu.renderer import VIEWS, RenderSettings, Renderer
from viewer.gpu.shadows import MAX_LIGHT_SAMPLES
from viewer.gpu.targets import DisplayTarget, HdrTarget
from viewer.probes.grid import ProbeGrid
from viewer.scene import Camera, Scene

GI_MODES = ("off", "compute", "solver", "neural")
MAX_SIZE = 8192


class CaptureError(ValueError):
    """Bad capture input (size, camera, view, GI mode, output path): one line, exit status 2."""


ProbeSource = Callable[[Scene, str, moderngl.Context], "ProbeGrid | None"]
"""(scene, gi mode, GL context) -> the indirect-light ProbeGrid for that mode (None: GI off). The
context lets a GPU solver run on the same context the renderer uses."""


class OffscreenRenderer:
    """A renderer with its own headless context and targets of one size: a display target (the 8-bit
    image a window would show, drawn as the window draws it) and, when asked for, an HDR target."""

    def __init__(self, size: tuple[int, int] = (512, 512), settings: RenderSettings | None = None,
                 samples: int = 4, ctx: moderngl.Context | None = None):
        self._owns_context = ctx is None
        self.ctx = ctx or create_context()
        self.size = (int(size[0]), int(size[1]))
        self.samples = min(int(samples), self.ctx.max_samples)
        self.renderer = Renderer(self.ctx, settings)
        self.display = DisplayTarget(self.ctx, self.size, samples=self.samples)
        self._hdr: HdrTarget | None = None

    @property
    def settings(self) -> RenderSettings:
        return self.renderer.settings

    @property
    def hdr(self) -> HdrTarget:
        if self._hdr is None:
            self._hdr = HdrTarget(self.ctx, self.size, samples=self.samples)
        return self._hdr

    def render_hdr(self, camera: Camera | None = None, view: str = "final") -> np.ndarray:
        """(H, W, 3) float32 linear values (radiance, or the debug quantity of `view`)."""
        self.renderer.draw(self.hdr, camera, view)
        return self.hdr.read()

    def render(self, camera: Camera | None = None, view: str = "final") -> np.ndarray:
        """(H, W, 3) uint8 sRGB display image."""
        self.renderer.draw(self.display, camera, view)
        return self.display.read()

    def frame_time(self, camera: Camera | None = None, view: str = "final", frames: int = 7) -> float:
        """Median milliseconds of a frame (a draw into the display target and its blit to another
        framebuffer of that size, as the window does, waited for with glFinish) after a warm-up."""
        return float(np.median(self.frame_times(camera, view, frames)))

    def frame_times(self, camera: Camera | None = None, view: str = "final", frames: int = 7) -> list[float]:
        """Milliseconds of each of `frames` frames (see frame_time)."""
        screen = DisplayTarget(self.ctx, self.size)
        try:
            self.render(camera, view)
            times = []
            for _ in range(frames):
                start = time.perf_counter()
                self.renderer.draw(self.display, camera, view)
                self.renderer.present(self.display, screen.resolved, view)
                self.ctx.finish()
                times.append(1e3 * (time.perf_counter() - start))
        finally:
            screen.release()
        return times

    def release(self) -> None:
        self.renderer.release()
        self.display.release()
        if self._hdr is not None:
            self._hdr.release()
        if self._owns_context:
            self.ctx.release()


def capture(scene: Scene, probes: ProbeGrid | None, out_path: str | Path | None = None,
            size: tuple[int, int] = (512, 512), view: str = "final", camera: Camera | None = None,
            settings: RenderSettings | None = None, voxels=None, voxel_radiance: np.ndarray | None = None,
            samples: int = 4, ctx: moderngl.Context | None = None) -> np.ndarray:
    """Render one image headless and save it (PNG, or `.npy` for linear HDR) if `out_path` is given.

    probes: indirect-light ProbeGrid or None (GI off). view: one of VIEWS; `voxels` voxelizes the scene
    (32^3) unless `voxels` is given. samples: multisampling (edge anti-aliasing). Returns the uint8
    display image (H, W, 3), or the float32 HDR image for an `.npy` path.
    """
    if view not in VIEWS:
        raise CaptureError(f"view must be one of {', '.join(VIEWS)}, not {view!r}")
    width, height = int(size[0]), int(size[1])
    if not (0 < width <= MAX_SIZE and 0 < height <= MAX_SIZE):
        raise CaptureError(f"image size must be 1..{MAX_SIZE} pixels each way, got {width}x{height}")
    hdr_out = out_path is not None and Path(out_path).suffix.lower() == ".npy"
    if out_path is not None and not hdr_out and Path(out_path).suffix.lower() not in (".png", ".jpg", ".jpeg"):
        raise CaptureError(f"{out_path}: the output must be a .png (or .jpg, or .npy for linear HDR)")
    if view == "voxels" and voxels is None:
        from viewer.rays.voxels import voxelize
        voxels = voxelize(scene, 32)
    offscreen = OffscreenRenderer((width, height), settings, samples, ctx)
    try:
        renderer = offscreen.renderer
        renderer.set_scene(scene)
        renderer.set_probes(probes)
        if view == "voxels":
            renderer.set_voxels(voxels, voxel_radiance)
        image = offscreen.render_hdr(camera, view) if hdr_out else offscreen.render(camera, view)
    finally:
        offscreen.release()
    if out_path is not None:
        save(image, out_path)
    return image


def save(image: np.ndarray, path: str | Path) -> None:
    path = Path(path)
    if not path.resolve().parent.is_dir():
        raise CaptureError(f"{path}: the folder {path.parent} does not exist")
    if path.suffix.lower() == ".npy":
        np.save(path, image)
    else:
        from PIL import Image
        Image.fromarray(image).save(path)


# ---- command line ----------------------------------------------------------------------------------

def parse_size(text: str) -> tuple[int, int]:
    """`WxH` -> (W, H)."""
    try:
        width, height = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise CaptureError(f"--size {text!r}: expected WxH, e.g. 640x480") from None
    if not (0 < width <= MAX_SIZE and 0 < height <= MAX_SIZE):
        raise CaptureError(f"--size {text!r}: each side must be 1..{MAX_SIZE}")
    return width, height


def solver_probes(args) -> ProbeSource:
    """The probe source for `--gi solver` (the numpy transport solver, viewer.physical.gi.solve) and `--gi compute`
    (the compute-shader solver on the capture's own context), with the GI settings found on args
    (voxels, probes, kernel, bounces, directions, dering; defaults otherwise), indirect light only."""
    def source(scene: Scene, gi: str, ctx) -> ProbeGrid | None:
        from viewer.physical import gi as solver

        names = ("voxels", "probes", "kernel", "bounces", "directions", "dering")
        settings = solver.GISettings(**{name: getattr(args, name) for name in names
                                        if getattr(args, name, None) is not None})
        if gi == "solver":
            return solver.solve(scene, settings, include_emitted=False)
        if gi == "compute":
            from viewer.gpu.compute_relight import solve_probes

            return solve_probes(ctx, scene, settings, include_emitted=False)
        if gi == "neural":
            from viewer.neural.field import DEFAULT_MODEL, ModelError, NeuralField

            try:
                field = NeuralField(getattr(args, "model", None) or DEFAULT_MODEL)
            except ModelError as exc:
                raise CaptureError(f"--gi neural: {exc}") from None
            from viewer.neural.domain import print_warning

            print_warning(scene, field.card.domain)
            return field.solve(scene, include_emitted=False)
        raise CaptureError(f"--gi {gi}: unknown GI source")
    return source


def run_capture(args, probe_source: ProbeSource | None = None) -> int:
    """`python -m viewer capture`. Reads from args (a missing attribute takes its default):

    scene (name or file, default cornell), out (.png/.jpg, or .npy for linear HDR; required),
    size ("WxH" or (W, H); 512x512), gi (off|compute|solver|neural; off), view (one of VIEWS; final),
    camera ("ox,oy,oz,tx,ty,tz"; the one the viewer opens the scene with), fov (degrees; that camera's),
    exposure (EV; 0),
    tonemap (aces|reinhard|none; aces), msaa (samples; 4), light_samples (32), sun ("dx,dy,dz,r,g,b"),
    voxel_color (albedo|radiance; albedo) and the GI settings of `solver_probes`.

    probe_source builds the ProbeGrid for a `--gi` mode other than off (default: `solver_probes`).
    Bad input raises CaptureError or scene.SceneError (both ValueErrors) with a one-line message.
    Returns the exit status 0.
    """
    from viewer.scene import load, parse_sun

    value = lambda name, default=None: default if getattr(args, name, None) is None else getattr(args, name)
    out = value("out")
    if not out:
        raise CaptureError("capture needs --out FILE.png")
    sun = value("sun")
    scene = load(value("scene", "cornell"), sun=parse_sun(sun) if isinstance(sun, str) else sun)
    size = value("size", (512, 512))
    size = parse_size(size) if isinstance(size, str) else (int(size[0]), int(size[1]))
    gi = value("gi", "off")
    if gi not in GI_MODES:
        raise CaptureError(f"--gi {gi!r}: expected one of {', '.join(GI_MODES)}")
    view = value("view", "final")
    if view not in VIEWS:
        raise CaptureError(f"--view {view!r}: expected one of {', '.join(VIEWS)}")
    fov = value("fov")
    if fov is not None and not 0.0 < float(fov) < 180.0:
        raise CaptureError(f"--fov {fov}: expected degrees between 0 and 180")
    camera = value("camera")
    if isinstance(camera, str):
        try:
            camera = parse_camera(camera, float(fov) if fov is not None else scene.camera.fov)
        except ValueError as exc:
            raise CaptureError(str(exc)) from None
    elif camera is None:  # the viewer's opening view: the file's camera, else one framing the scene
        from viewer.scene.camera import home_camera

        camera = home_camera(scene, value("scene", "cornell"))
        if fov is not None:
            camera = replace(camera, fov=float(fov))
    try:
        settings = RenderSettings(exposure=float(value("exposure", 0.0)), tonemap=value("tonemap", "aces"),
                                  light_samples=int(value("light_samples", 32)),
                                  voxel_color=value("voxel_color", "albedo"))
    except ValueError as exc:
        raise CaptureError(f"capture: {exc}") from None
    if not 0 <= settings.light_samples <= MAX_LIGHT_SAMPLES:
        raise CaptureError(f"--light-samples {settings.light_samples}: expected 0..{MAX_LIGHT_SAMPLES}")
    suffix = Path(out).suffix.lower()
    if suffix not in (".png", ".jpg", ".jpeg", ".npy"):
        raise CaptureError(f"--out {out}: expected a .png (or .jpg, or .npy for linear HDR radiance)")
    if not Path(out).resolve().parent.is_dir():
        raise CaptureError(f"--out {out}: the folder {Path(out).parent} does not exist")

    start = time.perf_counter()
    ctx = create_context()
    try:
        probes = None
        if gi != "off":
            probes = (probe_source or solver_probes(args))(scene, gi, ctx)
        solved = time.perf_counter()
        voxels, radiance = _debug_voxels(scene, view, settings, value("voxels", 32))
        capture(scene, probes, out, size=size, view=view, camera=camera, settings=settings, voxels=voxels,
                voxel_radiance=radiance, samples=int(value("msaa", 4)), ctx=ctx)
    finally:
        ctx.release()
    print(f"capture: {out} ({size[0]}x{size[1]}, view {view}, gi {gi}); probes {solved - start:.2f} s, "
          f"render {time.perf_counter() - solved:.2f} s", file=sys.stderr)
    return 0


def _debug_voxels(scene: Scene, view: str, settings: RenderSettings, resolution: int):
    """Voxels (and their solved radiance, when the view colours by it) for the `voxels` view."""
    if view != "voxels":
        return None, None
    from viewer.rays.voxels import voxelize

    voxels = voxelize(scene, int(resolution))
    if settings.voxel_color != "radiance":
        return voxels, None
    from viewer.physical import transport

    return voxels, transport.solve(voxels, scene.sun).radiance

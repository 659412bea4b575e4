"""Headless rendering: a Scene (+ ProbeGrid) -> an image array or a PNG, through an EGL context.

    image = capture(scene, probes, "out.png", size=(640, 480), view="final")

`capture` is what `python -m viewer capture` runs (via `run_capture`, which renders a CaptureRequest), and
what tests and benchmarks use.
An `.npy` output path saves the linear HDR radiance (H, W, 3) float32 instead of a PNG, for numeric
comparisons with the path-traced reference.
"""

from __future__ import annotations

import time
from pathlib import Path

import moderngl
import numpy as np

from viewer.gpu.capture_request import MAX_SIZE, CaptureError
from viewer.gpu.context import create_context
from viewer.gpu.renderer import VIEWS, RenderSettings, Renderer
from viewer.gpu.targets import DisplayTarget, HdrTarget
from viewer.probes.grid import ProbeGrid
from viewer.scene import Camera, Scene
from viewer.output import replacing

__all__ = ["CaptureError", "MAX_SIZE", "OffscreenRenderer", "capture", "save"]

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

    def render_hdr(self, camera: Camera | None = None, view: str = "final", supersample: int = 1) -> np.ndarray:
        """(H, W, 3) float32 linear values (radiance, or the debug quantity of `view`). `supersample` n:
        the mean of n x n images, each one sample a pixel at a stratified offset inside it: the box filter
        in linear light that a path tracer's image has. The multisampling's 4 samples leave a lamp's
        edge stepped where it is hundreds of times brighter than the ceiling beside it: on the box
        scenes against Mitsuba (1024 samples a pixel, box filter) 37.4-37.6 dB PSNR with them, 38.1 at
        n = 8 and 41.6 at n = 16 (docs/GALLERY.md)."""
        if supersample <= 1:
            self.renderer.draw(self.hdr, camera, view)
            return self.hdr.read()
        single = HdrTarget(self.ctx, self.size, samples=0)
        try:
            return self._supersampled(single, camera, view, supersample)
        finally:
            single.release()

    def render(self, camera: Camera | None = None, view: str = "final", supersample: int = 1) -> np.ndarray:
        """(H, W, 3) uint8 sRGB display image; with `supersample` n > 1, `render_hdr`'s n x n images
        averaged in linear light, then tone mapped."""
        if supersample > 1:
            single = HdrTarget(self.ctx, self.size, samples=0)
            try:
                image = self._supersampled(single, camera, view, supersample)
                rgba = np.concatenate([image, np.ones(image.shape[:2] + (1,), np.float32)], axis=2)
                single.texture.write(np.ascontiguousarray(rgba[::-1]).tobytes())   # the mean, to tone map
                self.renderer.present(single, self.display, view)
                return self.display.read()
            finally:
                single.release()
        self.renderer.draw(self.display, camera, view)
        return self.display.read()

    def _supersampled(self, single: HdrTarget, camera: Camera | None, view: str, n: int) -> np.ndarray:
        """(H, W, 3) float32: the mean of n x n images drawn into `single` (one sample a pixel: a
        multisample would move out of the pixel) at an n x n grid of offsets inside the pixel."""
        total = np.zeros((self.size[1], self.size[0], 3), np.float64)
        for i in range(n):
            for j in range(n):
                self.renderer.draw(single, camera, view, jitter=((i + 0.5) / n - 0.5, (j + 0.5) / n - 0.5))
                total += single.read()
        return (total / (n * n)).astype(np.float32)

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
            samples: int = 4, ctx: moderngl.Context | None = None, supersample: int = 1) -> np.ndarray:
    """Render one image headless and save it (PNG, or `.npy` for linear HDR) if `out_path` is given.

    probes: indirect-light ProbeGrid or None (GI off). view: one of VIEWS; `voxels` voxelizes the scene
    (32^3) unless `voxels` is given. samples: multisampling (edge anti-aliasing); supersample n > 1:
    n x n subpixel images averaged in linear light instead (`OffscreenRenderer.render_hdr`). Returns
    the uint8 display image (H, W, 3), or the float32 HDR image for an `.npy` path.
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
        image = (offscreen.render_hdr(camera, view, supersample) if hdr_out
                 else offscreen.render(camera, view, supersample))
    finally:
        offscreen.release()
    if out_path is not None:
        save(image, out_path)
    return image


def save(image: np.ndarray, path: str | Path) -> None:
    path = Path(path)
    if not path.resolve().parent.is_dir():
        raise CaptureError(f"{path}: the folder {path.parent} does not exist")
    with replacing(path) as out:
        if path.suffix.lower() == ".npy":
            np.save(out, image)
        else:
            from PIL import Image

            Image.fromarray(image).save(out, format=Image.registered_extensions().get(path.suffix.lower(), "PNG"))

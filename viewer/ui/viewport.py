"""The 3D view inside the window: when to draw the scene, at what resolution, and presenting it.

A full-resolution frame of the renderer costs tens of milliseconds on a software GL (llvmpipe), so
the scene is drawn only when something it depends on changed (camera, view, scene, probes, render
settings, exposure and tone curve included: the renderer tone-maps as it shades, into an 8-bit sRGB
DisplayTarget), and while the user is moving the camera or dragging a slider it is drawn at a reduced
"preview" resolution; the first frame after that replaces the preview with a full-resolution image.
Presenting that image is a blit (a bilinear pass for a preview) and happens every frame.

The still image's edges are anti-aliased by refinement (`refine`): the frames after it each draw one
more image, moved by a subpixel jitter, and average it in (viewer/gpu/targets.py RefiningTarget), until
`refine` images are in. Each such frame costs one single-sampled frame and a full-screen pass, where
multisampling (`samples`, the alternative) makes every still frame 3-4 times as costly on llvmpipe.
"""

from __future__ import annotations

from dataclasses import astuple

import moderngl
import numpy as np

from viewer.gpu.programs import ShaderError
from viewer.gpu.renderer import Renderer
from viewer.gpu.targets import DisplayTarget, RefiningTarget
from viewer.scene import Camera


class Viewport:
    def __init__(self, ctx: moderngl.Context, renderer: Renderer, render_scale: float = 1.0,
                 preview_scale: float = 0.5, samples: int = 0, refine: int = 0):
        self.ctx = ctx
        self.renderer = renderer
        self.render_scale = render_scale
        """Full-quality resolution as a fraction of the window's."""
        self.preview_scale = preview_scale
        """Resolution while things move, as a fraction of the full-quality one."""
        self.samples = samples
        """Multisampling of the full-quality image (edge anti-aliasing). Previews, drawn while the camera
        or a slider moves, are not multisampled: what moves keeps its frame rate, and the still image,
        drawn once, has clean edges."""
        self.refine = refine
        """Images averaged into the still image, one more a frame (1 or 0: off); with `samples` above 1 the
        still image is multisampled instead."""
        self._targets: dict[str, DisplayTarget] = {}
        self._key = None              # what the view should show now
        self._drawn: tuple | None = None   # (key, quality) of the image in `_shown`
        self._shown: DisplayTarget | None = None
        self._refinable = False   # the view shown is one the renderer refines (drawn in one pass)
        self.error: str | None = None
        """The last draw's shader error (the previous image stays up until a draw succeeds)."""

    def _settings_key(self) -> tuple:
        s = self.renderer.settings
        return tuple(getattr(s, f) for f in s.__dataclass_fields__)

    def _target(self, quality: str, window_size: tuple[int, int]) -> DisplayTarget:
        scale = self.render_scale * (self.preview_scale if quality == "preview" else 1.0)
        size = (max(1, round(window_size[0] * scale)), max(1, round(window_size[1] * scale)))
        samples = min(self.samples, self.ctx.max_samples) if quality == "full" else 0
        refining = quality == "full" and samples <= 1 and self.refine > 1
        target = self._targets.get(quality)
        if (target is None or target.size != size or target.samples != samples
                or isinstance(target, RefiningTarget) != refining):
            if target is not None:
                if target is self._shown:
                    self._shown, self._drawn = None, None
                target.release()
            target = (RefiningTarget(self.ctx, size, self.renderer.programs) if refining
                      else DisplayTarget(self.ctx, size, samples=samples))
            self._targets[quality] = target
        return target

    @property
    def refining(self) -> bool:
        """The still image is shown and more images are to be averaged into it (a frame each)."""
        shown = self._shown
        return (self.drawn and isinstance(shown, RefiningTarget) and 0 < shown.images < self.refine
                and self._refinable)

    @property
    def drawn(self) -> bool:
        """The image shown is the full-resolution one of the current state (the probes perhaps read per
        fragment, or gathered with stale rays, while the renderer is `baking`)."""
        return self._drawn == (self._key, "full")

    @property
    def settled(self) -> bool:
        """The image shown is the full-resolution one of the current state, its indirect lightmap baked and
        its refinement done."""
        return self.drawn and not self.renderer.baking and not self.refining

    def frame(self, camera: Camera, view: str, content_key: tuple, framebuffer: moderngl.Framebuffer,
              preview: bool = False, force: bool = False) -> bool:
        """Draw the scene if needed, then present it into `framebuffer`. Returns whether it drew.

        content_key: anything else the image depends on (scene and probe versions). preview: the user is
        interacting; a changed image is then drawn at the preview resolution. force: draw even if
        nothing changed."""
        window_size = tuple(framebuffer.viewport[2:])
        key = (astuple(camera), view, content_key, self._settings_key(), window_size, self.render_scale,
               self.samples, self.refine, self.renderer.bake_version())
        self._key = key
        quality = "preview" if preview and self.preview_scale < 1.0 else "full"
        drew = False
        redraw = force or self._drawn is None or self._drawn[0] != key or (self._drawn[1] == "preview" and quality == "full")
        if redraw or (quality == "full" and self.refining):
            target = self._target(quality, window_size)
            if redraw and isinstance(target, RefiningTarget):
                target.restart()
                self._refinable = self.renderer.fused(target, view)   # the views drawn in one pass
            try:
                self.renderer.draw(target, camera, view)
                self._shown, self._drawn, drew, self.error = target, (key, quality), True, None
            except ShaderError as exc:  # e.g. a view whose shader variant does not compile
                self._drawn, self.error = (key, "full"), str(exc)   # not again until something changes
        if self._shown is not None:
            self.renderer.present(self._shown, framebuffer, view)
        else:
            framebuffer.clear(0.0, 0.0, 0.0, 1.0)
        return drew

    def invalidate(self) -> None:
        """Draw again on the next frame (after shaders were reloaded)."""
        self._drawn, self.error = None, None

    @staticmethod
    def read(framebuffer: moderngl.Framebuffer) -> np.ndarray:
        """(H, W, 3) uint8 of what `framebuffer` holds, top row first."""
        x, y, width, height = framebuffer.viewport
        data = framebuffer.read(viewport=(x, y, width, height), components=3, alignment=1)
        return np.frombuffer(data, np.uint8).reshape(height, width, 3)[::-1].copy()

    def release(self) -> None:
        for target in self._targets.values():
            target.release()
        self._targets.clear()
        self._shown = self._drawn = None

"""Render targets: a float HDR buffer of linear radiance, and an 8-bit sRGB display image.

The renderer draws into either. The HDR target is RGBA32F (RGBA16F on request) with a depth buffer,
optionally multisampled; `resolve` averages the samples into `texture`, which the tone-mapping pass and
`read` use. The display target holds what a window shows (tone-mapped, sRGB-encoded), drawn in one pass
where the view allows it.
"""

from __future__ import annotations

import moderngl
import numpy as np


class HdrTarget:
    def __init__(self, ctx: moderngl.Context, size: tuple[int, int], samples: int = 0, dtype: str = "f4"):
        self.ctx = ctx
        self.size = (int(size[0]), int(size[1]))
        self.samples = int(samples)
        self.texture = ctx.texture(self.size, 4, dtype=dtype)
        self.texture.filter = (moderngl.LINEAR, moderngl.LINEAR)   # for presenting at another size
        self.texture.repeat_x = self.texture.repeat_y = False
        if self.samples > 1:
            color = ctx.renderbuffer(self.size, 4, samples=self.samples, dtype=dtype)
            depth = ctx.depth_renderbuffer(self.size, samples=self.samples)
            self.framebuffer = ctx.framebuffer([color], depth)
            self._resolved = ctx.framebuffer([self.texture])
            self._owned = [color, depth, self._resolved]
        else:
            depth = ctx.depth_renderbuffer(self.size)
            self.framebuffer = ctx.framebuffer([self.texture], depth)
            self._resolved = None
            self._owned = [depth]

    @property
    def aspect(self) -> float:
        return self.size[0] / self.size[1]

    def resolve(self) -> None:
        """Average the samples into `texture` (nothing to do without multisampling)."""
        if self._resolved is not None:
            self.ctx.copy_framebuffer(self._resolved, self.framebuffer)

    def read(self) -> np.ndarray:
        """(H, W, 3) float32 linear values, top row first."""
        data = np.frombuffer(self.texture.read(), np.float32 if self.texture.dtype == "f4" else np.float16)
        return data.reshape(self.size[1], self.size[0], 4)[::-1, :, :3].astype(np.float32)

    def release(self) -> None:
        for obj in (*self._owned, self.framebuffer, self.texture):
            obj.release()


class DisplayTarget:
    """An 8-bit image of sRGB-encoded display values (RGBA8) with a depth buffer, optionally
    multisampled: what the window and PNG captures show. The renderer draws the main views into it in
    one pass, tone mapping and encoding in the surface shader. Presenting it at its own size is a blit
    (a memory copy on llvmpipe, ~1 ms at 1280x720; from an sRGB-format texture the blit converts and
    costs ~5 ms, so the encoding stays in the shader)."""

    def __init__(self, ctx: moderngl.Context, size: tuple[int, int], samples: int = 0):
        self.ctx = ctx
        self.size = (int(size[0]), int(size[1]))
        self.samples = int(samples)
        self.texture = ctx.texture(self.size, 4)
        self.texture.filter = (moderngl.LINEAR, moderngl.LINEAR)   # for presenting at another size
        self.texture.repeat_x = self.texture.repeat_y = False
        self.resolved = ctx.framebuffer([self.texture])
        """The single-sampled image (the same framebuffer as `framebuffer` without multisampling)."""
        if self.samples > 1:
            color = ctx.renderbuffer(self.size, 4, samples=self.samples)
            depth = ctx.depth_renderbuffer(self.size, samples=self.samples)
            self.framebuffer = ctx.framebuffer([color], depth)
            self._owned = [color, depth, self.resolved]
        else:
            depth = ctx.depth_renderbuffer(self.size)
            self.framebuffer = ctx.framebuffer([self.texture], depth)
            self._owned = [depth, self.resolved]

    @property
    def aspect(self) -> float:
        return self.size[0] / self.size[1]

    def resolve(self) -> None:
        """Average the samples into `texture` (nothing to do without multisampling)."""
        if self.samples > 1:
            self.ctx.copy_framebuffer(self.resolved, self.framebuffer)

    def read(self) -> np.ndarray:
        """(H, W, 3) uint8, top row first."""
        data = np.frombuffer(self.texture.read(), np.uint8)
        return data.reshape(self.size[1], self.size[0], 4)[::-1, :, :3].copy()

    def release(self) -> None:
        for obj in (*self._owned, self.framebuffer, self.texture):
            obj.release()


class InterleaveBuffers:
    """The pieces of an interleaved-direct-light frame (surface.glsl with INTERLEAVE), recombined by
    interleave_resolve.glsl: rest radiance, direct irradiance, albedo / pi, and the surface's plane."""

    NAMES = ("rest_image", "direct_irradiance_image", "albedo_image", "plane_image")

    def __init__(self, ctx: moderngl.Context, size: tuple[int, int]):
        self.size = (int(size[0]), int(size[1]))
        # Half floats for the colours (0.1% precision); the plane needs full floats for its gradients.
        self.textures = [ctx.texture(self.size, 4, dtype=dtype) for dtype in ("f2", "f2", "f2", "f4")]
        for texture in self.textures:
            texture.filter = (moderngl.NEAREST, moderngl.NEAREST)
        self.depth = ctx.depth_renderbuffer(self.size)
        self.framebuffer = ctx.framebuffer(self.textures, self.depth)

    def use(self, first_unit: int) -> dict:
        """Bind the textures from `first_unit` on; returns the sampler uniforms."""
        for offset, texture in enumerate(self.textures):
            texture.use(location=first_unit + offset)
        return {name: first_unit + offset for offset, name in enumerate(self.NAMES)}

    def release(self) -> None:
        self.framebuffer.release()
        self.depth.release()
        for texture in self.textures:
            texture.release()

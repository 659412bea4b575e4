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
        self.depth = depth

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


def remade(old, fits: bool, make):
    """`old` where it `fits`, else what `make()` returns, `old` released (a target of another size)."""
    if old is not None and fits:
        return old
    if old is not None:
        old.release()
    return make()


PLASTIC = 1.324717957244746
"""The plastic number: the R2 sequence's steps are its inverse and inverse square (Roberts 2018)."""


def refine_jitter(image: int) -> tuple[float, float]:
    """The subpixel offset of image number `image` (0, 1, ...) of a refined still view: the R2
    low-discrepancy sequence, centred on the pixel, so that the first image is the unjittered one and
    every prefix of the sequence covers the pixel evenly."""
    return (float((0.5 + image / PLASTIC) % 1.0 - 0.5), float((0.5 + image / PLASTIC ** 2) % 1.0 - 0.5))


class RefineStep:
    """What one more image of a RefiningTarget draws with: its framebuffer, its jitter and the surface
    shader's uniforms (surface.glsl ACCUMULATE)."""

    def __init__(self, framebuffer: moderngl.Framebuffer, jitter: tuple[float, float], mean: moderngl.Texture,
                 uniforms: dict):
        self.framebuffer, self.jitter, self.mean, self.uniforms = framebuffer, jitter, mean, uniforms

    def bind(self) -> dict:
        """Bind the mean so far to its unit (just before the pass that reads it); the shader's uniforms."""
        self.mean.use(location=RefiningTarget.UNIT)
        return self.uniforms


class RefiningTarget(DisplayTarget):
    """A display target whose still image gets sharper frame by frame: each draw is one more image, moved
    by a subpixel jitter (`refine_jitter`), averaged with the ones before in display values (as a
    multisampled display target's resolve averages its samples), so that edges come out anti-aliased at
    the cost of one single-sampled frame a frame instead of a multisampled one. The surface pass mixes
    each image into the mean so far (surface.glsl ACCUMULATE), read from one 8-bit image and written to
    the other, which then becomes `texture`; the pixels no surface covers get the background's share
    (refine_background.glsl). Rounding the mean to 8 bits at each image moves an edge pixel by at most
    a level or two; where the images agree (all but the edges) the mean is exact. `images` counts the
    images in the mean; `restart` begins a new mean with the next draw."""

    UNIT = 9
    """The texture unit of the mean the next image reads (the HDR image's, unused by the surface pass)."""

    def __init__(self, ctx: moderngl.Context, size: tuple[int, int], programs):
        """`programs`: the renderer's ProgramLibrary (refine_background.glsl)."""
        super().__init__(ctx, size, samples=0)
        self.images = 0
        other = ctx.texture(self.size, 4, data=bytes(4 * self.size[0] * self.size[1]))
        other.filter, other.repeat_x, other.repeat_y = self.texture.filter, False, False
        self._other = (other, ctx.framebuffer([other]), ctx.framebuffer([other], self.depth))
        self._programs = programs
        program = programs.get("refine_background")
        self._background = (program, ctx.vertex_array(program, []))   # made with the target: its GL objects

    def restart(self) -> None:
        self.images = 0

    def step(self) -> RefineStep:
        """The next image's framebuffer, jitter and uniforms (`finish` makes it the target's image)."""
        return RefineStep(self._other[2], refine_jitter(self.images), self.texture,
                          dict(accumulated=self.UNIT, accumulate_weight=1.0 / (self.images + 1)))

    def finish(self, step: RefineStep) -> None:
        """After the surfaces: the uncovered pixels' share of the background; the new mean becomes the
        target's image."""
        program = self._programs.get("refine_background")
        if program is not self._background[0]:   # the shaders were reloaded
            self._background[1].release()
            self._background = (program, self.ctx.vertex_array(program, []))
        for name, value in step.bind().items():
            program[name] = value
        self.ctx.depth_func = "<="
        self._background[1].render(moderngl.TRIANGLES, vertices=3)
        self.ctx.depth_func = "<"
        mine = (self.texture, self.resolved, self.framebuffer)
        (self.texture, self.resolved, self.framebuffer), self._other = self._other, mine
        self.images += 1

    def release(self) -> None:
        self._background[1].release()
        for obj in (*self._other, self.framebuffer, self.resolved, self.texture, self.depth):
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

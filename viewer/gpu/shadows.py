"""Shadow maps for the direct light: one five-face shadow cube per emitter sample, and one for the sun.

Emitter samples (viewer/gpu/lights.py) are points on one-sided emitters, so each sees only the half
space in front of it: a cube around the sample without its back face covers it. Every face is a 90
degree perspective view rendered into one tile of a shared depth atlas; `direct_light.glsl` picks the
face from the receiver's direction in the sample's (tangent, bitangent, normal) frame, with the same
(right, up, forward) axes as `FACE_AXES` here. The maps depend only on the geometry and the samples, so
they are rendered once per scene, not per frame.
"""

from __future__ import annotations

import math

import moderngl
import numpy as np

from viewer.gpu.camera import gl_bytes, look_along, orthographic, perspective
from viewer.gpu.lights import LightSamples
from viewer.scene import DirectionalLight

# (right, up, forward) of the five faces as indices into the frame (t, b, n) with a sign; must match
# the face choice in direct_light.glsl.
FACE_AXES = (((0, 1), (1, 1), (2, 1)),    # +n: right t, up b
             ((1, 1), (2, 1), (0, 1)),    # +t: right b, up n
             ((1, 1), (2, 1), (0, -1)),   # -t
             ((0, 1), (2, 1), (1, 1)),    # +b: right t, up n
             ((0, 1), (2, 1), (1, -1)))   # -b
MAX_LIGHT_SAMPLES = 256
"""Size of the light-sample uniform block (64 bytes each: 16 KiB, the least any GL implementation allows);
must match direct_light.glsl."""
DEPTH_OFFSET = (2.0, 2.0)
"""glPolygonOffset(factor, units) while drawing the lamps' depth: slope-scaled bias against shadow acne."""
SUN_DEPTH_OFFSET = (0.5, 2.0)
"""The same for the sun's map, with a quarter of the slope: a wall the sun grazes has a steep depth slope,
and twice it pushed the wall back past the points it shades: the sun lit a line down the corners of a
room it enters by a window, and 3x the sunlight it should on the room's inner faces (texels of a window
room facing the sun: 6.4% lit against 2.2% by rays; now 2.2%). The receivers' normal offset
(RenderSettings.shadow_bias) keeps the lit faces lit: 62.0% against 62.0% by rays."""


def _face_view(eye: np.ndarray, frame: np.ndarray, face: int) -> np.ndarray:
    right, up, forward = (sign * frame[axis] for axis, sign in FACE_AXES[face])
    view = np.eye(4)
    view[0, :3], view[1, :3], view[2, :3] = right, up, -forward  # the eye looks down -z
    view[:3, 3] = -view[:3, :3] @ eye
    return view


class EmitterShadows:
    """Depth atlas of the emitter samples' shadow cubes, and the samples' storage buffer."""

    def __init__(self, ctx: moderngl.Context, samples: LightSamples, lo: np.ndarray, hi: np.ndarray,
                 tile: int = 128):
        self.ctx = ctx
        self.samples = samples
        self.tile = int(tile)
        radius = max(0.5 * float(np.linalg.norm(np.asarray(hi) - np.asarray(lo))), 1e-6)
        self.near = 1e-3 * radius
        self.far = 4.0 * radius
        self.lift = 2e-4 * radius
        # A sample's five faces lie side by side in a row of tiles; rows of samples are stacked in
        # `blocks` columns so the atlas stays roughly square.
        count = max(samples.count, 1)
        self.blocks = math.ceil(math.sqrt(count / 5.0))
        self.rows = math.ceil(count / self.blocks)
        self.atlas = ctx.depth_texture((5 * self.blocks * self.tile, self.rows * self.tile))
        self.atlas.compare_func = "<="
        self.atlas.filter = (moderngl.LINEAR, moderngl.LINEAR)   # 2x2 percentage-closer filtering
        self.atlas.repeat_x = self.atlas.repeat_y = False
        self.framebuffer = ctx.framebuffer(depth_attachment=self.atlas)
        if samples.count > MAX_LIGHT_SAMPLES:
            raise ValueError(f"at most {MAX_LIGHT_SAMPLES} light samples, got {samples.count}")
        self.buffer = ctx.buffer(self._packed(samples).tobytes())

    def _packed(self, samples: LightSamples) -> np.ndarray:
        """The storage buffer's contents: the samples, each with its tile's place in the atlas."""
        packed = np.zeros((MAX_LIGHT_SAMPLES, 4, 4), np.float32)
        packed[:samples.count] = samples.packed()
        width, height = self.atlas.size
        for k in range(samples.count):
            x, y = self.tile_origin(k, 0)
            packed[k, 1, 3], packed[k, 2, 3] = x / width, y / height
        return packed

    def repower(self, samples: LightSamples) -> bool:
        """Take `samples` if they sit where these shadow cubes were rendered from (a lamp's colour or
        intensity edited: the same places, other powers), keeping the depth atlas; False if they do not."""
        old = self.samples
        if samples.count != old.count or not all(np.array_equal(a, b) for a, b in (
                (samples.position, old.position), (samples.normal, old.normal), (samples.tangent, old.tangent))):
            return False
        self.samples = samples
        self.buffer.write(self._packed(samples).tobytes())
        return True

    def tile_origin(self, sample: int, face: int) -> tuple[int, int]:
        """Lower-left texel of a face's tile in the atlas."""
        block, row = divmod(sample, self.rows)
        return (5 * block + face) * self.tile, row * self.tile

    @property
    def tile_scale(self) -> tuple[float, float]:
        width, height = self.atlas.size
        return self.tile / width, self.tile / height

    def face_matrices(self):
        """(sample, face, view_proj) of every face of every sample."""
        projection = perspective(90.0, 1.0, self.near, self.far)
        s = self.samples
        for k in range(s.count):
            frame = np.stack([s.tangent[k], s.bitangent[k], s.normal[k]])
            eye = s.position[k] + s.normal[k] * self.lift
            for face in range(5):
                yield k, face, projection @ _face_view(eye, frame, face)

    def render(self, program: moderngl.Program, draw) -> None:
        """Draw the depth of the scene into every tile; `draw(program)` issues the scene's draw call."""
        self.framebuffer.use()
        self.framebuffer.clear(depth=1.0)
        self.ctx.enable(moderngl.DEPTH_TEST)
        self.ctx.disable(moderngl.CULL_FACE)  # every surface casts shadows from both sides
        self.ctx.polygon_offset = DEPTH_OFFSET
        for sample, face, matrix in self.face_matrices():
            self.framebuffer.viewport = (*self.tile_origin(sample, face), self.tile, self.tile)
            program["view_proj"].write(gl_bytes(matrix))
            draw(program)
        self.ctx.polygon_offset = (0.0, 0.0)

    def uniforms(self, atlas_unit: int) -> dict:
        return dict(light_sample_count=self.samples.count, emitter_shadow_atlas=atlas_unit,
                    shadow_tile_scale=self.tile_scale,
                    shadow_tile_texels=float(self.tile), shadow_near=self.near, shadow_far=self.far,
                    shadow_lift=self.lift)

    def use(self, atlas_unit: int) -> None:
        self.atlas.use(location=atlas_unit)
        self.buffer.bind_to_uniform_block(0)

    def release(self) -> None:
        for obj in (self.framebuffer, self.atlas, self.buffer):
            obj.release()


class SunShadow:
    """An orthographic shadow map looking along the sun's light over the scene's bounding sphere (a
    1x1 map that is always lit when there is no sun, so the shaders always have a texture bound)."""

    def __init__(self, ctx: moderngl.Context, sun: DirectionalLight | None, lo: np.ndarray, hi: np.ndarray,
                 size: int = 2048):
        self.ctx = ctx
        self.sun = sun if sun is not None and np.any(sun.irradiance > 0) else None
        size = int(size) if self.sun is not None else 1
        self.map = ctx.depth_texture((size, size))
        self.map.compare_func = "<="
        self.map.filter = (moderngl.LINEAR, moderngl.LINEAR)
        self.map.repeat_x = self.map.repeat_y = False
        self.framebuffer = ctx.framebuffer(depth_attachment=self.map)
        centre = 0.5 * (np.asarray(lo) + np.asarray(hi))
        radius = max(0.5 * float(np.linalg.norm(np.asarray(hi) - np.asarray(lo))), 1e-6)
        self.texel = 2.0 * radius / size
        self.view_proj = np.eye(4)
        if self.sun is not None:
            d = self.sun.direction
            up = (0.0, 1.0, 0.0) if abs(d[1]) < 0.99 else (1.0, 0.0, 0.0)
            view = look_along(centre + 2.0 * radius * d, -d, up)
            self.view_proj = orthographic(radius, radius, radius * 0.5, radius * 3.5) @ view

    def render(self, program: moderngl.Program, draw) -> None:
        self.framebuffer.use()
        self.framebuffer.clear(depth=1.0)
        if self.sun is None:
            return
        self.ctx.enable(moderngl.DEPTH_TEST)
        self.ctx.disable(moderngl.CULL_FACE)
        self.ctx.polygon_offset = SUN_DEPTH_OFFSET
        program["view_proj"].write(gl_bytes(self.view_proj))
        draw(program)
        self.ctx.polygon_offset = (0.0, 0.0)

    def resun(self, sun: DirectionalLight | None) -> bool:
        """Take `sun` if it shines from where this map was rendered (or both are off), keeping the map;
        False if it does not."""
        sun = sun if sun is not None and np.any(sun.irradiance > 0) else None
        if (sun is None) != (self.sun is None) or (sun is not None and not np.array_equal(sun.direction,
                                                                                          self.sun.direction)):
            return False
        self.sun = sun
        return True

    def uniforms(self, map_unit: int) -> dict:
        sun = self.sun
        return dict(sun_enabled=sun is not None, sun_shadow_map=map_unit, sun_texel=self.texel,
                    sun_direction=tuple(sun.direction) if sun else (0.0, 1.0, 0.0),
                    sun_irradiance=tuple(sun.irradiance) if sun else (0.0, 0.0, 0.0),
                    sun_view_proj=gl_bytes(self.view_proj))

    def use(self, map_unit: int) -> None:
        self.map.use(location=map_unit)

    def release(self) -> None:
        self.framebuffer.release()
        self.map.release()

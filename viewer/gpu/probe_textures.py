"""A ProbeGrid on the GPU: seven RGBA16F 3D textures, trilinear, clamped to the edge.

`ProbeGrid.texture_data()` packs the 27 SH numbers of each probe into seven RGBA texels in GL order
[z, y, x]. Texel (i, j, k) of a texture over [lo, hi] has its centre at probe (i, j, k), so hardware
trilinear filtering is the same interpolation as `ProbeGrid.interpolate`. moderngl's 3D textures repeat
by default, which would blend the outermost probes with the opposite side of the box: clamp instead.
"""

from __future__ import annotations

import moderngl
import numpy as np

from viewer.probes import ProbeGrid

TEXTURE_COUNT = 7


def empty_grid() -> ProbeGrid:
    """One probe that sees no light: what the shaders read while GI is off."""
    return ProbeGrid(np.zeros(3), np.ones(3), np.zeros((1, 1, 1, 9, 3), np.float32), np.ones((1, 1, 1), bool))


class ProbeTextures:
    def __init__(self, ctx: moderngl.Context, probes: ProbeGrid, dtype: str = "f2"):
        self.ctx = ctx
        self.dtype = dtype
        self.textures: list[moderngl.Texture3D] = []
        self.resolution = 0
        self.update(probes)

    def update(self, probes: ProbeGrid) -> None:
        """Upload new coefficients (reusing the textures when the resolution is unchanged)."""
        m = probes.resolution
        volumes = probes.texture_data()
        numpy_type = np.float16 if self.dtype == "f2" else np.float32
        if m != self.resolution:
            self.release()
            for _ in range(TEXTURE_COUNT):
                texture = self.ctx.texture3d((m, m, m), 4, dtype=self.dtype)
                texture.repeat_x = texture.repeat_y = texture.repeat_z = False  # CLAMP_TO_EDGE
                texture.filter = (moderngl.LINEAR, moderngl.LINEAR)
                self.textures.append(texture)
            self.resolution = m
        limit = np.finfo(numpy_type).max  # half floats overflow to infinity above 65504
        for texture, volume in zip(self.textures, volumes):
            texture.write(np.ascontiguousarray(np.clip(volume, -limit, limit), numpy_type).tobytes())
        self.lo, self.hi = probes.lo.astype(np.float32), probes.hi.astype(np.float32)

    def use(self, first_unit: int) -> list[int]:
        """Bind the seven textures to consecutive units; returns the units (for `probe_sh[7]`)."""
        units = list(range(first_unit, first_unit + TEXTURE_COUNT))
        for texture, unit in zip(self.textures, units):
            texture.use(location=unit)
        return units

    def release(self) -> None:
        for texture in self.textures:
            texture.release()
        self.textures = []
        self.resolution = 0

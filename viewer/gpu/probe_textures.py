"""A ProbeGrid on the GPU: seven RGBA16F 3D textures, trilinear, clamped to the edge.

`ProbeGrid.texture_data()` packs the 27 SH numbers of each probe into seven RGBA texels in GL order
[z, y, x]. Texel (i, j, k) of a texture over [lo, hi] has its centre at probe (i, j, k), so hardware
trilinear filtering is the same interpolation as `ProbeGrid.interpolate`. moderngl's 3D textures repeat
by default, which would blend the outermost probes with the opposite side of the box: clamp instead.

Half floats hold at most 65504 with 11 significant bits. A very bright lamp (radiance 1e5 and up) puts
probe coefficients above that, and clipping each coefficient separately would change the SH's shape
(the DC term clipped, the others not: negative, black irradiance on one side). So every texel is scaled
by one power of two per grid, `texel_scale`, that brings the largest texel to between HALF_TARGET / 2
and HALF_TARGET; since the weight in the last alpha is scaled with the coefficients and the shaders
divide by the interpolated weight (shaders/probe_grid.glsl), the scale cancels there, exactly. The same
scale lifts dim grids (by up to HALF_TARGET) away from the half floats' subnormal range.
docs/STABILITY.md measures both ends.
"""

from __future__ import annotations

import moderngl
import numpy as np

from viewer.probes.grid import ProbeGrid

TEXTURE_COUNT = 7
HALF_TARGET = 2.0 ** 14
"""Largest texel magnitude after scaling: a power of two with headroom below the half-float maximum."""


def texel_volumes(probes: ProbeGrid, dtype: str = "f2") -> tuple[list[np.ndarray], float]:
    """The seven volumes of `ProbeGrid.texture_data()` in the texture's type, and the power of two they
    were multiplied by (1 for float32 textures). Non-finite coefficients become 0 rather than Inf or NaN
    texels that trilinear filtering would spread to the neighbouring probes."""
    volumes = [np.nan_to_num(v, nan=0.0, posinf=0.0, neginf=0.0) for v in probes.texture_data()]
    if dtype != "f2":
        return [np.ascontiguousarray(v, np.float32) for v in volumes], 1.0
    largest = max(float(np.abs(v).max()) for v in volumes)
    scale = 1.0 if largest == 0.0 else float(2.0 ** np.clip(np.floor(np.log2(HALF_TARGET / largest)), -120, 120))
    limit = float(np.finfo(np.float16).max)  # only round-off can reach it now
    return [np.ascontiguousarray(np.clip(v * scale, -limit, limit), np.float16) for v in volumes], scale


def empty_grid() -> ProbeGrid:
    """One probe that sees no light: what the shaders read while GI is off."""
    return ProbeGrid(np.zeros(3), np.ones(3), np.zeros((1, 1, 1, 9, 3), np.float32), np.ones((1, 1, 1), bool))


class ProbeTextures:
    def __init__(self, ctx: moderngl.Context, probes: ProbeGrid, dtype: str = "f2"):
        self.ctx = ctx
        self.dtype = dtype
        self.textures: list[moderngl.Texture3D] = []
        self.resolution = 0
        self.texel_scale = 1.0
        """The power of two every texel carries (see the module's docstring)."""
        self.update(probes)
        self._upload()   # at once: the compute solver writes into the textures themselves

    def update(self, probes: ProbeGrid) -> None:
        """Take new coefficients, uploaded when a draw first reads them (`use`): where the renderer reads
        the probes from its lightmap, an edit's probes cost no upload (8 ms of a Cornell box's colour edit
        on llvmpipe)."""
        self._pending = probes
        self.lo, self.hi = probes.lo.astype(np.float32), probes.hi.astype(np.float32)

    def _upload(self) -> None:
        """Upload the coefficients `update` took, if any (reusing the textures when the resolution is
        unchanged)."""
        probes, self._pending = self._pending, None
        if probes is None:
            return
        m = probes.resolution
        volumes, self.texel_scale = texel_volumes(probes, self.dtype)
        if m != self.resolution:
            self.release()
            for _ in range(TEXTURE_COUNT):
                texture = self.ctx.texture3d((m, m, m), 4, dtype=self.dtype)
                texture.repeat_x = texture.repeat_y = texture.repeat_z = False  # CLAMP_TO_EDGE
                texture.filter = (moderngl.LINEAR, moderngl.LINEAR)
                self.textures.append(texture)
            self.resolution = m
        for texture, volume in zip(self.textures, volumes):
            texture.write(volume.tobytes())

    def use(self, first_unit: int, upload: bool = True) -> list[int]:
        """Bind the seven textures to consecutive units, the last `update`'s coefficients uploaded first
        (unless not `upload`: a draw that does not read them); returns the units (for `probe_sh[7]`)."""
        if upload:
            self._upload()
        units = list(range(first_unit, first_unit + TEXTURE_COUNT))
        for texture, unit in zip(self.textures, units):
            texture.use(location=unit)
        return units

    def release(self) -> None:
        for texture in self.textures:
            texture.release()
        self.textures = []
        self.resolution = 0

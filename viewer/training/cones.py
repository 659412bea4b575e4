"""Voxel cone tracing: the surfaces' light gathered at the probes through a mip chain of the voxel grid.

The cheap visibility of real-time GI (Crassin et al. 2011, "Interactive indirect illumination using
voxel cone tracing"): the voxels' outgoing radiance, premultiplied by how much of a cell it covers, and
the cells' opacity are filtered into a 3D mip chain; from every probe a few wide cones march front to
back, each sample read at the level whose cells are as wide as the cone there, and accumulate

    C += (1 - A) R,    A += (1 - A) alpha        (front-to-back "over", premultiplied R)

until A reaches 1 or the cone leaves the grid. Each cone's radiance C is projected onto L2 SH with the
cone's share of the sphere as its weight, 4 pi / cones (viewer.probes.sh's basis and order).

The voxels are anisotropic, as in Crassin's: a cone looking along +x sees the light of the surfaces that
face -x, and a thin wall's two sides do not mix. Each cell keeps, per signed axis a cone may travel
along, the radiance of its voxels that face the cone (weighted by area x cosine) premultiplied by their
projected coverage min(1, sum A cos / h^2), and that coverage as its opacity. A sample along direction d
blends the three axes of d's signs with weights d_x^2, d_y^2, d_z^2. A coarser level composites each
cell's two children along the axis of travel front to back and averages the four pairs, so a wall stays
opaque at every level; what still leaks is light through walls thinner than a coarse cell, beside
other light (`viewer.training.bounce_floor --ladder` measures it).
"""

from __future__ import annotations

import numba
import numpy as np

from viewer.probes import sh
from viewer.rays.voxels import FACINGS, VoxelGrid

STEP = 0.5
"""Distance between samples, in cone diameters at the sample (the opacity is corrected for it)."""
OPAQUE = 0.99
"""A cone stops once its accumulated opacity reaches this."""
THICKNESS = 2.0
"""Opacity of a sample as if it spanned this many times its length: trilinear reads blur a one-cell wall
over two cells, which lets a cone through it otherwise (a closed room of radiance 1 seen with 16 cones
from its centre, from midway and from 1.7 voxels off a corner: 0.96 / 0.91 / 0.79 of it at 1, 0.995 /
0.99 / 0.93 at 2, 0.997 / 0.999 / 0.98 at 4)."""
EXIT_MARGIN = 1.0
"""A cone marches until its centre is this many half diameters past the grid (the border cells carry on
beyond it: reads are clamped to the edge)."""


def cone_directions(count: int) -> np.ndarray:
    """(count, 3) cone axes: the six signed axes for 6 cones (a spherical 3-design), else a spherical
    Fibonacci lattice."""
    if count == 6:
        return FACINGS.copy()
    return sh.sphere_directions(count)[0]


def cone_tan(count: int) -> float:
    """tan of the half-angle of a cone whose cap covers 4 pi / count of the sphere: cos = 1 - 2 / count."""
    c = 1.0 - 2.0 / count
    return float(np.sqrt(max(1.0 - c * c, 0.0)) / max(c, 1e-6))


class ConeTracer:
    """The geometry half of the mip chain (each cell's coverage per signed axis of travel), kept for one
    voxel grid; `gathered(radiance, points)` filters the light into the chain and traces the cones."""

    def __init__(self, voxels: VoxelGrid, cones: int = 16):
        n, h = voxels.resolution, voxels.voxel_size
        self.lo, self.h, self.n = np.asarray(voxels.lo, np.float64), float(h), n
        self.directions = cone_directions(cones)
        self.tan = cone_tan(cones)
        self.weight = 4.0 * np.pi / cones
        self.step, self.exit_margin, self.thickness = STEP, EXIT_MARGIN, THICKNESS
        self._cell = voxels.coords[:, 0] + n * (voxels.coords[:, 1] + n * voxels.coords[:, 2])
        # per voxel and signed axis of travel s (FACINGS[s]): the area it shows a cone along it
        facing_cone = np.maximum(-(voxels.normal @ FACINGS.T), 0.0) * voxels.area[:, None]   # (K, 6)
        seen = self._per_cell(facing_cone)
        self._coverage = np.minimum(seen / (h * h), 1.0)                                       # (N^3, 6)
        self._share = facing_cone / np.maximum(seen[self._cell], 1e-30)   # each voxel's share of its cell's
        # The coverage is the opacity: only the faces a cone meets from the front block it. The coarse
        # levels blur the walls behind a probe into its first samples, and their backs would shut the
        # cones leaving a corner (1.7 voxels off a corner of a closed room of radiance 1, 16 cones see
        # 0.70 of it so, 0.93 without).

    def _per_cell(self, values: np.ndarray) -> np.ndarray:
        """(N^3, F) the sums over each cell's voxels of `values` (K, F)."""
        return np.stack([np.bincount(self._cell, values[:, f], minlength=self.n ** 3)
                         for f in range(values.shape[1])], 1)

    def gathered(self, radiance: np.ndarray, points: np.ndarray) -> np.ndarray:
        """(P, 9, 3) the light of the voxels leaving with `radiance` (K, 3), cone traced to `points` (P, 3)."""
        n = self.n
        level0 = np.empty((n ** 3, 6, 4))
        for c in range(3):
            level0[:, :, c] = self._per_cell(self._share * radiance[:, c:c + 1]) * self._coverage
        level0[:, :, 3] = self._coverage
        chain, sizes, offsets = mip_chain(level0.reshape(n, n, n, 6, 4).transpose(2, 1, 0, 3, 4))
        cones = _trace(np.ascontiguousarray(points, np.float64), self.directions, self.tan, self.lo, self.h,
                       chain, sizes, offsets, self.step, OPAQUE, self.exit_margin, self.thickness)   # (P, C, 3)
        basis = sh.basis(self.directions) * self.weight                                      # (C, 9)
        return np.einsum("ck,pcj->pkj", basis, cones)


def mip_chain(level0: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The chain of a (N, N, N, 6, 4) volume indexed [x, y, z, signed axis of travel, (premultiplied
    r, g, b, opacity)]: (flat cells of every level (L, 24), sizes (L,), offsets (L,)). Each level is made
    of the one below as Crassin's anisotropic voxels are: per signed axis, the two children along it
    composited front to back (the one the cone enters first over the other), the four pairs averaged. A
    wall across a coarse cell stays opaque to a cone crossing it. The chain stops at an odd size (24^3:
    24, 12, 6, 3): a padded level would mix empty cells into the walls at the grid's far side."""
    levels = [level0]
    while levels[-1].shape[0] > 1 and levels[-1].shape[0] % 2 == 0:
        v = levels[-1]
        half = v.shape[0] // 2
        v = v.reshape(half, 2, half, 2, half, 2, 6, 4)
        out = np.empty((half, half, half, 6, 4))
        for s in range(6):
            axis = 1 + 2 * (s // 2)                       # the children's index along the axis of travel
            first, second = (0, 1) if s % 2 == 0 else (1, 0)
            front, back = np.take(v[..., s, :], first, axis=axis), np.take(v[..., s, :], second, axis=axis)
            composited = front + (1.0 - front[..., 3:]) * back   # premultiplied "over", opacity alike
            out[..., s, :] = composited.mean(axis=tuple(a - (a > axis) for a in (1, 3, 5) if a != axis))
        levels.append(out)
    sizes = np.array([v.shape[0] for v in levels], np.int64)
    offsets = np.concatenate([[0], np.cumsum(sizes ** 3)[:-1]]).astype(np.int64)
    # flat index x + m (y + m z), as the kernel reads it
    flat = np.concatenate([v.transpose(2, 1, 0, 3, 4).reshape(-1, 24) for v in levels])
    return np.ascontiguousarray(flat), sizes, offsets


@numba.njit(cache=True, nogil=True)
def _sample(chain, size, offset, level_h, lo, x, y, z, sx, sy, sz, out):
    """Trilinear read of one level at world point (x, y, z): the 4 values of each signed axis sx, sy, sz
    into out (12,)."""
    out[:] = 0.0
    gx, gy, gz = (x - lo[0]) / level_h - 0.5, (y - lo[1]) / level_h - 0.5, (z - lo[2]) / level_h - 0.5
    ix, iy, iz = int(np.floor(gx)), int(np.floor(gy)), int(np.floor(gz))
    fx, fy, fz = gx - ix, gy - iy, gz - iz
    for corner in range(8):
        # clamped to the edge: beyond the grid continues its border cells (a room's walls, its open front)
        cx = min(max(ix + (corner & 1), 0), size - 1)
        cy = min(max(iy + ((corner >> 1) & 1), 0), size - 1)
        cz = min(max(iz + ((corner >> 2) & 1), 0), size - 1)
        w = ((fx if corner & 1 else 1.0 - fx) * (fy if (corner >> 1) & 1 else 1.0 - fy)
             * (fz if (corner >> 2) & 1 else 1.0 - fz))
        row = offset + cx + size * (cy + size * cz)
        for k in range(4):
            out[k] += w * chain[row, 4 * sx + k]
            out[4 + k] += w * chain[row, 4 * sy + k]
            out[8 + k] += w * chain[row, 4 * sz + k]


@numba.njit(cache=True, nogil=True, parallel=True)
def _trace(points, directions, tan, lo, h, chain, sizes, offsets, step, opaque, exit_margin, thickness):
    """(P, C, 3) radiance each cone gathers, front to back through the mip chain."""
    count, cones, levels = points.shape[0], directions.shape[0], sizes.shape[0]
    out = np.zeros((count, cones, 3))
    extent = h * sizes[0]
    for p in numba.prange(count):
        low, high, seen = np.zeros(12), np.zeros(12), np.zeros(4)
        for c in range(cones):
            dx, dy, dz = directions[c, 0], directions[c, 1], directions[c, 2]
            # the signed axes a cone along d travels (FACINGS order: +x -x +y -y +z -z), weighted by d^2
            sx, sy, sz = (0 if dx > 0 else 1), (2 if dy > 0 else 3), (4 if dz > 0 else 5)
            t, total, r, g, b = 0.5 * h, 0.0, 0.0, 0.0, 0.0
            while total < opaque:
                x, y, z = points[p, 0] + t * dx, points[p, 1] + t * dy, points[p, 2] + t * dz
                # as wide as the cone, up to the coarsest level's cells (then it samples that level)
                diameter = min(max(h, 2.0 * t * tan), h * 2.0 ** (levels - 1))
                margin = 0.5 * diameter * exit_margin
                if (x < lo[0] - margin or y < lo[1] - margin or z < lo[2] - margin or x > lo[0] + extent + margin
                        or y > lo[1] + extent + margin or z > lo[2] + extent + margin):
                    break
                level = min(np.log2(diameter / h), levels - 1.0)
                l0 = int(level)
                l1 = min(l0 + 1, levels - 1)
                mix = level - l0
                _sample(chain, sizes[l0], offsets[l0], h * 2.0 ** l0, lo, x, y, z, sx, sy, sz, low)
                _sample(chain, sizes[l1], offsets[l1], h * 2.0 ** l1, lo, x, y, z, sx, sy, sz, high)
                seen[:] = 0.0
                for j, wa in ((0, dx * dx), (1, dy * dy), (2, dz * dz)):
                    for k in range(4):
                        seen[k] += wa * ((1.0 - mix) * low[4 * j + k] + mix * high[4 * j + k])
                a = min(max(seen[3], 0.0), 1.0)
                corrected = 1.0 - (1.0 - a) ** (step * thickness) if a < 1.0 else 1.0
                scale = corrected / a if a > 1e-9 else step * thickness
                r += (1.0 - total) * seen[0] * scale
                g += (1.0 - total) * seen[1] * scale
                b += (1.0 - total) * seen[2] * scale
                total += (1.0 - total) * corrected
                t += step * diameter
            out[p, c, 0], out[p, c, 1], out[p, c, 2] = r, g, b
    return out

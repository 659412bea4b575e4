"""The direct light on the voxels themselves: what each surface receives straight from the emitters and
the sun, the start of the light the seen feature gathers (viewer/neural/seen.py).

Read from the probes' direct SH half a voxel in front of each voxel (encoding versions up to 8), a
surface beside a lamp missed most of the light its cosine catches: L2 SH spread a small bright lamp over
the sphere, the lattice's interpolation blurs its 1 / r^2 over a cell, and the probes' shadows are a
cell wide. Summed at each voxel instead, with the probes' own terms (the patches' solid angles, their
pieces near them, one visibility ray per voxel and cluster of patches, the sun's ray), the voxels' direct
light is the solver's to 0.1% in a sunlit room, and the seen light gathered from it is 13.6% off
Mitsuba's reflected light on the public scenes where the probes' read-back gave 16.7% (docs/TRAINING.md).
"""

from __future__ import annotations

import numba
import numpy as np

from viewer.neural.direct import SH_BLOCK, Pieces, kernel_terms, solid_angle
from viewer.neural.shadows import patch_visibility
from viewer.rays.sun import voxel_sun_cover
from viewer.rays.voxels import SURFACE_OFFSET, VoxelGrid
from viewer.threads import cores_for


def surface_points(voxels: VoxelGrid) -> np.ndarray:
    """(K, 3) where each voxel receives its direct light and starts its shadow rays, SURFACE_OFFSET voxels
    in front of it as the solver's rays start (half a voxel off, where the probes' SH was read, the outer
    face of a room's wall started outside the scene and saw the sun)."""
    return voxels.position + SURFACE_OFFSET * voxels.voxel_size * voxels.normal


def sun_irradiance(sun, visible: np.ndarray | None, normals: np.ndarray) -> np.ndarray:
    """(K, 3) the sun's irradiance on surfaces facing `normals` (K, 3) where `visible` (K,) says the ray
    towards it escapes (None: no sun)."""
    out = np.zeros((len(normals), 3))
    if sun is None or visible is None or not np.any(np.asarray(sun.irradiance) > 0):
        return out
    direction = np.asarray(sun.direction, np.float64)
    cosine = np.maximum(normals @ (direction / np.linalg.norm(direction)), 0.0) * visible
    return cosine[:, None] * np.asarray(sun.irradiance, np.float64)[None]


def emitter_irradiance_rows(lights, points: np.ndarray, normals: np.ndarray, visible: np.ndarray | None = None,
                            pieces: Pieces | None = None, rows: np.ndarray | None = None) -> np.ndarray:
    """(C, K) float32 irradiance straight from the emitting patches at surface points (K, 3) facing
    `normals` (K, 3): `emitter_sh_rows`' terms (the same solid angles, pieces and visibility rows),
    each times the receiver's cosine instead of projected on SH. Read from the probes' SH instead, a
    surface beside a lamp misses the light its cosine catches: L2 SH spread a small bright lamp over the
    sphere, and the lattice's interpolation blurs its 1 / r^2 over a cell."""
    out = np.zeros((np.shape(lights[3])[1], len(points)), np.float32)
    if len(lights[2]) == 0 or len(points) == 0:
        return out
    f32 = [np.ascontiguousarray(np.asarray(a).T, np.float32) for a in (points, normals)]
    with cores_for(len(points) * len(lights[2])):   # the voxels a move changed, from a lamp's few patches
        _emitter_irradiance(*f32, *kernel_terms(lights, visible, pieces, rows), out)
    return out


@numba.njit(cache=True, nogil=True, fastmath=True, error_model="numpy", parallel=True)
def _emitter_irradiance(points, receiver, source, normal, area, radiance, visible, rows, shadowed, near_field, start,
                        piece_position, piece_normal, piece_area, piece_gain, near2, out):
    """The terms of `emitter_irradiance_rows`: points and receiver normals (3, K), out (C, K)."""
    count = points.shape[1]
    zero = np.float32(0.0)
    for block in numba.prange((count + SH_BLOCK - 1) // SH_BLOCK):
        first = block * SH_BLOCK
        n = min(SH_BLOCK, count - first)
        w = np.empty(SH_BLOCK, np.float32)
        for e in range(source.shape[0]):
            sx, sy, sz = source[e, 0], source[e, 1], source[e, 2]
            mx, my, mz = normal[e, 0], normal[e, 1], normal[e, 2]
            flux, clamp = area[e], area[e] * near_field
            for i in range(n):
                p = first + i
                omega, x, y, z = solid_angle(sx - points[0, p], sy - points[1, p], sz - points[2, p], mx, my, mz,
                                              flux, clamp)
                cosine = max(x * receiver[0, p] + y * receiver[1, p] + z * receiver[2, p], zero)
                w[i] = omega * cosine * (visible[rows[e], p] if shadowed else np.float32(1.0))
            if start[e + 1] > start[e]:   # points near the patch: its pieces instead
                for i in range(n):
                    p = first + i
                    x, y, z = sx - points[0, p], sy - points[1, p], sz - points[2, p]
                    if x * x + y * y + z * z >= near2:
                        continue
                    seen = visible[rows[e], p] if shadowed else np.float32(1.0)
                    total = zero
                    if seen != zero:
                        for s in range(start[e], start[e + 1]):
                            omega, qx, qy, qz = solid_angle(piece_position[s, 0] - points[0, p],
                                                             piece_position[s, 1] - points[1, p],
                                                             piece_position[s, 2] - points[2, p], piece_normal[s, 0],
                                                             piece_normal[s, 1], piece_normal[s, 2], piece_area[s],
                                                             piece_area[s] * near_field)
                            cosine = max(qx * receiver[0, p] + qy * receiver[1, p] + qz * receiver[2, p], zero)
                            total += omega * cosine * piece_gain[s]
                    w[i] = total * seen
            for c in range(radiance.shape[1]):
                rc = radiance[e, c]
                if rc == 0:
                    continue
                for i in range(n):
                    out[c, first + i] += rc * w[i]


def voxel_direct(voxels: VoxelGrid, lights, pieces: Pieces, blockers, sun, lo: np.ndarray,
                 spacing: np.ndarray) -> np.ndarray:
    """(K, 3) the irradiance each voxel receives straight from the emitting patches `lights`
    (`encoding.emitting_patches`, with their `pieces`) and the sun, shadowed by `blockers` (None:
    nothing casts a shadow): one ray per voxel and cluster of patches (`shadows.shadow_targets`, as the
    probes'), nine towards the sun from across the voxel (`voxel_sun_cover`)."""
    points = surface_points(voxels)
    visible = None
    if blockers is not None and len(lights[2]):
        visible = patch_visibility(blockers, points, lights[0], lights[1], lo, spacing).T
    out = emitter_irradiance_rows(lights, points, voxels.normal, visible, pieces).T.astype(np.float64)
    seen_sun = None
    if sun is not None and np.any(np.asarray(sun.irradiance) > 0):
        seen_sun = voxel_sun_cover(blockers, voxels, np.asarray(sun.direction, np.float64))
    return out + sun_irradiance(sun, seen_sun, voxels.normal)

"""The direct light at the probe lattice: emitting patches and their pieces near the probes (their shadows
and the sun's: viewer/neural/shadows.py).

The `direct_*` features of the network's input (viewer/neural/encoding.py), and the gather the one-bounce
feature (viewer/neural/bounce.py) reuses with the lit surfaces as emitters.
"""

from __future__ import annotations

from dataclasses import dataclass

import numba
import numpy as np

from viewer.probes import sh
from viewer.rays.voxels import VoxelGrid, face_facing

NEAR_FIELD = 1.0 / np.pi
"""r^2 + A/pi: the near-field clamp of the transport kernel, so a probe next to a lamp stays finite."""
def splat(points: np.ndarray, lo: np.ndarray, spacing: np.ndarray, m: int):
    """[(flat cell index (P,), weight (P,))] for the 8 cell centres around each point (weights sum to
    1; clamped at the lattice's faces, so a wall on the scene's bounds stays in the boundary layer). In one
    compiled pass (numpy's took 0.3 ms for a room's 2,311 voxels, three times a new geometry)."""
    points = np.ascontiguousarray(points, np.float64).reshape(-1, 3)
    index, weight = np.empty((8, len(points)), np.int64), np.empty((8, len(points)))
    _splat(points, np.asarray(lo, np.float64).reshape(3), np.asarray(spacing, np.float64).reshape(3), int(m), index,
           weight)
    return list(zip(index, weight))


@numba.njit(cache=True, nogil=True)
def _splat(points, lo, spacing, m, index, weight):
    top, last = max(m - 2, 0), m ** 3 - 1
    for p in range(points.shape[0]):
        i, fi = _corner(points[p, 0], lo[0], spacing[0], m, top)
        j, fj = _corner(points[p, 1], lo[1], spacing[1], m, top)
        k, fk = _corner(points[p, 2], lo[2], spacing[2], m, top)
        for corner in range(8):
            b0, b1, b2 = corner & 1, (corner >> 1) & 1, (corner >> 2) & 1
            w = (fi if b0 else 1.0 - fi) * (fj if b1 else 1.0 - fj)
            weight[corner, p] = w * (fk if b2 else 1.0 - fk)
            index[corner, p] = min(((i + b0) * m + j + b1) * m + k + b2, last)


@numba.njit(cache=True, nogil=True, inline="always")
def _corner(x, lo, spacing, m, top):
    """The lower corner's index along one axis and the point's fraction past it."""
    u = min(max((x - lo) / spacing - 0.5, 0.0), m - 1.0)
    i = min(np.int64(np.floor(u)), top)
    return i, u - i


def lattice_cells(points: np.ndarray, lo: np.ndarray, spacing: np.ndarray, m: int) -> np.ndarray:
    """(P,) int64 the flat index ((i x m + j) x m + k) of the lattice cell each point (P, 3) lies in,
    clamped to the lattice."""
    cell = np.clip(np.floor((points - lo) / spacing).astype(np.int64), 0, m - 1)
    return (cell[:, 0] * m + cell[:, 1]) * m + cell[:, 2]


def facings(normal: np.ndarray) -> np.ndarray:
    """(K,) int 0-5: the signed axis each normal (K, 3) is closest to (2 a + 1 for +a, 2 a for -a). Patches
    merge surfaces of one facing only: the two sides of a thin wall in one cell have opposite normals,
    and merged, their mean normal is zero and the patch shines nowhere. The voxelizer's own index
    (`voxels.face_facing`: 2 a for +a) of the opposite normal, ties and zero normals alike."""
    return face_facing(-np.asarray(normal))


NEAR_PIECES = 6.0
"""Distance, in lattice cells (their longest side), within which a probe sums an emitting patch's pieces
(the voxels' light samples, `Pieces`) instead of taking the patch as one solid angle, as the solver's
probes do within 6 voxels. A patch merges a cell's worth of lamp: seen from a probe a few cells away,
one term misjudges its solid angle and direction. Between the probes, against Mitsuba (relative to all
the light; paper-test, CornellBox-Original, a validation room, a dark room), the direct light was
8.8 / 8.2 / 24 / 46% off as patches alone, 4.8 / 4.8 / 6.9 / 10.4% with pieces within 3 cells, 3.4 /
3.5 / 6.4 / 9.9% within 6, where the solver's is 3.0 / 3.2 / 6.2 / 10.1%. It costs a new Cornell box's
encoding 3-4 ms (512 pieces), and 50-180 ms in rooms lit by whole glowing walls (up to 15,000)."""
NEAR_ALL = 3.0
"""Distance, in lattice cells, within which a probe's SH sums every piece of a patch; between it and
NEAR_PIECES, the patch's quarters (`quartered`): a quarter of a cell seen from 3-6 cells away is as
small in the sky as a whole patch from 6-12, where one term serves. On val-00009 (a ceiling lamp of
1.2 x 0.6 m, 10,496 pieces) the SH 25 -> 16 ms; all the light against Mitsuba moved by at most 0.1
points in the 26 scenes of `viewer.training.evaluate`, the reflected light not at all. Within 2 cells
instead: 12 ms, and up to 0.3 points."""



@dataclass(frozen=True)
class Pieces:
    """The light samples of emitting patches (`VoxelGrid.lights`), grouped by patch: patch e's are
    [start[e], start[e + 1]), each with its radiance relative to the patch's (`gain`: a patch's radiance
    is its voxels' mean over all their area, a lamp's and the ceiling's around it, so its pieces are
    brighter than it by the ratio of the areas)."""

    start: np.ndarray
    """(E + 1,) int64."""
    position: np.ndarray
    """(S, 3)."""
    normal: np.ndarray
    """(S, 3)."""
    area: np.ndarray
    """(S,)."""
    gain: np.ndarray
    """(S,) the piece's radiance over its patch's (their largest channels)."""
    near: float
    """Distance from a patch's centre within which a probe sums its pieces."""

    @staticmethod
    def none(patches: int, near: float = -1.0) -> "Pieces":
        """No pieces for `patches` patches: every probe takes each patch as one term."""
        empty = np.zeros((0, 3))
        return Pieces(np.zeros(patches + 1, np.int64), empty, empty, np.zeros(0), np.zeros(0), float(near))

    def of(self, patches: np.ndarray) -> "Pieces":
        """The pieces of `patches` (indices), in their order."""
        patches = np.asarray(patches, np.int64)
        counts = self.start[patches + 1] - self.start[patches]
        start = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
        take = np.arange(start[-1]) + np.repeat(self.start[patches] - start[:-1], counts)
        return Pieces(start, self.position[take], self.normal[take], self.area[take], self.gain[take], self.near)


def quartered(pieces: Pieces, centre: np.ndarray, normal: np.ndarray) -> Pieces:
    """Each patch's pieces merged by the quarter of the patch they lie in (either side of its centre
    `centre` (E, 3) along the two axes across its facing, from `normal` (E, 3)): up to four pieces a patch,
    each at its pieces' centre of power (area x gain), with their area, their mean normal and the gain
    of their power over their area. The sums in one compiled pass over the pieces, in their order (81
    patches of 6,144 pieces: 0.42 -> 0.08 ms, paid by every lamp's basis summed)."""
    if len(pieces.area) == 0:
        return pieces
    axis = np.argmax(np.abs(normal), axis=1)
    sums = np.zeros((len(pieces.start) - 1, 4, 11))
    held = np.zeros((len(pieces.start) - 1, 4), np.bool_)
    _quarter_sums(pieces.start, np.asarray(pieces.position, np.float64), np.asarray(pieces.normal, np.float64),
                  np.asarray(pieces.area, np.float64), np.asarray(pieces.gain, np.float64),
                  np.asarray(centre, np.float64), axis, sums, held)
    quarter = sums[held]   # by patch, then quarter: the order of their keys
    area, flux = quarter[:, 0], quarter[:, 1]
    position = np.where(flux[:, None] > 0, quarter[:, 2:5] / np.where(flux > 0, flux, 1)[:, None],
                        quarter[:, 5:8] / np.where(area > 0, area, 1)[:, None])
    mean_normal = quarter[:, 8:11] / np.maximum(np.linalg.norm(quarter[:, 8:11], axis=1, keepdims=True), 1e-12)
    start = np.concatenate([[0], np.cumsum(held.sum(axis=1))]).astype(np.int64)
    return Pieces(start, position, mean_normal, area, flux / area, pieces.near)


@numba.njit(cache=True, nogil=True)
def _quarter_sums(start, position, normal, area, gain, centre, axis, sums, held):
    """sums[e, q] = the area, power (area x gain), power x position, area x position and area x normal of
    patch e's pieces in quarter q (held[e, q]: it has some), summed in the pieces' order."""
    for e in range(start.shape[0] - 1):
        first, second = (axis[e] + 1) % 3, (axis[e] + 2) % 3
        for s in range(start[e], start[e + 1]):
            q = (2 if position[s, first] - centre[e, first] > 0 else 0) + (
                1 if position[s, second] - centre[e, second] > 0 else 0)
            a = area[s]
            power = a * gain[s]
            row = sums[e, q]
            row[0] += a
            row[1] += power
            for k in range(3):
                row[2 + k] += power * position[s, k]
                row[5 + k] += a * position[s, k]
                row[8 + k] += a * normal[s, k]
            held[e, q] = True


def _patch_groups(cell: np.ndarray, voxels: VoxelGrid) -> tuple[np.ndarray, np.ndarray, int]:
    """The emitting voxels (K,), the patch of each (K,) and the count of patches: one per lattice cell
    and facing, in the order of `emitting_patches`."""
    lit = np.flatnonzero(np.any(voxels.emission > 0, axis=1))
    if len(lit) == 0:
        return lit, np.zeros(0, np.int64), 0
    key, group = np.unique(cell[lit] * 8 + facings(voxels.normal[lit]), return_inverse=True)
    return lit, group.ravel(), len(key)


def emitting_patches(cell: np.ndarray, voxels: VoxelGrid):
    """The emitting voxels merged per lattice cell and facing: (positions (E, 3), normals (E, 3), areas
    (E,), radiance (E, 3)). Seen from the probes (a lattice cell or more away), the pieces of a lamp in
    one cell all arrive from about the same direction, so one patch per cell keeps the feature cheap."""
    lit, group, count = _patch_groups(cell, voxels)
    if count == 0:
        return np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0), np.zeros((0, 3))
    a = voxels.area[lit]
    area = np.bincount(group, a, minlength=count)

    def mean(values):
        return np.stack([np.bincount(group, a * values[:, k], minlength=count) for k in range(3)], 1) / area[:, None]

    normal = mean(voxels.normal[lit])
    normal /= np.maximum(np.linalg.norm(normal, axis=1, keepdims=True), 1e-12)
    return mean(voxels.position[lit]), normal, area, mean(voxels.emission[lit])


def patch_pieces(cell: np.ndarray, voxels: VoxelGrid, radiance: np.ndarray, near: float) -> Pieces:
    """The pieces of the patches of `emitting_patches(cell, voxels)` (whose radiance (E, 3) is
    `radiance`), in its order of patches: each light sample goes to the patch of its voxel (samples of
    voxels that do not emit are left out)."""
    lit, group, count = _patch_groups(cell, voxels)
    samples = voxels.lights
    if count == 0 or samples.count == 0:
        return Pieces.none(count, near)
    patch_of_voxel = np.full(voxels.count, -1, np.int64)
    patch_of_voxel[lit] = group
    patch = patch_of_voxel[samples.voxel]
    keep = np.flatnonzero(patch >= 0)
    order = keep[np.argsort(patch[keep], kind="stable")]
    patch = patch[order]
    start = np.concatenate([[0], np.cumsum(np.bincount(patch, minlength=count))]).astype(np.int64)
    brightest = np.asarray(radiance).max(axis=1)
    gain = samples.radiance[order].max(axis=1) / np.where(brightest > 0, brightest, 1.0)[patch]
    return Pieces(start, samples.position[order], samples.normal[order], samples.area[order], gain, float(near))


def emitter_sh(lights, points: np.ndarray, visible: np.ndarray | None = None,
               pieces: Pieces | None = None) -> np.ndarray:
    """(P, 9, 3) SH of the light arriving straight from the emitting patches: each patch is a solid
    angle cos_e A / (r^2 + A/pi), seen from the probe if its front faces it, times `visible` (P, E)
    (`shadows.patch_visibility`; None: nothing in the way). With `pieces`, a probe within `pieces.near` of
    a patch sums the solid angles of the patch's quarters instead (`quartered`), and within NEAR_ALL /
    NEAR_PIECES of that the patch's pieces, each from its own direction (the same visibility)."""
    rows = None if visible is None else np.asarray(visible).T
    return emitter_sh_rows(lights, points, rows, pieces).transpose(2, 1, 0).astype(np.float64)


def emitter_sh_rows(lights, points: np.ndarray, visible: np.ndarray | None = None,
                    pieces: Pieces | None = None, rows: np.ndarray | None = None) -> np.ndarray:
    """`emitter_sh` as (C, 9, P) float32 for a radiance of C channels (lights[3] is (E, C)), with the
    visibility as (E, P) rows, or as any (R, P) rows of which patch e reads row `rows[e]` (a cluster's
    shared ray: no (E, P) copy to make): the layout the compiled loop works in (`viewer.neural.encoder`
    keeps one channel per emitter, a radiance of 1 times its weights)."""
    out = np.zeros((np.shape(lights[3])[1], sh.SH_COUNT, len(points)), np.float32)
    if len(lights[2]) == 0:
        return out
    terms = kernel_terms(lights, visible, pieces, rows)
    quarters = Pieces.none(len(lights[2])) if pieces is None else quartered(pieces, lights[0], lights[1])
    parts = [np.ascontiguousarray(a, np.float32) for a in (quarters.position, quarters.normal, quarters.area,
                                                            quarters.gain)]
    inner = -1.0 if pieces is None or pieces.near <= 0 else pieces.near * NEAR_ALL / NEAR_PIECES
    _emitter_sh(np.ascontiguousarray(np.asarray(points).T, np.float32), *terms, quarters.start, *parts,
                np.float32(inner * inner if inner > 0 else -1.0), out)
    return out


def kernel_terms(lights, visible: np.ndarray | None, pieces: Pieces | None, rows: np.ndarray | None = None) -> tuple:
    """The compiled loops' arguments after their points (`_emitter_sh`, `irradiance._emitter_irradiance`):
    the patches' positions, normals, areas and radiance (E, C) as float32, their visibility rows (R, P)
    or one row of ones, each patch's row of them (E,) (`rows`, default patch e reads row e), whether
    those shadow, the near-field clamp, and the pieces (their starts, positions, normals, areas and
    gains, and the square of the distance within which they count). Rows shared by several patches are
    read in place: copying them out per patch made a large lamp's (159, 13824) array, and on this kind of
    virtual machine its fresh pages cost up to 70 ms of a moved object."""
    source, normal, area, radiance = lights
    f32 = [np.ascontiguousarray(a, np.float32) for a in (source, normal, area, radiance)]
    seen = np.ones((len(area), 1), np.float32) if visible is None else np.ascontiguousarray(visible, np.float32)
    rows = np.arange(len(area)) if rows is None or visible is None else np.asarray(rows)
    if pieces is None or len(pieces.area) == 0:
        pieces = Pieces.none(len(area))
    near2 = np.float32(pieces.near * pieces.near if pieces.near > 0 else -1.0)
    parts = [np.ascontiguousarray(a, np.float32) for a in (pieces.position, pieces.normal, pieces.area, pieces.gain)]
    return (*f32, seen, np.ascontiguousarray(rows, np.int64), visible is not None, np.float32(NEAR_FIELD),
            pieces.start, *parts, near2)


SH_BLOCK = 128
"""Probes per block of `_emitter_sh`: the patch loop runs over a block whose basis and sums stay in L1,
and the probe loops inside it vectorize. The blocks are shared out among the cores (a 12^3 lattice in 14
blocks, evenly over two)."""


@numba.njit(cache=True, nogil=True, fastmath=True, error_model="numpy", parallel=True)
def _emitter_sh(points, source, normal, area, radiance, visible, rows, shadowed, near_field, start, piece_position,
                piece_normal, piece_area, piece_gain, near2, quarter_start, quarter_position, quarter_normal,
                quarter_area, quarter_gain, inner2, out):
    """The terms of `emitter_sh`: points (3, P), radiance (E, C), visible (R, P) and each patch's row of it
    `rows` (E,) when `shadowed`; where the probe is nearer than sqrt(near2) to patch e, the patch's
    quarters [quarter_start[e], quarter_start[e + 1]) summed instead, and nearer than sqrt(inner2) its
    pieces [start[e], start[e + 1]); out (C, 9, P).

    Each loop over a block's probes holds no branch, so that it vectorizes: the shadows multiply the basis
    in a loop of their own, and the sums gather in a block-local array added to `out` once (a Cornell box's
    1,079 patches on 12^3 points: 4-6 ms where a loop that chose the shadow per probe and added to `out`
    per patch took 13-18)."""
    count = points.shape[1]
    zero = np.float32(0.0)
    channels = radiance.shape[1]
    for block in numba.prange((count + SH_BLOCK - 1) // SH_BLOCK):
        first = block * SH_BLOCK
        n = min(SH_BLOCK, count - first)
        b = np.empty((9, SH_BLOCK), np.float32)
        pb = np.empty((9, SH_BLOCK), np.float32)   # the near probes' basis from the pieces
        inner, outer = np.empty(SH_BLOCK, np.int64), np.empty(SH_BLOCK, np.int64)
        nx, ny, nz = np.empty(SH_BLOCK, np.float32), np.empty(SH_BLOCK, np.float32), np.empty(SH_BLOCK, np.float32)
        sums = np.zeros((channels, 9, SH_BLOCK), np.float32)
        px, py, pz = points[0, first:first + n], points[1, first:first + n], points[2, first:first + n]
        for e in range(source.shape[0]):
            sx, sy, sz = source[e, 0], source[e, 1], source[e, 2]
            mx, my, mz = normal[e, 0], normal[e, 1], normal[e, 2]
            flux, clamp = area[e], area[e] * near_field
            for i in range(n):   # the patch as one term
                weight, x, y, z = solid_angle(sx - px[i], sy - py[i], sz - pz[i], mx, my, mz, flux, clamp)
                for k in range(9):
                    b[k, i] = zero
                _add_basis(b, i, weight, x, y, z)
            if start[e + 1] > start[e]:   # probes near the patch: its quarters, or nearer its pieces, instead
                m_inner = m_outer = 0
                for i in range(n):
                    x, y, z = sx - px[i], sy - py[i], sz - pz[i]
                    d2 = x * x + y * y + z * z
                    if d2 < inner2:
                        inner[m_inner] = i
                        m_inner += 1
                    elif d2 < near2:
                        outer[m_outer] = i
                        m_outer += 1
                _near_basis(inner, m_inner, px, py, pz, nx, ny, nz, pb, b, start[e], start[e + 1], piece_position,
                            piece_normal, piece_area, piece_gain, near_field)
                _near_basis(outer, m_outer, px, py, pz, nx, ny, nz, pb, b, quarter_start[e], quarter_start[e + 1],
                            quarter_position, quarter_normal, quarter_area, quarter_gain, near_field)
            if shadowed:
                seen = visible[rows[e], first:first + n]
                for k in range(9):
                    row = b[k]
                    for i in range(n):
                        row[i] *= seen[i]
            for c in range(channels):
                rc = radiance[e, c]
                if rc == 0:
                    continue
                for k in range(9):
                    row, basis = sums[c, k], b[k]
                    for i in range(n):
                        row[i] += rc * basis[i]
        for c in range(channels):
            for k in range(9):
                row, part = out[c, k, first:first + n], sums[c, k]
                for i in range(n):
                    row[i] += part[i]


@numba.njit(cache=True, nogil=True, fastmath=True, error_model="numpy", inline="always")
def _near_basis(near, m, px, py, pz, nx, ny, nz, pb, b, first, last, position, normal, area, gain, near_field):
    """b[:, near[j]] for the m probes `near` (indices into px, py, pz): the sum of pieces [first, last),
    the probes gathered first so that the loop over them vectorizes."""
    if m == 0:
        return
    zero = np.float32(0.0)
    for j in range(m):
        nx[j], ny[j], nz[j] = px[near[j]], py[near[j]], pz[near[j]]
        for k in range(9):
            pb[k, j] = zero
    for s in range(first, last):
        qx0, qy0, qz0 = position[s, 0], position[s, 1], position[s, 2]
        ax, ay, az = normal[s, 0], normal[s, 1], normal[s, 2]
        flux, g = area[s], gain[s]
        for j in range(m):
            omega, qx, qy, qz = solid_angle(qx0 - nx[j], qy0 - ny[j], qz0 - nz[j], ax, ay, az, flux, flux * near_field)
            _add_basis(pb, j, omega * g, qx, qy, qz)
    for j in range(m):
        for k in range(9):
            b[k, near[j]] = pb[k, j]


@numba.njit(cache=True, nogil=True, fastmath=True, error_model="numpy", inline="always")
def solid_angle(x, y, z, mx, my, mz, flux, clamp):
    """(cos_e A / (r^2 + A / pi), the unit direction) of a patch at offset (x, y, z) from the probe,
    facing (mx, my, mz); 0 where its back faces the probe."""
    r2 = x * x + y * y + z * z
    inv = np.float32(1.0) / np.sqrt(max(r2, np.float32(1e-12)))
    x, y, z = x * inv, y * inv, z * inv
    return max(-(x * mx + y * my + z * mz), np.float32(0.0)) * flux / (r2 + clamp), x, y, z


@numba.njit(cache=True, nogil=True, fastmath=True, error_model="numpy", inline="always")
def _add_basis(b, i, weight, x, y, z):
    """b[:, i] += weight x the real SH basis (docs/ARCHITECTURE.md's order) of the unit direction."""
    b[0, i] += weight * np.float32(0.282095)
    b[1, i] += weight * np.float32(0.488603) * y
    b[2, i] += weight * np.float32(0.488603) * z
    b[3, i] += weight * np.float32(0.488603) * x
    b[4, i] += weight * np.float32(1.092548) * x * y
    b[5, i] += weight * np.float32(1.092548) * y * z
    b[6, i] += weight * np.float32(0.315392) * (np.float32(3.0) * z * z - np.float32(1.0))
    b[7, i] += weight * np.float32(1.092548) * x * z
    b[8, i] += weight * np.float32(0.546274) * (x * x - y * y)

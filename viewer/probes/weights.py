"""Which probes light a surface point, and how much: the per-point probe weights of the renderer's
indirect light, in the spirit of DDGI (Majercik et al. 2019, "Dynamic Diffuse Global Illumination with
Ray-Traced Irradiance Fields", section 5.2).

A surface point p with normal n takes the probes at the 8 corners of the probe-lattice cell around
p + offset x spacing x n, each weighted by

    trilinear weight  x  validity (1, or probes.INVALID_WEIGHT inside solids)
                      x  back-face weight ((dot(n, w) + 1) / 2)^2 + BACKFACE_FLOOR
                      x  visibility (1 if the segment p -> probe crosses no surface, else 0)

(w the unit direction from p to the probe) and renormalized. The visibility is exact: each segment is
cast against the scene's triangles (viewer/rays/cast.py), so a face never mixes in a probe it cannot see (the
inside of a box, the far side of a thin wall), which the lattice alone cannot tell. A point that sees
none of its 8 probes lies in a gap narrower than the lattice (the ceiling above a lamp hung 1 cm below
it, the floor under a box): it gets no indirect light, as in Mitsuba, instead of light from probes
that cannot reach it.

Visibility depends on the geometry and the probe lattice only, never on the light: it is computed once
per scene and probe layout (`SurfaceWeights.of`), and every GI update after that is a weighted sum of 8
probes per point (`SurfaceBake`, over the lightmap's texels for viewer/gpu/indirect_bake.py).
"""

from __future__ import annotations

from dataclasses import dataclass

import numba
import numpy as np

from viewer.rays import dda, embree
from viewer.rays.cast import TriangleCaster, distinct_rows
from viewer.probes import sh
from viewer.probes.grid import ProbeGrid

NORMAL_OFFSET = 0.25
"""The lattice cell is the one around p + NORMAL_OFFSET probe spacings along n: a little off the surface,
so that more of the 8 probes lie in front of it."""
BACKFACE_FLOOR = 0.2
"""DDGI's floor of the back-face weight, so that a point whose probes all lie behind its plane (a face
closer to a probe layer than the offset) still gets their light, smoothly."""
SURFACE_LIFT = 1e-4
"""The visibility segments start this far off the surface, in probe spacings (not through the face
itself)."""
CORNERS = np.array([[c & 1, (c >> 1) & 1, (c >> 2) & 1] for c in range(8)], np.int64)
"""Corner c of a lattice cell is base + CORNERS[c] (x in bit 0, y in bit 1, z in bit 2)."""


@dataclass(frozen=True)
class SurfaceWeights:
    """For P surface points: the lattice cell (P, 3) of each and the normalized weights (P, 8) of its
    corners (CORNERS order). Weights sum to 1 per point."""

    base: np.ndarray
    weights: np.ndarray
    resolution: int

    @staticmethod
    def of(points: np.ndarray, normals: np.ndarray, probes: ProbeGrid, occluders: dda.Cells | TriangleCaster,
           normal_offset: float = NORMAL_OFFSET) -> "SurfaceWeights":
        """The weights of points (P, 3) with unit normals (P, 3) against the lattice of `probes`, with
        the visibility cast against `occluders`, the scene's triangles: a TriangleCaster (Embree, where a
        detailed mesh's cells list hundreds of triangles each), or their dda.Cells."""
        caster = occluders if isinstance(occluders, TriangleCaster) else TriangleCaster.marching(occluders)
        p = np.ascontiguousarray(points, np.float64).reshape(-1, 3)
        n = np.ascontiguousarray(normals, np.float64).reshape(-1, 3)
        lattice = (np.asarray(probes.lo, np.float64), np.asarray(probes.spacing, np.float64), int(probes.resolution),
                   np.ascontiguousarray(probes.probe_weights(), np.float64), float(normal_offset), SURFACE_LIFT,
                   BACKFACE_FLOOR)
        base, weights = np.empty((len(p), 3), np.int32), np.empty((len(p), 8), np.float32)
        if caster.direct is not None:   # Embree from compiled loops: one pass on every core
            blocks = embree.spread((len(p) + embree.BLOCK - 1) // embree.BLOCK, 1)   # the threads' shares alike
            _weighed(p, n, *lattice, *caster.direct.occlusion, blocks, base, weights)
            return SurfaceWeights(base, weights, int(probes.resolution))
        for start in range(0, len(p), CHUNK):
            part = slice(start, start + CHUNK)
            base[part], w, origin, directions, lengths, asked = _lattice_weights(p[part], n[part], *lattice)
            seen = np.zeros(w.shape)
            point, corner = np.nonzero(asked)
            seen[point, corner] = ~caster.blocked(origin[point], directions[point, corner], lengths[point, corner])
            weights[part] = _normalized(w, seen)
        return SurfaceWeights(base, weights, int(probes.resolution))

    def take(self, rows: np.ndarray) -> "SurfaceWeights":
        """The weights of the points `rows` (indices), in that order."""
        return SurfaceWeights(self.base[rows], self.weights[rows], self.resolution)

    def irradiance(self, probes: ProbeGrid, normals: np.ndarray) -> np.ndarray:
        """(P, 3) irradiance at the points from `probes` (the same lattice as the weights)."""
        index = np.minimum(self.base[:, None, :] + CORNERS[None], self.resolution - 1)
        c = probes.coefficients[index[..., 0], index[..., 1], index[..., 2]]        # (P, 8, 9, 3)
        mixed = np.einsum("pk,pkjc->pjc", self.weights, c)
        y = sh.basis(np.asarray(normals, np.float64).reshape(-1, 3)) * sh.COSINE_LOBE
        return np.maximum(np.einsum("pj,pjc->pc", y, mixed), 0.0)


CHUNK = 1 << 16
"""Points weighed at a time: their visibility rays take 27 MB."""


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _lattice_weights(points, normals, lo, spacing, m, probe_weight, offset, lift, floor):
    """Each point's lattice cell (P, 3), its 8 probes' weights before visibility (P, 8), and the segments
    from the point to the probes that visibility decides: their common origin (P, 3), unit directions
    (P, 8, 3) and lengths (P, 8), and `asked` (P, 8), the probes in front of the point's plane with a
    weight. For the casters that take their segments as arrays (the DDA's, embreex's binding); with Embree
    called from compiled loops, `_weighed` does it all in one pass."""
    count = points.shape[0]
    base = np.empty((count, 3), np.int32)
    weights = np.zeros((count, 8))
    directions = np.zeros((count, 8, 3))
    lengths = np.zeros((count, 8))
    origin = np.empty((count, 3))
    asked = np.zeros((count, 8), np.bool_)
    for r in range(count):
        c0, c1, c2, f0, f1, f2, ox, oy, oz = _cell(points, normals, r, lo, spacing, m, offset, lift)
        base[r, 0], base[r, 1], base[r, 2] = c0, c1, c2
        origin[r, 0], origin[r, 1], origin[r, 2] = ox, oy, oz
        for c in range(8):
            w, ask, dx, dy, dz, length = _corner(points, normals, r, c, c0, c1, c2, f0, f1, f2, ox, oy, oz, lo,
                                                 spacing, m, probe_weight, floor)
            weights[r, c] = w
            if ask:
                directions[r, c, 0], directions[r, c, 1], directions[r, c, 2] = dx, dy, dz
                lengths[r, c] = length
                asked[r, c] = True
    return base, weights, origin, directions, lengths, asked


@numba.njit(cache=True, nogil=True, parallel=True, error_model="numpy")
def _weighed(points, normals, lo, spacing, m, probe_weight, offset, lift, floor, query, scene, blocks, base, out):
    """`_lattice_weights`, the segments' visibility through Embree and `_normalized`, point by point on
    every core: the same weights, without the (P, 8, 3) segments in memory (0.36 s of a 68k-triangle
    scan's 276k samples in numpy and one thread)."""
    count = points.shape[0]
    for i in numba.prange(blocks.shape[0]):
        block = blocks[i]
        record = embree.record()
        w, seen = np.empty(8), np.empty(8)
        for r in range(block * embree.BLOCK, min(count, (block + 1) * embree.BLOCK)):
            c0, c1, c2, f0, f1, f2, ox, oy, oz = _cell(points, normals, r, lo, spacing, m, offset, lift)
            base[r, 0], base[r, 1], base[r, 2] = c0, c1, c2
            for c in range(8):
                w[c], ask, dx, dy, dz, length = _corner(points, normals, r, c, c0, c1, c2, f0, f1, f2, ox, oy, oz,
                                                        lo, spacing, m, probe_weight, floor)
                seen[c] = 0.0
                if ask and not embree.occluded(query, scene, record, ox, oy, oz, dx, dy, dz, length):
                    seen[c] = 1.0
            total, total_seen = _sum8(w[0], w[1], w[2], w[3], w[4], w[5], w[6], w[7]), _sum8(
                w[0] * seen[0], w[1] * seen[1], w[2] * seen[2], w[3] * seen[3], w[4] * seen[4], w[5] * seen[5],
                w[6] * seen[6], w[7] * seen[7])
            lit = total_seen > 1e-6 * total
            for c in range(8):
                out[r, c] = np.float32(w[c] * seen[c] / total_seen) if lit else np.float32(0.0)


@numba.njit(cache=True, nogil=True, inline="always")
def _sum8(a, b, c, d, e, f, g, h):
    """numpy's sum of 8 numbers (its pairwise order), so that `_weighed` matches `_normalized` bit for bit."""
    return ((a + b) + (c + d)) + ((e + f) + (g + h))


@numba.njit(cache=True, nogil=True, inline="always", error_model="numpy")
def _cell(points, normals, r, lo, spacing, m, offset, lift):
    """Point r's lattice cell (c0, c1, c2), its place in it (f0, f1, f2) and its segments' origin."""
    unit = min(spacing[0], spacing[1], spacing[2])
    u0 = min(max((points[r, 0] + offset * unit * normals[r, 0] - lo[0]) / spacing[0] - 0.5, 0.0), m - 1.0)
    u1 = min(max((points[r, 1] + offset * unit * normals[r, 1] - lo[1]) / spacing[1] - 0.5, 0.0), m - 1.0)
    u2 = min(max((points[r, 2] + offset * unit * normals[r, 2] - lo[2]) / spacing[2] - 0.5, 0.0), m - 1.0)
    c0 = min(int(np.floor(u0)), max(m - 2, 0))
    c1 = min(int(np.floor(u1)), max(m - 2, 0))
    c2 = min(int(np.floor(u2)), max(m - 2, 0))
    ox = points[r, 0] + lift * unit * normals[r, 0]
    oy = points[r, 1] + lift * unit * normals[r, 1]
    oz = points[r, 2] + lift * unit * normals[r, 2]
    return c0, c1, c2, u0 - c0, u1 - c1, u2 - c2, ox, oy, oz


@numba.njit(cache=True, nogil=True, inline="always", error_model="numpy")
def _corner(points, normals, r, c, c0, c1, c2, f0, f1, f2, ox, oy, oz, lo, spacing, m, probe_weight, floor):
    """Corner c's weight before visibility, whether visibility decides it (a probe in front of the point's
    plane, with a weight), and then its segment's unit direction and length."""
    b0, b1, b2 = c & 1, (c >> 1) & 1, (c >> 2) & 1
    trilinear = (f0 if b0 else 1.0 - f0) * (f1 if b1 else 1.0 - f1) * (f2 if b2 else 1.0 - f2)
    i0, i1, i2 = min(c0 + b0, m - 1), min(c1 + b1, m - 1), min(c2 + b2, m - 1)
    px, py, pz = lo[0] + (i0 + 0.5) * spacing[0], lo[1] + (i1 + 0.5) * spacing[1], lo[2] + (i2 + 0.5) * spacing[2]
    tx, ty, tz = px - points[r, 0], py - points[r, 1], pz - points[r, 2]
    distance = np.sqrt(tx * tx + ty * ty + tz * tz)
    cosine = (tx * normals[r, 0] + ty * normals[r, 1] + tz * normals[r, 2]) / max(distance, 1e-300)
    w = trilinear * probe_weight[i0, i1, i2] * (((cosine + 1.0) / 2.0) ** 2 + floor)
    if cosine > 0.0 and w > 0.0:   # behind the point's plane the surface itself is in the way
        sx, sy, sz = px - ox, py - oy, pz - oz
        length = np.sqrt(sx * sx + sy * sy + sz * sz)
        return w, True, sx / length, sy / length, sz / length, length
    return w, False, 0.0, 0.0, 0.0, 0.0


def _normalized(w: np.ndarray, seen: np.ndarray) -> np.ndarray:
    """The visible probes' weights (P, 8) summing to 1; none where no probe is visible (a gap narrower
    than the lattice, left dark)."""
    total, total_seen = w.sum(axis=1), (w * seen).sum(axis=1)
    lit = total_seen > 1e-6 * total
    return np.where(lit[:, None], w * seen / np.where(lit, total_seen, 1.0)[:, None], 0.0).astype(np.float32)


@dataclass(frozen=True)
class SurfaceBake:
    """The irradiance of T surface points as a function of the probes, ready to evaluate once per GI
    update: E_t = sum_k weights[t, k] E(probe_k, n_t), with E(probe, n) the probe's SH convolved with the
    cosine lobe about n. Points of one face share a normal, so E is computed once per (probe, normal)
    pair that some point uses (`pair_probe`, `pair_normal`) and each point sums 8 of them: 24
    multiply-adds a point instead of 8 x 27."""

    pair_probe: np.ndarray
    """(Q,) int32 flat index (x-major: (i M + j) M + k) of each pair's probe."""
    pair_normal: np.ndarray
    """(Q,) int32 each pair's row of the distinct normals (`normal_id`'s numbering)."""
    texel_pairs: np.ndarray
    """(T, 8) int32 the pair of each point's corner."""
    weights: np.ndarray
    """(T, 8) float32 SurfaceWeights.weights."""
    lobe: np.ndarray
    """(U, 9) float32 each distinct normal's cosine lobe in SH, made once with the pairs (not on every
    update: 55 ms a GI update for a scanned mesh's million pairs) and per normal, not per pair (the SH
    basis of the 68k-triangle scan's 2 M pairs took 0.48 s of a new scene's critical path)."""

    @staticmethod
    def of(weights: SurfaceWeights, normal_id: np.ndarray, normals: np.ndarray) -> "SurfaceBake":
        """normal_id: (T,) each point's row of `normals` (U, 3), the distinct unit normals (a face's
        normal, per side)."""
        base = np.ascontiguousarray(weights.base, np.int64)
        normal_id = np.ascontiguousarray(normal_id, np.int64)
        texel_pairs, pair_probe, pair_normal = _pairs(base, weights.resolution, normal_id, len(normals))
        lobe = np.ascontiguousarray((sh.basis(np.asarray(normals, np.float64)) * sh.COSINE_LOBE).astype(np.float32))
        return SurfaceBake(pair_probe, pair_normal, texel_pairs, weights.weights, lobe)

    def irradiance(self, coefficients: np.ndarray, out: np.ndarray | None = None,
                   points: np.ndarray | None = None) -> np.ndarray:
        """(T, 3) float32 irradiance from the probes' SH (M, M, M, 9, 3); given `points` (indices), only
        those rows of `out` (T, 3) float32 are written, and it is returned."""
        flat = np.ascontiguousarray(np.asarray(coefficients, np.float32).reshape(-1, sh.SH_COUNT, 3))
        pair = _pair_irradiance(flat, self.pair_probe, self.pair_normal, self.lobe)
        if out is None:
            out = np.empty((len(self.weights), 3), np.float32)
        if points is None:
            points = np.arange(len(self.weights))
        _mix(pair, self.texel_pairs, self.weights, out, points)
        return out


def lobe_normals(normals: np.ndarray, normal_id: np.ndarray, coarse: np.ndarray,
                 steps: int = 32) -> tuple[np.ndarray, np.ndarray]:
    """(normal_id, normals) for `SurfaceBake.of`: the points in `coarse` (T,) bool take their normals
    with each component rounded to 1 / `steps` (and made unit again); the others keep theirs. A
    scanned mesh's one-sample tiles each have a normal of their own (138k on the 68k-triangle scan, times
    8 probes a pair each); rounded, they share a few thousand, while the irradiance of an L2 lobe turns
    by under 2 degrees' worth."""
    normal_id = np.asarray(normal_id, np.int64)
    if not np.any(coarse):
        return normal_id, normals
    kept = np.zeros(len(normals), bool)          # the normals of the other points, as they are
    kept[normal_id[~coarse]] = True
    used = np.zeros(len(normals), bool)          # and those the coarse points round
    used[normal_id[coarse]] = True
    used = np.flatnonzero(used)
    rounded = np.round(np.asarray(normals)[used] * steps).astype(np.int64)
    first, which = distinct_rows(rounded)
    snapped = rounded[first].astype(np.float64)
    snapped /= np.maximum(np.linalg.norm(snapped, axis=1, keepdims=True), 1e-12)
    number = np.cumsum(kept) - 1
    number[used] = int(kept.sum()) + np.asarray(which).ravel()   # a normal both keep is kept for the others
    ids = np.where(coarse, number[normal_id], np.cumsum(kept)[normal_id] - 1)
    return ids, np.concatenate([np.asarray(normals)[kept], snapped])


@numba.njit(cache=True, nogil=True)
def _pairs(base, m, normal_id, count):
    """Number the (probe, normal) pairs: the points grouped by normal (a counting sort), each group's probes
    numbered in order of first use, a table of the lattice's probes remembering which group numbered them
    last. Linear in the points and the probes, where sorting the 8 keys of a scanned mesh's 276k points
    (55k normals: too many pairs for a table of them all) took 0.4 s."""
    points = base.shape[0]
    start = np.zeros(count + 1, np.int64)
    for t in range(points):
        start[normal_id[t] + 1] += 1
    for g in range(count):
        start[g + 1] += start[g]
    order, filled = np.empty(points, np.int64), start[:-1].copy()
    for t in range(points):
        order[filled[normal_id[t]]] = t
        filled[normal_id[t]] += 1
    group, slot = np.full(m * m * m, -1, np.int64), np.empty(m * m * m, np.int64)
    texel_pairs = np.empty((points, 8), np.int32)
    pair_probe, pair_normal = np.empty(points * 8, np.int32), np.empty(points * 8, np.int32)
    used = 0
    for g in range(count):
        for i in range(start[g], start[g + 1]):
            t = order[i]
            for c in range(8):
                probe = ((min(base[t, 0] + (c & 1), m - 1) * m + min(base[t, 1] + ((c >> 1) & 1), m - 1)) * m
                         + min(base[t, 2] + ((c >> 2) & 1), m - 1))
                if group[probe] != g:
                    group[probe], slot[probe] = g, used
                    pair_probe[used], pair_normal[used] = probe, g
                    used += 1
                texel_pairs[t, c] = slot[probe]
    return texel_pairs, pair_probe[:used].copy(), pair_normal[:used].copy()


@numba.njit(cache=True, nogil=True, parallel=True)
def _pair_irradiance(coefficients, pair_probe, pair_normal, lobe):
    out = np.empty((pair_probe.shape[0], 3), np.float32)
    for q in numba.prange(pair_probe.shape[0]):
        c, n = coefficients[pair_probe[q]], pair_normal[q]
        for channel in range(3):
            total = np.float32(0.0)
            for j in range(c.shape[0]):
                total += lobe[n, j] * c[j, channel]
            out[q, channel] = total
    return out


@numba.njit(cache=True, nogil=True, parallel=True)
def _mix(pair, texel_pairs, weights, out, points):
    for i in numba.prange(points.shape[0]):
        t = points[i]
        r = g = b = np.float32(0.0)
        for k in range(8):
            q = texel_pairs[t, k]
            w = weights[t, k]
            r += w * pair[q, 0]
            g += w * pair[q, 1]
            b += w * pair[q, 2]
        out[t, 0], out[t, 1], out[t, 2] = max(r, 0.0), max(g, 0.0), max(b, 0.0)

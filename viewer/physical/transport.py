"""Multi-bounce diffuse light transport between voxels (numpy): the reference solver.

The paper (R. Yang) writes the light in the scene as a Markov chain: a transition function T moves
radiance from every voxel to every other one, bounce after bounce, and the final light is the sum of the
chain (eq. 23-30):

    B = B0 + T B0 + T^2 B0 + ...,   T_ij = albedo_i / pi * G_ij

with B the outgoing radiance of a Lambertian voxel (B_i = Le_i + albedo_i / pi * E_i) and E_i = sum_j
B_j G_ij its irradiance. Two kernels G:

- `physical`: point-to-patch form factor, both cosines, 1/r^2, the sender's area, visibility through the
  voxel grid:  G_ij = cos_i cos_j A_j / (r^2 + A_j / pi) V_ij. The A_j / pi term is the near-field
  clamp: the exact on-axis form factor of a disc of area A_j, so G stays finite for neighbours.
- `paper`: eq. 25 as written: the receiver cosine only, no visibility:  G_ij = cos_i A_j / (r^2 + A_j/pi).

A receiver cannot gather more than pi (its whole hemisphere); rows above that are scaled back, so the
series converges for every albedo below 1. The physical kernel only needs this for discretization
error; the paper kernel needs it because without visibility it counts hidden surfaces too.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import sparse

from viewer.rays.raymarch import Tracer
from viewer.rays.sun import voxel_sun_cover
from viewer.scene import DirectionalLight
from viewer.rays.voxels import FACINGS, SURFACE_OFFSET, VoxelGrid  # noqa: F401  (SURFACE_OFFSET: re-exported)

KERNELS = ("physical", "paper")
CLUSTER_RESOLUTION = 16
"""Visibility between far voxels is traced between clusters of a grid about this fine (see _Visibility)."""


@dataclass(frozen=True)
class TransportSettings:
    kernel: str = "physical"
    """`physical` (form factor with visibility) or `paper` (eq. 25: receiver cosine, no visibility)."""
    bounces: int = 100
    """Most bounces summed. The first is the direct light (emitters and sun) reflected once, so 0 and 1
    both give direct light only."""
    tolerance: float = 1e-4
    """Stop once a bounce adds less than this fraction of the light gathered so far."""
    extrapolate: bool = True
    """If `bounces` run out first (albedo near 1), add the geometric tail of the remaining bounces."""


@dataclass(frozen=True)
class Radiosity:
    """The converged light of every voxel."""

    radiance: np.ndarray
    """(K, 3) outgoing radiance B (emitted + reflected)."""
    emitted: np.ndarray
    """(K, 3) emitted radiance Le."""
    irradiance: np.ndarray
    """(K, 3) incident irradiance E (from other voxels and the sun)."""
    bounces: int
    """Bounces actually summed."""

    @property
    def reflected(self) -> np.ndarray:
        return self.radiance - self.emitted


def transition_matrix(voxels: VoxelGrid, kernel: str = "physical", tracer: Tracer | None = None,
                      block: int = 192) -> sparse.csr_matrix:
    """The geometric kernel G (K x K, row = receiver) with rows clamped to at most pi."""
    if kernel not in KERNELS:
        raise ValueError(f"kernel must be one of {KERNELS}, not {kernel!r}")
    tracer = tracer or Tracer.build(voxels)
    visibility = _Visibility(voxels, tracer)
    pos, nrm, area = voxels.position, voxels.normal, voxels.area
    k = voxels.count
    # Dot products of d = p_j - p_i expanded into matrix products (BLAS), block by block of receivers.
    pos_sq = np.einsum("ij,ij->i", pos, pos)
    pos_dot_n = np.einsum("ij,ij->i", pos, nrm)
    rows, cols, vals = [], [], []
    for i0 in range(0, k, block):
        i = np.arange(i0, min(i0 + block, k))
        r2 = np.maximum(pos_sq[i, None] + pos_sq[None, :] - 2.0 * (pos[i] @ pos.T), 0.0)
        r2[np.arange(len(i)), i] = 0.0
        r = np.sqrt(np.maximum(r2, 1e-30))
        cos_i = (nrm[i] @ pos.T - pos_dot_n[i, None]) / r
        if kernel == "paper":
            mask = (cos_i > 0) & (r2 > 0)
            ii, jj = np.nonzero(mask)
            rows.append(i[ii]), cols.append(jj)
            vals.append(cos_i[ii, jj] * area[jj] / (r2[ii, jj] + area[jj] / np.pi))
            continue
        cos_j = (pos[i] @ nrm.T - pos_dot_n[None, :]) / r
        # Symmetric visibility: trace each unordered pair once (j > i) and fill both directions.
        mask = (cos_i > 0) & (cos_j > 0) & (np.arange(k)[None, :] > i[:, None])
        ii, jj = np.nonzero(mask)
        gi, gj = i[ii], jj
        visible = visibility.between(gi, gj)
        gi, gj, ii, jj = gi[visible], gj[visible], ii[visible], jj[visible]
        both = cos_i[ii, jj] * cos_j[ii, jj]
        dist2 = r2[ii, jj]
        rows += [gi, gj]
        cols += [gj, gi]
        vals += [both * area[gj] / (dist2 + area[gj] / np.pi), both * area[gi] / (dist2 + area[gi] / np.pi)]
    g = sparse.csr_matrix((np.concatenate(vals).astype(np.float32),
                           (np.concatenate(rows), np.concatenate(cols))), shape=(k, k))
    return _clamp_rows(g)


def _segments_visible(tracer: Tracer, h: float, pa, na, pb, nb) -> np.ndarray:
    """Visibility between surface points (with their normals) through the voxel grid."""
    return tracer.segments_clear(pa + SURFACE_OFFSET * h * na, pb + SURFACE_OFFSET * h * nb)


@dataclass(frozen=True)
class Clusters:
    """Clusters of voxels for far-field visibility: cells of `factor`^3 voxels, one cluster per facing
    (keys sorted). The numpy and the compute-shader solvers share them."""

    factor: int
    index: np.ndarray
    """(K,) cluster of each voxel."""
    cell: np.ndarray
    """(K, 3) cluster cell of each voxel (voxel coords // factor)."""
    position: np.ndarray
    """(C, 3) area-weighted centroid."""
    normal: np.ndarray
    """(C, 3) unit area-weighted normal."""
    cluster_cell: np.ndarray
    """(C, 3) cluster cell of each cluster."""

    @property
    def count(self) -> int:
        return len(self.position)


def clusters_of(voxels: VoxelGrid) -> Clusters:
    factor = max(1, voxels.resolution // CLUSTER_RESOLUTION)
    facing = np.argmax(voxels.normal @ FACINGS.T, axis=1)
    cc = voxels.coords // factor
    m = -(-voxels.resolution // factor)
    keys, index = np.unique((cc[:, 0] + cc[:, 1] * m + cc[:, 2] * m * m) * 6 + facing, return_inverse=True)
    count = len(keys)
    w = voxels.area[:, None]
    total = lambda x: np.stack([np.bincount(index, x[:, c], count) for c in range(3)], 1)
    position = total(voxels.position * w) / np.bincount(index, voxels.area, count)[:, None]
    n = total(voxels.normal * w)
    normal = n / np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-30)
    cell_id = keys // 6
    cluster_cell = np.stack([cell_id % m, (cell_id // m) % m, cell_id // (m * m)], axis=1)
    return Clusters(factor, index, cc, position, normal, cluster_cell)


class _Visibility:
    """V_ij for pairs of voxels, exact where it shapes the picture and clustered where it does not.

    Pairs that involve an emitter (direct light and its hard shadow edges) and pairs of neighbouring
    voxels are traced voxel to voxel. Every other pair takes the visibility of the pair of clusters
    (CLUSTER_CELLS^3 cells, one cluster per facing) that holds it: indirect light is smooth, and this
    cuts the rays traced by about CLUSTER_CELLS^6 / 2 at 32^3 and above. Cluster pairs are traced once
    and remembered.
    """

    def __init__(self, voxels: VoxelGrid, tracer: Tracer):
        self.voxels, self.tracer = voxels, tracer
        clusters = clusters_of(voxels)
        self.factor, self.cluster, self.cluster_cell = clusters.factor, clusters.index, clusters.cell
        self.c_pos, self.c_nrm = clusters.position, clusters.normal
        self.known = np.full((clusters.count, clusters.count), -1, np.int8)
        self.emitter = np.any(voxels.emission > 0, axis=1)

    def between(self, i: np.ndarray, j: np.ndarray) -> np.ndarray:
        v = self.voxels
        exact = self.emitter[i] | self.emitter[j] | (self.factor == 1)
        exact |= np.abs(self.cluster_cell[i] - self.cluster_cell[j]).max(axis=1) <= 1
        out = np.empty(len(i), bool)
        e = np.nonzero(exact)[0]
        out[e] = _segments_visible(self.tracer, v.voxel_size, v.position[i[e]], v.normal[i[e]],
                                   v.position[j[e]], v.normal[j[e]])
        f = np.nonzero(~exact)[0]
        ci, cj = self.cluster[i[f]], self.cluster[j[f]]
        unknown = self.known[ci, cj] < 0
        if unknown.any():
            count = len(self.known)
            # one trace per unordered pair, from the lower cluster index: V is symmetric
            lo, hi = np.minimum(ci[unknown], cj[unknown]), np.maximum(ci[unknown], cj[unknown])
            pairs = np.unique(lo * count + hi)
            a, b = pairs // count, pairs % count
            seen = _segments_visible(self.tracer, v.voxel_size, self.c_pos[a], self.c_nrm[a],
                                     self.c_pos[b], self.c_nrm[b])
            self.known[a, b] = seen
            self.known[b, a] = seen
        out[f] = self.known[ci, cj] > 0
        return out


def _clamp_rows(g: sparse.csr_matrix) -> sparse.csr_matrix:
    total = np.asarray(g.sum(axis=1)).ravel()
    scale = np.where(total > np.pi, np.pi / np.maximum(total, 1e-30), 1.0).astype(np.float32)
    return sparse.diags(scale) @ g


def sun_irradiance(voxels: VoxelGrid, sun: DirectionalLight | None, tracer: Tracer | None = None) -> np.ndarray:
    """(K, 3) irradiance from the directional light: E_sun * max(0, n.l) times the share of the voxel's
    surface that sees it (`viewer.rays.sun`)."""
    if sun is None or not np.any(sun.irradiance > 0):
        return np.zeros((voxels.count, 3))
    tracer = tracer or Tracer.build(voxels)
    share = np.maximum(voxels.normal @ sun.direction, 0.0) * voxel_sun_cover(tracer, voxels, sun.direction)
    return share[:, None] * sun.irradiance[None, :]


def direct_irradiance(voxels: VoxelGrid, tracer: Tracer | None = None, kernel: str = "physical",
                      chunk: int = 1 << 21) -> np.ndarray:
    """(K, 3) irradiance straight from the emitters, summed over the fine light samples with the same
    kernel as the bounces: `physical` E_i = sum_s Le_s cos_i cos_s A_s / (r^2 + A_s / pi) V(i, voxel of s);
    `paper` drops the emitter's cosine and the visibility (eq. 25), so it lights what lies in a box's
    shadow; emitters still emit from their front side only."""
    lights = voxels.lights
    out = np.zeros((voxels.count, 3))
    if not lights.count:
        return out
    tracer = tracer or Tracer.build(voxels)
    per = max(1, chunk // lights.count)
    for s0 in range(0, voxels.count, per):
        i = np.arange(s0, min(s0 + per, voxels.count))
        p, n = voxels.position[i], voxels.normal[i]
        # d = light - receiver, its dot products as matrix products
        r2 = np.maximum((p * p).sum(1)[:, None] + (lights.position ** 2).sum(1)[None] - 2.0 * p @ lights.position.T, 0.0)
        r = np.sqrt(np.maximum(r2, 1e-30))
        cos_i = (n @ lights.position.T - (p * n).sum(1)[:, None]) / r
        cos_s = (p @ lights.normal.T - (lights.position * lights.normal).sum(1)[None]) / r
        if kernel == "paper":
            # no emitter cosine and no visibility, but emitters stay one-sided (the fixed convention)
            weight = np.where((cos_i > 0) & (cos_s > 0), cos_i * lights.area / (r2 + lights.area / np.pi), 0.0)
            # like the rows of G: no receiver gathers more than its hemisphere
            total = weight.sum(axis=1, keepdims=True)
            weight *= np.where(total > np.pi, np.pi / np.maximum(total, 1e-30), 1.0)
        else:
            weight = np.where((cos_i > 0) & (cos_s > 0), cos_i * cos_s * lights.area / (r2 + lights.area / np.pi), 0.0)
            weight *= light_visibility(tracer, voxels, voxels.position[i], voxels.normal[i], weight > 0)
        out[i] = weight @ lights.radiance
    return out


def light_visibility(tracer: Tracer, voxels: VoxelGrid, points, normals, needed) -> np.ndarray:
    """(P, S) visibility from surface points (offset along `normals`; None for free-space points) to
    the light samples, traced once per (point, emitting voxel) and shared by that voxel's pieces."""
    lights = voxels.lights
    emitters, piece_of = np.unique(lights.voxel, return_inverse=True)
    need = np.zeros((len(points), len(emitters)), bool)
    rows, cols = np.nonzero(needed)
    need[rows, piece_of[cols]] = True
    pi, ei = np.nonzero(need)
    e = emitters[ei]
    h = voxels.voxel_size
    end = voxels.position[e] + SURFACE_OFFSET * h * voxels.normal[e]
    start = points[pi] if normals is None else points[pi] + SURFACE_OFFSET * h * normals[pi]
    seen = np.zeros(need.shape, bool)
    seen[pi, ei] = tracer.segments_clear(start, end)
    return seen[:, piece_of]


def _geometric_tail(previous: np.ndarray, last: np.ndarray) -> np.ndarray:
    """The bounces not summed yet. After many bounces each one is the last times a fixed ratio r (the
    dominant eigenvalue of T, below 1), so the rest of eq. 30 adds last * r / (1 - r)."""
    ratio = last.sum(axis=0) / np.maximum(previous.sum(axis=0), 1e-30)
    ratio = np.clip(ratio, 0.0, 0.9999)
    return last * (ratio / (1.0 - ratio))


def solve(voxels: VoxelGrid, sun: DirectionalLight | None = None,
          settings: TransportSettings = TransportSettings(), transition: sparse.csr_matrix | None = None,
          tracer: Tracer | None = None) -> Radiosity:
    """Sum the light transition bounce after bounce (eq. 30) until it converges.

    The first bounce (emitters and sun -> surfaces) uses the fine light samples; the transition
    matrix then carries the reflected light, bounce after bounce.
    """
    tracer = tracer or Tracer.build(voxels)
    g = transition if transition is not None else transition_matrix(voxels, settings.kernel, tracer)
    reflectance = voxels.albedo / np.pi
    e_direct = sun_irradiance(voxels, sun, tracer) + direct_irradiance(voxels, tracer, settings.kernel)
    emitted = voxels.emission.astype(np.float64)
    bounce = reflectance * e_direct
    reflected = bounce.copy()
    done, converged = 1, False
    previous = bounce
    for done in range(1, settings.bounces + 1):
        if done > 1:
            previous, bounce = bounce, reflectance * (g @ bounce.astype(np.float32))
            reflected += bounce
        if np.abs(bounce).max() <= settings.tolerance * max(np.abs(reflected).max(), 1e-30):
            converged = True
            break
    if not converged and settings.extrapolate and done > 1:
        reflected += _geometric_tail(previous, bounce)
    irradiance = np.asarray(g @ reflected.astype(np.float32), np.float64) + e_direct
    return Radiosity(radiance=emitted + reflected, emitted=emitted, irradiance=irradiance, bounces=done)

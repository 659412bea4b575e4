"""The one-bounce feature: the direct light reflected once by the surfaces, gathered at the probes.

Apart from the input channels (viewer/neural/encoding.py): `Bounce` is also kept per scene across
edits (viewer/neural/encoder.py) and measured against the solver's reflected light
(viewer/training/bounce_floor.py).
"""

from __future__ import annotations

from functools import lru_cache

import numba
import numpy as np

from viewer.neural.direct import emitter_sh, facings, splat
from viewer.probes import sh
from viewer.probes.grid import ProbeGrid
from viewer.rays.voxels import VoxelGrid


BOUNCE_PATCH = 2
"""Edge, in probe-lattice cells, of the patches (per facing) that reflect the light in `bounce_sh`."""
READ_BACK = 0.75
"""How far in front of a voxel, in voxels, `Bounce.reflected` reads the light of a further bounce from
the probes. The seen light's bounces, each read back at the voxels and gathered again, converge to the
solver's probes within 1.1% at three quarters of a voxel on the Cornell box, paper-test and
CornellBox-Original (four bounces and the tail: 0.989-1.004 of their mean), and fall 1-4.6% short at
half a voxel (0.954-0.990), where the probes nearest a wall, half a lattice cell from it, see the wall
in half their directions and L2 SH spreads that over the lobe; a whole voxel overshoots (1.002-1.010)."""
BOUNCE_LATTICE = 3
"""`bounce_sh` and `Bounce.gathered` gather on a lattice this many times coarser than the probes' and
interpolate: the bounce is smooth (measured on 20 v2 rooms, the best-scaled one-bounce DC is 37% off the
solver's reflected light at 12^3 interpolated, 41% at 24^3, where each room's mean is 66% off). A 24^3
lattice gathers at 8^3 (encoding version 14; 12^3 before): 3.4x fewer points, which every edit pays for
(the unshadowed gather of all the surfaces' light), and the network fine-tuned on it keeps every scene's
reflected light within 1.5x the solver's error (docs/TRAINING.md)."""


def bounce_sh(voxels: VoxelGrid, direct: np.ndarray, lo: np.ndarray, hi: np.ndarray, m: int) -> np.ndarray:
    """(P, 9, 3) the direct light reflected once by the surfaces, gathered at the probes without shadows.

    Each voxel's irradiance is its normal's cosine lobe over the direct SH (`direct` (P, 9, 3)) read half
    a voxel in front of it; times albedo / pi it leaves as radiance. Voxels are merged into patches
    (BOUNCE_PATCH cells per facing) that shine on the probes of a lattice BOUNCE_LATTICE times coarser,
    as the emitters do (`emitter_sh`), and the coarse SH is splatted back onto the probes. The light
    reflected many times, and the shadows of this light, are the network's to learn; this term gives it
    the shape: which walls are lit, their colour, how far they are."""
    if voxels.count == 0:
        return np.zeros((m ** 3, sh.SH_COUNT, 3))
    return Bounce(voxels, lo, hi, m).sh(voxels.albedo, direct)


class Bounce:
    """`bounce_sh` for one voxel geometry on one lattice, kept across edits (viewer.neural.encoder).

    The gathered SH is linear in the patches' radiance, so a call whose patches mostly shine as they did
    on the previous call (an albedo edit: the direct light is the same, a group's voxels change colour)
    gathers only the difference of the patches that changed and adds it to the kept coarse SH. The
    voxels' irradiance is kept while the direct light stays equal. A call where more than half the
    patches change gathers everything again, which also drops the round-off the sums carried."""

    def __init__(self, voxels: VoxelGrid, lo: np.ndarray, hi: np.ndarray, m: int, patch: int = BOUNCE_PATCH,
                 lattice: int = BOUNCE_LATTICE):
        lo, hi = np.asarray(lo, np.float64), np.asarray(hi, np.float64)
        self.position, self.normal, self.area = voxels.position, voxels.normal, voxels.area
        self.m, spacing = m, (hi - lo) / m
        self._front = splat(voxels.position + 0.5 * voxels.voxel_size * voxels.normal, lo, spacing, m)
        self._read_back = splat(voxels.position + READ_BACK * voxels.voxel_size * voxels.normal, lo, spacing, m)
        facing = facings(voxels.normal)
        block = np.floor((voxels.position - lo) / (spacing * patch)).astype(np.int64)
        _, patch = np.unique(row_keys(np.column_stack([block, facing])), return_inverse=True)
        self._patch = patch.ravel()
        self._count = int(self._patch.max()) + 1 if len(self._patch) else 0
        self._patch_area = np.bincount(self._patch, voxels.area, minlength=self._count)
        normal = self._mean(voxels.normal)
        self._patch_normal = normal / np.maximum(np.linalg.norm(normal, axis=1, keepdims=True), 1e-12)
        self._patch_position = self._mean(voxels.position)
        coarse = max(m // lattice, 2)
        self._points = ProbeGrid.positions_for(lo, hi, coarse).reshape(-1, 3)
        self._spread = spread(tuple(lo), tuple(hi), m, coarse)
        self._direct = self._leaving_per_albedo = None
        self._lobe = self._corners = None   # `reflected`'s: the voxels' cosine lobes, their 8 probes
        self._radiance = self._gathered = None
        self.gathered_patches = 0
        """How many patches the last `sh` gathered (all of them, or the ones whose light changed)."""

    def fits(self, voxels: VoxelGrid) -> bool:
        return all(a is b or np.array_equal(a, b) for a, b in
                   ((self.position, voxels.position), (self.normal, voxels.normal), (self.area, voxels.area)))

    def _mean(self, values: np.ndarray) -> np.ndarray:
        """(patches, C) the voxels' (K, C) `values` averaged over each patch by area."""
        return np.stack([np.bincount(self._patch, self.area * values[:, k], minlength=self._count)
                         for k in range(values.shape[1])], 1) / self._patch_area[:, None]

    def gathered(self, radiance: np.ndarray) -> np.ndarray:
        """(P, 9, C) the light of the voxels leaving with `radiance` (K, C), gathered at the probes as `sh`
        gathers the bounce (patches as points, no shadows): the encoding's `bounce` input takes the
        surfaces' light of every bounce this way (`seen_light`), and `viewer.training.bounce_floor` the
        solver's."""
        channels = np.shape(radiance)[1]
        if self._count == 0:
            return np.zeros((self.m ** 3, sh.SH_COUNT, channels))
        lights = (self._patch_position, self._patch_normal, self._patch_area, self._mean(radiance))
        coarse = emitter_sh(lights, self._points)
        return spread_onto(self._spread, coarse.reshape(len(self._points), -1)).reshape(-1, sh.SH_COUNT, channels)

    def light(self, direct: np.ndarray | None, irradiance: np.ndarray | None = None) -> None:
        """Light the voxels by `direct` (P, 9, 3), SH at the probes read half a voxel in front of each, or
        by their own `irradiance` (K, 3) (`irradiance.voxel_direct`; then `direct` is not read): what
        `leaving` reflects. Kept while the light stays equal."""
        light = direct if irradiance is None else irradiance
        if self._direct is None or self._direct.shape != np.shape(light) or not np.array_equal(light, self._direct):
            self._leaving_per_albedo = (self._leaving(direct) if irradiance is None
                                        else np.asarray(irradiance, np.float64) / np.pi).astype(np.float64)
            self._direct = np.array(light, copy=True)

    def leaving(self, albedo: np.ndarray) -> np.ndarray:
        """(K, 3) the radiance each voxel of `albedo` (K, 3) reflects under the direct light of the last
        `light` or `sh` call: what the seen rays gather (viewer/neural/seen.py)."""
        return albedo * self._leaving_per_albedo

    def reflected(self, albedo: np.ndarray, light: np.ndarray) -> np.ndarray:
        """(K, C) the radiance each voxel of `albedo` (K, C) reflects under `light` (P, 9, C), SH at the
        probes read READ_BACK voxels in front of it (in one compiled pass: three times faster than the
        same sums in numpy on a Cornell box)."""
        return np.asarray(albedo, np.float32) * self._leaving(light, further=True)

    def _leaving(self, light: np.ndarray, further: bool = False) -> np.ndarray:
        """(K, C) float32 max(0, irradiance) / pi of every voxel under `light` (P, 9, C), read half a voxel
        in front of it (the direct light's SH) or READ_BACK voxels (a `further` bounce's)."""
        if self._lobe is None:
            self._lobe = np.ascontiguousarray(sh.basis(self.normal) * sh.COSINE_LOBE / np.pi, np.float32)
            self._corners = {False: _stacked(self._front), True: _stacked(self._read_back)}
        return _reflected(*self._corners[further], self._lobe, np.ascontiguousarray(light, np.float32))

    def sh(self, albedo: np.ndarray, direct: np.ndarray, channels: np.ndarray | None = None,
           irradiance: np.ndarray | None = None) -> np.ndarray:
        """(P, 9, 3) `bounce_sh` for the voxels' `albedo` (K, 3) under `direct` (P, 9, 3), or with
        `irradiance` (K, 3) under that light on the voxels themselves (`irradiance.voxel_direct`; then
        `direct` is not read). Only the colour `channels` (3,) bool (default all) are brought up to
        date; the others hold an earlier call's values."""
        channels = np.ones(3, bool) if channels is None else np.asarray(channels, bool)
        if self._count == 0:
            return np.zeros((self.m ** 3, sh.SH_COUNT, 3))
        self.light(direct, irradiance)
        radiance = self._mean(albedo * self._leaving_per_albedo)  # (patches, 3)
        if self._gathered is None:
            change, rows = np.where(channels, radiance, 0.0), np.arange(self._count)
            self._gathered, self._radiance = np.zeros((len(self._points), sh.SH_COUNT, 3)), np.zeros_like(radiance)
        else:
            change = np.where(channels, radiance - self._radiance, 0.0)
            rows = np.flatnonzero(np.any(change != 0.0, axis=1))
            if 2 * len(rows) > self._count:   # most patches changed: gather them all again
                self._gathered[..., channels] = 0.0
                change, rows = np.where(channels, radiance, 0.0), np.arange(self._count)
        if len(rows):
            lights = (self._patch_position[rows], self._patch_normal[rows], self._patch_area[rows], change[rows])
            self._gathered += emitter_sh(lights, self._points)
        self._radiance[:, channels] = radiance[:, channels]
        self.gathered_patches = len(rows)
        return spread_onto(self._spread, self._gathered.reshape(len(self._points), -1)).reshape(-1, sh.SH_COUNT, 3)


def _stacked(corners) -> tuple[np.ndarray, np.ndarray]:
    """`splat`'s eight (index, weight) pairs as (8, K) int64 indices and (8, K) float32 weights."""
    return (np.stack([i for i, _ in corners]).astype(np.int64), np.stack([w for _, w in corners]).astype(np.float32))


def row_keys(rows: np.ndarray) -> np.ndarray:
    """(K,) int64 keys of the (K, D) int rows, in the rows' lexicographic order: `np.unique` of the keys
    groups the rows as `np.unique(rows, axis=0)` does, with a plain sort instead of a sort of rows (3 of a
    Cornell box's 13 ms of patches)."""
    rows = rows - rows.min(axis=0)
    key = np.zeros(len(rows), np.int64)
    for column, radix in zip(rows.T, rows.max(axis=0) + 1):
        key = key * radix + column
    return key


@lru_cache(maxsize=4)
def spread(lo: tuple, hi: tuple, m: int, coarse: int) -> tuple[np.ndarray, np.ndarray]:
    """The trilinear weights that carry a coarse lattice's SH to the probes of the m^3 lattice over the same
    box, as (8, m^3) coarse indices and (8, m^3) weights: one per lattice, whatever the scene inside (a
    moved lamp or object keeps it)."""
    lo, hi = np.asarray(lo, np.float64), np.asarray(hi, np.float64)
    corners = splat(ProbeGrid.positions_for(lo, hi, m).reshape(-1, 3), lo, (hi - lo) / coarse, coarse)
    return (np.stack([i for i, _ in corners]).astype(np.int64),
            np.stack([w for _, w in corners]).astype(np.float64))


def spread_onto(weights: tuple[np.ndarray, np.ndarray], values: np.ndarray) -> np.ndarray:
    """(m^3, F) float64 the coarse lattice's `values` (coarse^3, F) at the probes by `spread`'s weights (one
    compiled pass over the probes: 0.5 ms for a 24^3 lattice's 27 values, where scipy's sparse product
    took 0.9)."""
    index, weight = weights
    out = np.empty((index.shape[1], values.shape[1]))
    _spread_onto(index, weight, np.ascontiguousarray(values, np.float64), out)
    return out


@numba.njit(cache=True, nogil=True, parallel=True)
def _spread_onto(index, weight, values, out):
    for p in numba.prange(index.shape[1]):
        row = out[p]
        row[:] = 0.0
        for k in range(index.shape[0]):
            w, source = weight[k, p], values[index[k, p]]
            for f in range(values.shape[1]):
                row[f] += w * source[f]


@numba.njit(cache=True, nogil=True, parallel=True)
def _reflected(index, weight, lobe, light):
    """(K, C) max(0, irradiance) / pi of each voxel: its 8 probes' SH (`light` (P, 9, C), at `index`
    (8, K) with `weight` (8, K)) against its cosine lobe (`lobe` (K, 9): A_l Y_lm(n) / pi)."""
    k_count, channels = lobe.shape[0], light.shape[2]
    out = np.zeros((k_count, channels), np.float32)
    for k in numba.prange(k_count):
        for c in range(channels):
            total = 0.0
            for j in range(index.shape[0]):
                p, w = index[j, k], weight[j, k]
                part = 0.0
                for b in range(9):
                    part += lobe[k, b] * light[p, b, c]
                total += w * part
            out[k, c] = max(total, 0.0)
    return out

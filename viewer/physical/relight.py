"""The relight stage of the physical GI: given what the geometry stage traced (viewer.physical.geometry), the light
of the scene from its colours, lamps and sun, in milliseconds. It never traces a ray.

With T the transport matrix (the share of voxel i's cosine-weighted gather rays that reach voxel j),
rho the voxel albedo, E_d the irradiance straight from the lamps and the sun, and Le the emission of the
surfaces the gather rays find (large emitters; lamps come through E_d), the reflected radiance R of the
Lambertian voxels solves

    R = rho / pi * E_d + rho * T (Le + R)                               (B = Le + R, eq. 23-30)

whose Neumann series is the paper's Markov chain of bounces (eq. 30): R_0 = rho / pi * E_d + rho T Le
is the first bounce, and each Jacobi sweep R <- R_0 + rho T R adds one more (how the truncated chain of
`bounces` is summed, and how the GPU sweeps). To convergence the CPU sweeps Gauss-Seidel, which uses each
row's update at once (over-relaxed). The sweeps start from the previous solution when there is one (an edit moves the
answer a little) and stop once the largest change is below `tolerance` of the largest radiance; when the
change decays geometrically (albedo near 1) the remaining tail is added in closed form (Aitken), so a
white furnace converges in tens of sweeps, not thousands. The probes are then one product: the SH basis of each probe direction times the radiance of
the voxel it sees, plus the lamps' and the sun's direct light.
"""

from __future__ import annotations

from dataclasses import dataclass

import numba
import numpy as np

from viewer.probes import sh
from viewer.physical.geometry import Geometry, SunPaths
from viewer.physical.lightpaths import LightPaths
from viewer.probes.grid import ProbeGrid
from viewer.rays.voxels import VoxelAlbedo, voxel_albedo
from viewer.scene import Scene


@dataclass(frozen=True)
class Materials:
    """The relight's inputs: what colour and light edits change."""

    albedo: np.ndarray
    """(K, 3) voxel albedo."""
    emission: np.ndarray
    """(K, 3) emitted radiance of the voxels the gather rays find (0 for lamps)."""
    lamp: np.ndarray
    """(U, 3) emitted radiance of each lamp patch (viewer.physical.geometry.LightPaths)."""
    sun: np.ndarray
    """(3,) the sun's irradiance (0 without a sun)."""


def materials(scene: Scene, geometry: Geometry, lights: LightPaths, albedo: VoxelAlbedo | None = None,
              before: tuple | None = None) -> Materials:
    """Per-face colours and emission -> per voxel and per lamp patch (sparse products, no voxelizing).
    `albedo`: the voxel albedo kept across edits of this geometry (only the voxels of recoloured faces
    are summed again); `before`: (the emission array, Materials) of the last call on this geometry and
    lamps, whose emissions serve while the scene's emission is that same array (an albedo edit: two
    products over every face, 16 ms of a million-triangle scan's)."""
    sun = scene.sun.irradiance if scene.sun is not None else np.zeros(3)
    voxel = albedo.of(scene) if albedo is not None else voxel_albedo(geometry.faces, geometry.tint, scene)
    if before is not None and before[0] is scene.emission:
        emission, lamp = before[1].emission, before[1].lamp
    else:
        gathered = np.where(geometry.lamp[:, None], 0.0, scene.emission)
        lamp = (lights.patch_of_sample @ scene.emission[lights.sample_face] if lights.count
                else np.zeros((0, 3)))
        emission, lamp = np.asarray(geometry.faces @ gathered, np.float32), np.asarray(lamp, np.float32)
    return Materials(np.asarray(voxel, np.float32), emission, lamp, np.asarray(sun, np.float64))


@dataclass(frozen=True)
class RelightSettings:
    tolerance: float = 1e-5
    """Stop once a sweep changes no voxel by more than this share of the largest radiance. The answer
    is then within about tolerance / (1 - albedo) of the converged one, wherever the sweeps started:
    an edit's warm-started relight and a cold solve of the edited scene agree to 1e-5."""
    max_sweeps: int = 400
    """Most sweeps (bounces) of one relight."""
    bounces: int | None = None
    """Sum exactly this many bounces from a cold start (1 = direct light reflected once) and do not
    extrapolate: the paper's truncated chain. None: converge."""


@dataclass(frozen=True)
class Lighting:
    reflected: np.ndarray
    """(K, 3) float32 reflected outgoing radiance R of every voxel."""
    direct: np.ndarray
    """(K, 3) float32 irradiance straight from the lamps and the sun."""
    sweeps: int
    """Sweeps this relight took."""


def direct_irradiance(lights: LightPaths, sun: SunPaths, mat: Materials) -> np.ndarray:
    """(K, 3) irradiance straight from the lamps and the sun."""
    voxel_matrix, radiance = lights.columns(mat.lamp)
    direct = dense_times(voxel_matrix, radiance)
    return direct + sun.voxel_cosine[:, None] * mat.sun[None].astype(np.float32)


def first_bounce(geometry: Geometry, lights: LightPaths, sun: SunPaths, mat: Materials) -> tuple[np.ndarray, np.ndarray]:
    """(R_0, E_d): the direct light reflected once plus the gathered emitters' light reflected once,
    and the direct irradiance."""
    direct = direct_irradiance(lights, sun, mat)
    return mat.albedo * (direct / np.float32(np.pi) + gather(geometry.transport, mat.emission)), direct


def solve(geometry: Geometry, lights: LightPaths, sun: SunPaths, mat: Materials,
          settings: RelightSettings = RelightSettings(), previous: Lighting | None = None) -> Lighting:
    """The reflected light of every voxel (see the module docstring), with sweeps on the CPU."""
    first, direct = first_bounce(geometry, lights, sun, mat)
    t, rho = geometry.transport, mat.albedo
    # to convergence, Gauss-Seidel over-relaxed: each voxel gathers the light its predecessors in this
    # sweep already updated; 10 sweeps instead of Jacobi's 17 on the Cornell box (one core, but a sweep is
    # memory-bound: 0.74 ms on one core against 0.66 on two). The paper's truncated chain needs Jacobi's
    # bounce-by-bounce sums.
    if settings.bounces is not None:
        reflected, sweeps = iterate(first, lambda r: _jacobi_sweep(t.indptr, t.indices, t.data, first, rho, r),
                                    settings, previous)
        return Lighting(reflected, direct, sweeps)
    # `iterate` over Gauss-Seidel sweeps, compiled whole: the window's render thread holds Python's lock
    # while it draws, and the few numpy steps between sweeps waited for it (a colour edit's relight took
    # 30-40 ms beside the frames, where it takes 15-17 ms alone)
    warm = previous is not None and previous.reflected.shape == first.shape
    start = (previous.reflected if warm else first).astype(np.float32)
    reflected, sweeps = _converge(t.indptr, t.indices, t.data, first, rho, start, np.float32(settings.tolerance),
                                  settings.max_sweeps)
    return Lighting(reflected, direct, sweeps)


def iterate(first: np.ndarray, sweep, settings: RelightSettings, previous: Lighting | None = None,
            correct=None) -> tuple[np.ndarray, int]:
    """Sweeps R <- sweep(R) = R_0 + rho T R until the change is below the tolerance, from the previous
    solution when its shape fits, with the Aitken tail when the change decays geometrically; with
    `settings.bounces` exactly that many bounces from R_0 (bounces - 1 sweeps). `correct(R)` is told
    of the starting R and of every extrapolated one (the GPU keeps its own copy). Returns (R, sweeps)."""
    warm = settings.bounces is None and previous is not None and previous.reflected.shape == first.shape
    reflected = previous.reflected.copy() if warm else first.copy()
    if correct is not None:
        correct(reflected)
    if settings.bounces is not None:
        for _ in range(1, settings.bounces):
            reflected = sweep(reflected)
        return reflected, max(settings.bounces, 1)
    change_before = ratio_before = None
    sweeps = 0
    for sweeps in range(1, settings.max_sweeps + 1):
        update = sweep(reflected)
        change = update - reflected
        reflected = update
        if np.abs(change).max(initial=0.0) <= settings.tolerance * max(np.abs(reflected).max(initial=0.0), 1e-30):
            break
        if change_before is not None:
            # Aitken: once the change shrinks by the same ratio r every sweep (the dominant mode of
            # rho T), the sweeps still to come add change * r / (1 - r)
            ratio = np.abs(change).sum(axis=0) / np.maximum(np.abs(change_before).sum(axis=0), 1e-30)
            if (ratio_before is not None and np.all(np.abs(ratio - ratio_before) < 1e-3 * ratio)
                    and np.all(ratio < 0.999)):
                reflected = reflected + change * (ratio / (1.0 - ratio)).astype(np.float32)
                if correct is not None:
                    correct(reflected)
                change_before = ratio_before = None
                continue
            ratio_before = ratio
        change_before = change
    return np.asarray(reflected, np.float32), sweeps


def probe_coefficients(geometry: Geometry, lights: LightPaths, sun: SunPaths, mat: Materials,
                       lighting: Lighting, include_emitted: bool = True) -> np.ndarray:
    """(P, 9, 3) incident-radiance SH at every probe: what the probe directions see (the reflected light,
    and with `include_emitted` the gathered emitters), plus the lamps' and the sun's direct light."""
    radiance = lighting.reflected + mat.emission if include_emitted else lighting.reflected
    radiance = np.vstack([radiance, np.zeros((1, 3), np.float32)])     # row K: nothing seen
    coefficients = _project(geometry.probe_hits, geometry.probe_basis_t, np.asarray(radiance, np.float32))
    if include_emitted:
        coefficients += direct_sh(geometry, lights, sun, mat)
    return coefficients


def direct_sh(geometry: Geometry, lights: LightPaths, sun: SunPaths, mat: Materials) -> np.ndarray:
    """(P, 9, 3) float32 SH of the light straight from the lamps and the sun at every probe."""
    p = len(geometry.probe_points)
    out = np.zeros((p, 9, 3), np.float32)
    if lights.count:
        probe_matrix, radiance = lights.columns(mat.lamp, probes=True)
        out += dense_times(probe_matrix, radiance).reshape(p, 9, 3)
    if sun.direction is not None and np.any(mat.sun > 0):
        out += sun.probe_visible[:, None, None] * sh.project_delta(sun.direction, mat.sun)[None].astype(np.float32)
    return out


def probe_grid(geometry: Geometry, coefficients: np.ndarray, dering: float = 0.0) -> ProbeGrid:
    """The probes as a ProbeGrid, invalid ones filled from valid neighbours (viewer.probes.grid.fill_invalid,
    wave by wave as the geometry planned them)."""
    m = geometry.probe_resolution
    if geometry.fill_waves.max(initial=0) < 0:
        grid = np.zeros((m, m, m, 9, 3), np.float32)
    else:
        grid = _fill(np.ascontiguousarray(coefficients, np.float32).reshape(-1, 27).copy(), geometry.fill_waves, m)
        grid = grid.reshape(m, m, m, 9, 3)
    if dering > 0:
        grid = sh.dering(grid, dering)
    return ProbeGrid(lo=geometry.probe_lo, hi=geometry.probe_hi, coefficients=grid, valid=geometry.valid)


# ---- the two products, compiled: each row is independent, so they run on every core ----------------------

def gather(matrix, values: np.ndarray) -> np.ndarray:
    """matrix @ values for a CSR matrix and (K, 3) values: what each receiver's gather rays find."""
    return _csr_times(matrix.indptr, matrix.indices, matrix.data, np.ascontiguousarray(values, np.float32))


def dense_times(matrix: np.ndarray, values: np.ndarray) -> np.ndarray:
    """(R, U) @ (U, 3) -> (R, 3) float32, without BLAS: these products are small, and OpenBLAS's
    threads spin-wait for each other, so one takes tens of milliseconds instead of one whenever the
    renderer keeps the other core busy (measured: viewer.neural.field)."""
    return _dense_times(matrix, np.ascontiguousarray(values, np.float32))


@numba.njit(cache=True, nogil=True, parallel=True)
def _dense_times(matrix, values):
    rows, columns = matrix.shape
    out = np.zeros((rows, 3), np.float32)
    for i in numba.prange(rows):
        a = b = c = 0.0
        for j in range(columns):
            w = matrix[i, j]
            if w != 0.0:
                a += w * values[j, 0]
                b += w * values[j, 1]
                c += w * values[j, 2]
        out[i, 0], out[i, 1], out[i, 2] = a, b, c
    return out


@numba.njit(cache=True, nogil=True, inline="always")
def _row(indptr, indices, data, values, i):
    """Row i of a CSR matrix times (K, 3) values: what receiver i's gather rays find (summed in float32,
    as the values are stored, so that the compiler may vectorize the sum)."""
    a = b = c = np.float32(0.0)
    for e in range(indptr[i], indptr[i + 1]):
        j, w = indices[e], data[e]
        a += w * values[j, 0]
        b += w * values[j, 1]
        c += w * values[j, 2]
    return a, b, c


OVER_RELAXATION = 1.2
"""Successive over-relaxation of the Gauss-Seidel sweep: each voxel moves this far past its Gauss-Seidel
update. Sweeps to converge after a colour edit, omega 1.0 / 1.1 / 1.2 / 1.3 / 1.4: 25 / 20 / 16 / 14 / 17
on paper-train-5 and 13 / 11 / 10 / 14 / 16 on cornell, each closer to the exact answer than plain
Gauss-Seidel."""


@numba.njit(cache=True, nogil=True, fastmath=True)
def _converge(indptr, indices, data, first, albedo, reflected, tolerance, max_sweeps):
    """`iterate` over Gauss-Seidel sweeps of R = R_0 + albedo * T R (the same steps: the tolerance, the
    Aitken tail), in place on `reflected`: each row in voxel order reads the rows before it as they are
    after this sweep, and moves OVER_RELAXATION past its Gauss-Seidel update. Returns (reflected, sweeps)."""
    count = reflected.shape[0]
    change = np.zeros((count, 3), np.float32)
    before = np.zeros(3)
    ratio_before = np.zeros(3)
    have_before = have_ratio = False
    sweeps = 0
    w = np.float32(OVER_RELAXATION)
    for sweeps in range(1, max_sweeps + 1):
        largest_change = largest = 0.0
        total = np.zeros(3)
        for i in range(count):
            a, b, c = _row(indptr, indices, data, reflected, i)
            old = (reflected[i, 0], reflected[i, 1], reflected[i, 2])
            reflected[i, 0] = (1 - w) * old[0] + w * (first[i, 0] + albedo[i, 0] * a)
            reflected[i, 1] = (1 - w) * old[1] + w * (first[i, 1] + albedo[i, 1] * b)
            reflected[i, 2] = (1 - w) * old[2] + w * (first[i, 2] + albedo[i, 2] * c)
            for k in range(3):
                change[i, k] = reflected[i, k] - old[k]
                largest_change = max(largest_change, abs(change[i, k]))
                largest = max(largest, abs(reflected[i, k]))
                total[k] += abs(change[i, k])
        if largest_change <= tolerance * max(largest, 1e-30):
            break
        if have_before:
            ratio = total / np.maximum(before, 1e-30)
            if have_ratio and np.all(np.abs(ratio - ratio_before) < 1e-3 * ratio) and np.all(ratio < 0.999):
                tail = (ratio / (1.0 - ratio)).astype(np.float32)
                for i in range(count):
                    for k in range(3):
                        reflected[i, k] += change[i, k] * tail[k]
                have_before = have_ratio = False
                continue
            ratio_before[:] = ratio
            have_ratio = True
        before[:] = total
        have_before = True
    return reflected, sweeps


@numba.njit(cache=True, nogil=True, parallel=True)
def _jacobi_sweep(indptr, indices, data, first, albedo, values):
    """One sweep, R_0 + albedo * T R, every row from the previous R: one more bounce (eq. 30)."""
    out = np.empty((len(indptr) - 1, 3), np.float32)
    for i in numba.prange(len(indptr) - 1):
        a, b, c = _row(indptr, indices, data, values, i)
        out[i, 0] = first[i, 0] + albedo[i, 0] * a
        out[i, 1] = first[i, 1] + albedo[i, 1] * b
        out[i, 2] = first[i, 2] + albedo[i, 2] * c
    return out


@numba.njit(cache=True, nogil=True, parallel=True)
def _csr_times(indptr, indices, data, values):
    out = np.empty((len(indptr) - 1, 3), np.float32)
    for i in numba.prange(len(indptr) - 1):
        a, b, c = _row(indptr, indices, data, values, i)
        out[i, 0], out[i, 1], out[i, 2] = a, b, c
    return out


@numba.njit(cache=True, nogil=True, parallel=True, fastmath=True)
def _project(hits, basis_t, radiance):
    """(P, 9, 3): sum over each probe's directions of basis x the radiance of the voxel it sees. The
    radiance seen is gathered first, so that each sum is a dot product over the directions that the
    compiler vectorizes (4x faster than accumulating direction by direction, measured), a coefficient's
    three channels in one pass over them."""
    count, directions = hits.shape
    out = np.empty((count, 9, 3), np.float32)
    for p in numba.prange(count):
        seen = np.empty((3, directions), np.float32)
        for r in range(directions):
            j = hits[p, r]
            seen[0, r], seen[1, r], seen[2, r] = radiance[j, 0], radiance[j, 1], radiance[j, 2]
        for k in range(9):
            red = green = blue = np.float32(0.0)
            for r in range(directions):
                w = basis_t[k, r]
                red += w * seen[0, r]
                green += w * seen[1, r]
                blue += w * seen[2, r]
            out[p, k, 0], out[p, k, 1], out[p, k, 2] = red, green, blue
    return out


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _fill(values, waves, m):
    """Each probe of wave w > 0 takes the mean of its 6-neighbours of waves 0..w-1, wave after wave
    (the same as viewer.probes.grid.fill_invalid; probe p = (x M + y) M + z). A probe of wave w has a
    neighbour of wave w - 1 by construction. Scalar loops and numpy's error model (no ZeroDivisionError
    path): array expressions and the error's message formatting took numba 7-15 s of a first run to
    compile."""
    last = waves.max()
    for wave in range(1, last + 1):
        for p in range(m * m * m):
            if waves[p] != wave:
                continue
            x, y, z = p // (m * m), (p // m) % m, p % m
            for c in range(values.shape[1]):
                total = 0.0
                count = 0
                for dx, dy, dz in ((1, 0, 0), (-1, 0, 0), (0, 1, 0), (0, -1, 0), (0, 0, 1), (0, 0, -1)):
                    qx, qy, qz = x + dx, y + dy, z + dz
                    if qx < 0 or qy < 0 or qz < 0 or qx >= m or qy >= m or qz >= m:
                        continue
                    q = (qx * m + qy) * m + qz
                    if 0 <= waves[q] < wave:
                        total += values[q, c]
                        count += 1
                values[p, c] = total / count
    return values

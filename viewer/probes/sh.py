"""Real orthonormal spherical harmonics, bands 0..2 (L2): 9 coefficients per colour channel.

Order and constants are fixed by docs/ARCHITECTURE.md: (l, m) = 00, 1-1, 10, 11, 2-2, 2-1, 20, 21, 22,
for a unit direction (x, y, z) in world axes pointing from the probe towards where the light comes from.
"""

from __future__ import annotations

import numba
import numpy as np

SH_COUNT = 9
BAND_OF = np.array([0, 1, 1, 1, 2, 2, 2, 2, 2])
# Cosine-lobe convolution (Ramamoorthi & Hanrahan 2001): E(n) = sum_lm A_l c_lm Y_lm(n).
COSINE_LOBE = np.array([np.pi, 2 * np.pi / 3, np.pi / 4])[BAND_OF]


def basis(directions: np.ndarray) -> np.ndarray:
    """(..., 3) unit directions -> (..., 9) basis values."""
    d = np.asarray(directions, np.float64)
    x, y, z = d[..., 0], d[..., 1], d[..., 2]
    return np.stack([
        np.full_like(x, 0.282095),
        0.488603 * y,
        0.488603 * z,
        0.488603 * x,
        1.092548 * x * y,
        1.092548 * y * z,
        0.315392 * (3 * z * z - 1),
        1.092548 * x * z,
        0.546274 * (x * x - y * y),
    ], axis=-1)


@numba.njit(cache=True, nogil=True, inline="always")
def add_basis(x, y, z, out, scale):
    """out (9,) += scale x `basis` of the unit direction (x, y, z), for compiled loops."""
    out[0] += scale * 0.282095
    out[1] += scale * 0.488603 * y
    out[2] += scale * 0.488603 * z
    out[3] += scale * 0.488603 * x
    out[4] += scale * 1.092548 * x * y
    out[5] += scale * 1.092548 * y * z
    out[6] += scale * 0.315392 * (3 * z * z - 1)
    out[7] += scale * 1.092548 * x * z
    out[8] += scale * 0.546274 * (x * x - y * y)


# --- Quadrature on the sphere ---------------------------------------------------------------------------

_GOLDEN_RATIO = (1 + 5 ** 0.5) / 2


def sphere_directions(n: int, seed: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """n near-uniform unit directions and their equal quadrature weights 4*pi/n.

    Spherical Fibonacci lattice (Gonzalez 2010, "Measurement of areas on a sphere using Fibonacci and
    latitude-longitude lattices"): z_i = 1 - (2i+1)/n is the midpoint rule in z (bands of equal area, by
    Archimedes' hat-box theorem) and phi_i = 2*pi*i/golden_ratio spreads the points in azimuth. With a
    `seed` the whole lattice is turned by a uniformly random rotation, so estimates taken with different
    seeds do not share the lattice's orientation (its poles lie on the z axis).

    Returns directions (n, 3) float64 and weights (n,) float64 that sum to 4*pi.
    """
    if n < 1:
        raise ValueError(f"need at least one direction, got n={n}")
    i = np.arange(n, dtype=np.float64)
    z = 1.0 - (2.0 * i + 1.0) / n
    ring = np.sqrt(np.clip(1.0 - z * z, 0.0, None))
    phi = 2.0 * np.pi * ((i / _GOLDEN_RATIO) % 1.0)
    directions = np.stack([ring * np.cos(phi), ring * np.sin(phi), z], axis=-1)
    if seed is not None:
        directions = directions @ _random_rotation(np.random.default_rng(seed)).T
    return directions, np.full(n, 4.0 * np.pi / n)


def _random_rotation(rng: np.random.Generator) -> np.ndarray:
    """A Haar-uniform 3x3 rotation: the matrix of a unit quaternion drawn from a 4D isotropic Gaussian."""
    quaternion = rng.normal(size=4)
    w, x, y, z = quaternion / np.linalg.norm(quaternion)
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
    ])


# --- Projection and reconstruction ----------------------------------------------------------------------

def project(directions: np.ndarray, weights: np.ndarray, values: np.ndarray) -> np.ndarray:
    """Quadrature projection c_lm = integral L(w) Y_lm(w) dw ~= sum_i weights_i L(w_i) Y_lm(w_i).

    directions (..., n, 3) unit vectors and weights (..., n) (e.g. from `sphere_directions`; weights sum
    to 4*pi for the whole sphere); values (..., n, C) radiance sampled at those directions. Leading
    dimensions broadcast, so one shared set of directions (n, 3) projects a whole batch of probes
    (P, n, C) -> (P, 9, C). Returns (..., 9, C) float64.

    It is one matmul of the weighted basis (9, n) with the samples: no (n, 9, C) intermediate.
    """
    weights = np.asarray(weights, np.float64)
    values = np.asarray(values, np.float64)
    if values.ndim < 2:
        raise ValueError(f"values must be (..., n, C), got shape {values.shape}")
    weighted_basis = basis(directions) * weights[..., None]           # (..., n, 9)
    return np.matmul(np.swapaxes(weighted_basis, -1, -2), values)     # (..., 9, C)


def evaluate(coefficients: np.ndarray, directions: np.ndarray) -> np.ndarray:
    """Reconstructed function f(w) = sum_lm c_lm Y_lm(w) (radiance, for a probe's coefficients).

    coefficients (..., 9, C), directions (..., 3) -> (..., C). The leading dimensions broadcast by numpy's
    rules: (9, C) with (N, 3) gives (N, C); (P, 9, C) with (P, 3) gives one direction per probe, (P, C);
    (P, 9, C) with (N, 1, 3) gives every direction for every probe, (N, P, C).
    """
    coefficients = np.asarray(coefficients, np.float64)
    if coefficients.ndim < 2 or coefficients.shape[-2] != SH_COUNT:
        raise ValueError(f"coefficients must be (..., {SH_COUNT}, C), got shape {coefficients.shape}")
    return np.matmul(basis(directions)[..., None, :], coefficients)[..., 0, :]


def convolve_cosine(coefficients: np.ndarray) -> np.ndarray:
    """Coefficients of irradiance from those of radiance: c_lm -> A_l c_lm (Funk-Hecke).

    The clamped cosine max(0, n.w) is zonal, so convolving with it scales band l by
    A_l = 4*pi/(2l+1) * <max(0, cos), Y_l0>/Y_l0(z) = pi, 2pi/3, pi/4 for l = 0, 1, 2 (Ramamoorthi &
    Hanrahan 2001, "An efficient representation for irradiance environment maps", eq. 8).
    (..., 9, C) -> (..., 9, C).
    """
    return np.asarray(coefficients, np.float64) * COSINE_LOBE[:, None]


def irradiance(coefficients: np.ndarray, normals: np.ndarray) -> np.ndarray:
    """Irradiance E(n) = integral L(w) max(0, n.w) dw = sum_lm A_l c_lm Y_lm(n)
    (docs/ARCHITECTURE.md, R&H 2001).

    Exact for the band-limited radiance that the 9 coefficients describe; for a general radiance the
    truncation to L2 misses bands l > 2, whose A_l are small (|A_4| = pi/24, odd l > 1 vanish).
    Shapes as in `evaluate`: coefficients (..., 9, C), normals (..., 3) -> (..., C).
    """
    return evaluate(convolve_cosine(coefficients), normals)


def project_delta(direction: np.ndarray, value: np.ndarray) -> np.ndarray:
    """SH of a directional source that delivers irradiance `value` to a surface facing it.

    Radiance L(w) = value * delta(w, direction) (a solid-angle delta), so c_lm = value * Y_lm(direction).
    Its L2 irradiance facing the source is value * (1/4 + 1/2 + 5/16) = 1.0625 * value (addition theorem:
    sum_m Y_lm(d)^2 = (2l+1)/(4pi)), and it rings negative (down to -19/480 * value) on the far side; see
    `dering`. direction (..., 3), normalised here; value (C,) or (..., C) -> (..., 9, C).
    """
    direction = np.asarray(direction, np.float64)
    direction = direction / np.linalg.norm(direction, axis=-1, keepdims=True)
    return basis(direction)[..., :, None] * np.asarray(value, np.float64)[..., None, :]


# --- Ringing ----------------------------------------------------------------------------------------------

WINDOWS = ("poussin", "hanning", "lanczos")
# Band factors of the spherical de la Vallee Poussin kernel ((1 + cos t)/2)^2, which is >= 0 everywhere:
# h_l = L! (L+1)! / ((L-l)! (L+l+1)!) for L = 2.
_POUSSIN = np.array([1.0, 1.0 / 2.0, 1.0 / 10.0])


def window_factors(strength: float, window: str = "poussin") -> np.ndarray:
    """Per-coefficient (9,) factors h_l of a deringing window; strength 0 gives all ones (identity).

    - "poussin" (default), 0 <= strength <= 1: h_l = 1 - strength * (1 - p_l) with p = (1, 1/2, 1/10)
      the band factors of the de la Vallee Poussin kernel ((1 + cos t)/2)^2. Windowing band factors is
      convolving with a zonal kernel, and this kernel is (1 - strength) * (the truncated delta) + strength
      * (a non-negative kernel). So for any non-negative radiance the most negative reconstructed
      radiance, and likewise irradiance, is at most (1 - strength) times the unwindowed one, and none at
      strength 1 (where the irradiance kernel 1/4 + c/4 + 5/160 P2(c) is also >= 0). The price is blur:
      at strength 1 band 1 is halved.
    - "hanning": h_l = (1 + cos(pi l / w)) / 2, and "lanczos": h_l = sin(pi l / w) / (pi l / w), both 0
      for l >= w, with window width w = 3 / strength bands (strength 1: w = 3, the SH order, as
      suggested in P.-P. Sloan, "Stupid Spherical Harmonics (SH) Tricks", GDC 2008). They shrink the
      negative radiance lobe of a delta but do not bound irradiance: Hanning at w = 3 deepens the delta's
      back-side irradiance from -0.040 to -0.047 of its peak, because it damps band 2 (which lifts the
      back side) faster than band 1.
    """
    if strength < 0:
        raise ValueError(f"dering strength must be >= 0, got {strength}")
    if window == "poussin":
        if strength > 1:
            raise ValueError(f"the poussin window takes strength in [0, 1], got {strength}")
        per_band = 1.0 - strength * (1.0 - _POUSSIN)
    elif window in ("hanning", "lanczos"):
        band = np.arange(3, dtype=np.float64)
        width = 3.0 / strength if strength > 0 else np.inf
        if window == "hanning":
            per_band = (1.0 + np.cos(np.pi * band / width)) / 2.0
        else:
            per_band = np.sinc(band / width)
        per_band = np.where(band < width, per_band, 0.0)
    else:
        raise ValueError(f"unknown window {window!r}; one of {WINDOWS}")
    return per_band[BAND_OF]


def dering(coefficients: np.ndarray, strength: float = 1.0, window: str = "poussin") -> np.ndarray:
    """Coefficients multiplied band by band by `window_factors(strength, window)`: (..., 9, C) -> same.

    strength 0 returns the coefficients unchanged (as float64). The band-0 factor is always 1, so the
    mean radiance (and the irradiance averaged over all normals) is kept.
    """
    return np.asarray(coefficients, np.float64) * window_factors(strength, window)[:, None]


def min_radiance_over_sphere(coefficients: np.ndarray, n: int = 4096) -> np.ndarray:
    """Most negative reconstructed radiance over n lattice directions: (..., 9, C) -> (..., C).

    A sampled minimum, so it is an upper bound on the true one; the lattice spacing (~3.6/sqrt(n) rad)
    bounds how far above it can be.
    """
    return _min_over_sphere(np.asarray(coefficients, np.float64), n)


def min_irradiance_over_sphere(coefficients: np.ndarray, n: int = 4096) -> np.ndarray:
    """Most negative irradiance E(n) over n lattice normals, for the stability checks: (..., 9, C) ->
    (..., C). A negative value means the probe would shade some surface with negative light."""
    return _min_over_sphere(convolve_cosine(coefficients), n)


def _min_over_sphere(coefficients: np.ndarray, n: int, chunk: int = 512) -> np.ndarray:
    """Minimum of sum_lm c_lm Y_lm(w) over the lattice, in chunks of directions so that a probe grid
    (P, 9, C) never needs a (P, n, C) array."""
    directions, _ = sphere_directions(n)
    minimum = np.full(coefficients.shape[:-2] + coefficients.shape[-1:], np.inf)
    for start in range(0, n, chunk):
        block = basis(directions[start:start + chunk])                   # (k, 9)
        values = np.einsum("kj,...jc->...kc", block, coefficients)       # (..., k, C)
        minimum = np.minimum(minimum, values.min(axis=-2))
    return minimum

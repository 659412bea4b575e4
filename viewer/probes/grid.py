"""ProbeGrid: M^3 L2-SH light probes over the scene bounds, and how to read them back.

Probe (i, j, k) sits at the centre of cell (i, j, k) of an M^3 grid over [lo, hi]
(`lo + (index + 0.5) * spacing`), so a GL 3D texture over the same box samples probe centres at texel
centres and clamps at the edges. `coefficients[i, j, k]` is (9, 3): the projection of the incident
radiance L(p, w) onto the SH basis of `viewer.probes.sh`, RGB in the last axis.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from viewer.probes import sh

INVALID_WEIGHT = 0.01
"""Weight of an invalid probe against a valid one when the renderer interpolates at a surface."""


@dataclass(frozen=True)
class ProbeGrid:
    lo: np.ndarray
    """(3,) lower corner of the probe box (world units)."""
    hi: np.ndarray
    """(3,) upper corner."""
    coefficients: np.ndarray
    """(M, M, M, 9, 3) float32 incident-radiance SH, indexed [x, y, z]."""
    valid: np.ndarray
    """(M, M, M) bool: False for probes found inside solid geometry (their values are filled in from
    valid neighbours, see `fill_invalid`)."""

    def __post_init__(self):
        c = np.asarray(self.coefficients, np.float32)
        if c.ndim != 5 or c.shape[3:] != (9, 3) or not (c.shape[0] == c.shape[1] == c.shape[2]):
            raise ValueError(f"coefficients must be (M, M, M, 9, 3), got {c.shape}")
        object.__setattr__(self, "coefficients", c)
        object.__setattr__(self, "valid", np.asarray(self.valid, bool).reshape(c.shape[:3]))
        object.__setattr__(self, "lo", np.asarray(self.lo, np.float64).reshape(3))
        object.__setattr__(self, "hi", np.asarray(self.hi, np.float64).reshape(3))

    @property
    def resolution(self) -> int:
        return self.coefficients.shape[0]

    @property
    def spacing(self) -> np.ndarray:
        return (self.hi - self.lo) / self.resolution

    @staticmethod
    def positions_for(lo, hi, resolution: int) -> np.ndarray:
        """(M, M, M, 3) probe centres, indexed [x, y, z]."""
        lo, hi = np.asarray(lo, np.float64), np.asarray(hi, np.float64)
        axes = [lo[a] + (np.arange(resolution) + 0.5) * (hi[a] - lo[a]) / resolution for a in range(3)]
        return np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1)

    @property
    def positions(self) -> np.ndarray:
        return self.positions_for(self.lo, self.hi, self.resolution)

    # ---- reading ------------------------------------------------------------------------------------
    def interpolate(self, points: np.ndarray) -> np.ndarray:
        """Trilinear SH at world points (P, 3) -> (P, 9, 3), clamped at the outer probes (the same
        sampling as a CLAMP_TO_EDGE 3D texture)."""
        p = np.asarray(points, np.float64).reshape(-1, 3)
        m = self.resolution
        u = (p - self.lo) / self.spacing - 0.5
        u = np.clip(u, 0.0, m - 1)
        i0 = np.minimum(np.floor(u).astype(np.int64), max(m - 2, 0))
        f = u - i0
        i1 = np.minimum(i0 + 1, m - 1)
        out = np.zeros((len(p), 9, 3), np.float64)
        for corner in range(8):
            bx, by, bz = corner & 1, (corner >> 1) & 1, (corner >> 2) & 1
            ix = np.where(bx, i1[:, 0], i0[:, 0])
            iy = np.where(by, i1[:, 1], i0[:, 1])
            iz = np.where(bz, i1[:, 2], i0[:, 2])
            w = (np.where(bx, f[:, 0], 1 - f[:, 0]) * np.where(by, f[:, 1], 1 - f[:, 1])
                 * np.where(bz, f[:, 2], 1 - f[:, 2]))
            out += w[:, None, None] * self.coefficients[ix, iy, iz]
        return out.astype(np.float32)

    def irradiance(self, points: np.ndarray, normals: np.ndarray) -> np.ndarray:
        """Irradiance E(n) (P, 3) at points for unit normals (cosine-lobe convolution)."""
        c = self.interpolate(points)
        y = sh.basis(np.asarray(normals, np.float64).reshape(-1, 3)) * sh.COSINE_LOBE
        return np.einsum("pk,pkc->pc", y, c)

    # ---- GPU layout ---------------------------------------------------------------------------------
    def texture_data(self) -> list[np.ndarray]:
        """Seven RGBA float32 volumes (M, M, M, 4) in GL order [z, y, x]: the 27 coefficients packed as
        coefficient-major RGB triples (c0.rgb c1.r | c1.gb c2.rg | ...), each probe's premultiplied by its
        weight w (1 if valid, INVALID_WEIGHT if not), and w in the last texel's alpha. A trilinear fetch
        divided by its alpha is then the validity-weighted interpolation (shaders/probe_grid.glsl)."""
        m = self.resolution
        weight = self.probe_weights().transpose(2, 1, 0)[..., None].astype(np.float32)
        flat = self.coefficients.transpose(2, 1, 0, 3, 4).reshape(m, m, m, 27) * weight
        flat = np.concatenate([flat, weight], axis=-1)
        return [np.ascontiguousarray(flat[..., 4 * t:4 * t + 4]) for t in range(7)]

    def probe_weights(self) -> np.ndarray:
        """(M, M, M) the weight of each probe when the renderer interpolates at a surface: 1 for valid
        probes, INVALID_WEIGHT for those inside solid geometry (kept above 0 so that a point whose probes
        are all invalid still gets their filled-in values)."""
        return np.where(self.valid, 1.0, INVALID_WEIGHT)

    def surface_irradiance(self, points: np.ndarray, normals: np.ndarray, normal_offset: float = 0.5,
                           plane_falloff: float = 3.0) -> np.ndarray:
        """Irradiance (P, 3) at surface points with unit normals, as the renderer shades a surface
        (shaders/probe_grid.glsl; `irradiance` is the plain interpolation, for points in free space).

        The 8 probes around p + n * normal_offset (in probe spacings) are weighted by their trilinear
        weight x `probe_weights` x exp(plane_falloff x the probe's distance in front of the surface
        plane, in spacings), and renormalized: probes behind the surface, inside the solid it bounds,
        fade out smoothly (the back-side weight of DDGI, Majercik et al. 2019), as do invalid ones.
        """
        p = np.asarray(points, np.float64).reshape(-1, 3)
        n = np.asarray(normals, np.float64).reshape(-1, 3)
        m, spacing = self.resolution, self.spacing
        u = np.clip((p + normal_offset * spacing.min() * n - self.lo) / spacing - 0.5, 0.0, m - 1)
        base = np.minimum(np.floor(u).astype(np.int64), max(m - 2, 0))
        f = u - base
        probe_weight = self.probe_weights()
        total = np.zeros(len(p))
        coefficients = np.zeros((len(p), 9, 3))
        for corner in range(8):
            b = np.array([corner & 1, (corner >> 1) & 1, (corner >> 2) & 1])
            index = np.minimum(base + b, m - 1)
            i, j, k = index.T
            position = self.lo + (index + 0.5) * spacing
            in_front = np.einsum("pc,pc->p", position - p, n) / spacing.min()
            w = (np.prod(np.where(b, f, 1.0 - f), axis=1) * probe_weight[i, j, k]
                 * np.exp(plane_falloff * in_front))
            total += w
            coefficients += w[:, None, None] * self.coefficients[i, j, k]
        y = sh.basis(n) * sh.COSINE_LOBE
        return np.einsum("pk,pkc->pc", y, coefficients / total[:, None, None])

    def with_coefficients(self, coefficients: np.ndarray) -> "ProbeGrid":
        return replace(self, coefficients=coefficients)


def fill_invalid(coefficients: np.ndarray, valid: np.ndarray, iterations: int | None = None) -> np.ndarray:
    """Replace invalid probes by the mean of their valid 6-neighbours, growing outwards until every
    probe has a value, so that trilinear sampling near a wall never mixes in light from inside it."""
    c = np.array(coefficients, np.float64)
    known = np.array(valid, bool)
    if known.all() or not known.any():
        return c.astype(np.float32) if known.any() else np.zeros_like(c, np.float32)
    m = c.shape[0]
    for _ in range(iterations or 3 * m):
        if known.all():
            break
        total = np.zeros_like(c)
        count = np.zeros(known.shape)
        for axis in range(3):
            for shift in (1, -1):
                kn = np.roll(known, shift, axis=axis)
                cv = np.roll(c, shift, axis=axis)
                edge = [slice(None)] * 3
                edge[axis] = 0 if shift == 1 else m - 1
                kn[tuple(edge)] = False  # no wrap-around
                total += np.where(kn[..., None, None], cv, 0.0)
                count += kn
        grow = (~known) & (count > 0)
        c[grow] = total[grow] / count[grow][:, None, None]
        known = known | grow
    return c.astype(np.float32)


def fill_waves(valid: np.ndarray) -> np.ndarray:
    """(M, M, M) int32: the iteration of probes.fill_invalid in which each probe gets its value (0 for
    valid probes), -1 for every probe when none is valid (fill_invalid then returns zeros)."""
    known = np.array(valid, bool)
    waves = np.where(known, 0, -1).astype(np.int32)
    if not known.any():
        return waves
    m = known.shape[0]
    for wave in range(1, 3 * m + 1):
        if known.all():
            break
        count = np.zeros(known.shape, np.int32)
        for axis in range(3):
            for shift in (1, -1):
                neighbour = np.roll(known, shift, axis=axis)
                edge = [slice(None)] * 3
                edge[axis] = 0 if shift == 1 else m - 1
                neighbour[tuple(edge)] = False  # no wrap-around
                count += neighbour
        grow = ~known & (count > 0)
        waves[grow] = wave
        known |= grow
    return waves

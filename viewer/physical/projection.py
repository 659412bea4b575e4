"""The numpy solver's probe projection: what each probe of a ProbeGrid sees of the voxels' light.

Reflected light is gathered along a Fibonacci lattice of directions to the first voxel hit (the
marcher of viewer.rays.raymarch); light straight from emitters is integrated piece by piece with its
solid angle and visibility, and the sun is added as a delta: the split of light sampling in a path
tracer. The ProbeGrid data type itself lives in viewer.probes.grid, apart from its producers.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from viewer.physical.transport import light_visibility
from viewer.probes import sh
from viewer.probes.grid import ProbeGrid, fill_invalid
from viewer.rays.raymarch import BACKFACE, Tracer

FAR_FIELD = 6.0
"""Distance, in voxel sizes, beyond which an emitting voxel's light pieces are projected as one."""


@dataclass(frozen=True)
class ProbeSettings:
    resolution: int = 16
    """M: probes per axis over the scene bounds."""
    directions: int = 512
    """Directions gathered per probe for the light reflected by surfaces (a Fibonacci lattice)."""
    include_emitted: bool = True
    """Add the light arriving straight from emitters and the sun. The renderer shades those itself and
    asks for False (indirect light only); `sample` and the comparisons with Mitsuba use True."""
    invalid_backface_fraction: float = 0.25
    """A probe that sees the back of surfaces in more than this fraction of directions is inside solid
    geometry: marked invalid and filled from valid neighbours, so it does not leak light into rooms."""
    dering: float = 0.0
    """Deringing window strength (0 = off, see `viewer.probes.sh.dering`)."""
    seed: int = 0
    """Rotation of the direction lattice."""


def project(voxels, radiosity, sun=None, bounds=None, settings: ProbeSettings = ProbeSettings(),
            tracer=None) -> ProbeGrid:
    """Project the incident radiance at every probe onto L2 SH.

    Reflected light (smooth) is gathered by marching `settings.directions` rays per probe to the first
    voxel hit. Light straight from emitters (small and bright) is integrated voxel by voxel instead,
    with the solid angle of each emitting voxel and its visibility, and the sun is added as a delta
    (`sh.project_delta`): the same split as light sampling in a path tracer, which keeps a small lamp
    from being missed or aliased by the direction lattice.
    """
    tracer = tracer or Tracer.build(voxels)
    lo, hi = bounds if bounds is not None else (voxels.lo, voxels.hi)
    m = settings.resolution
    points = ProbeGrid.positions_for(lo, hi, m).reshape(-1, 3)
    dirs, weights = sh.sphere_directions(settings.directions, seed=settings.seed)
    reflected = np.vstack([radiosity.reflected, np.zeros((1, 3))])  # row -1: nothing hit
    coefficients = np.zeros((len(points), 9, 3))
    backface = np.zeros(len(points))
    per_chunk = max(1, (1 << 21) // len(dirs))
    for s in range(0, len(points), per_chunk):
        p = points[s:s + per_chunk]
        hits = tracer.first_hits(np.repeat(p, len(dirs), axis=0), np.tile(dirs, (len(p), 1)))
        hits = hits.reshape(len(p), len(dirs))
        backface[s:s + per_chunk] = (hits == BACKFACE).mean(axis=1)
        radiance = reflected[np.where(hits >= 0, hits, -1)]
        coefficients[s:s + per_chunk] = sh.project(dirs, weights, radiance)
    if settings.include_emitted:
        coefficients += _emitter_sh(voxels, radiosity, points, tracer)
        coefficients += _sun_sh(sun, points, tracer)
    valid = backface <= settings.invalid_backface_fraction
    grid = coefficients.reshape(m, m, m, 9, 3)
    valid = valid.reshape(m, m, m)
    grid = fill_invalid(grid, valid)
    if settings.dering > 0:
        grid = sh.dering(grid, settings.dering)
    return ProbeGrid(lo=lo, hi=hi, coefficients=grid, valid=valid)


def _emitter_sh(voxels, radiosity, points, tracer, chunk: int = 1 << 21) -> np.ndarray:
    """SH of the light arriving straight from the emitters, summed over the fine light samples: each
    piece is a patch of solid angle cos_s A_s / (r^2 + A_s / pi) (the near-field clamp of the
    transport kernel), seen unless its voxel is occluded.

    Seen from afar, the pieces of one emitting voxel all arrive from about the same direction: beyond
    FAR_FIELD voxel sizes their solid angles are summed and projected once, from the voxel's centre of
    light; only nearer probes project piece by piece (the directions differ by less than ~1/FAR_FIELD
    radians there, well below what L2 SH resolves)."""
    lights = voxels.lights
    out = np.zeros((len(points), 9, 3))
    if not lights.count:
        return out
    emitters, piece_of = np.unique(lights.voxel, return_inverse=True)
    # per emitting voxel: its pieces' radiance as a (S, U) selection per channel, and its centre of light
    select = np.zeros((lights.count, len(emitters)))
    select[np.arange(lights.count), piece_of] = 1.0
    centre = (select.T @ (lights.position * lights.area[:, None])) / (select.T @ lights.area)[:, None]
    near_distance = FAR_FIELD * voxels.voxel_size
    per = max(1, chunk // lights.count)
    for s in range(0, len(points), per):
        p = points[s:s + per]
        d = lights.position[None] - p[:, None]                       # (P, S, 3) probe -> light
        r2 = np.einsum("psc,psc->ps", d, d)
        w = d / np.sqrt(np.maximum(r2, 1e-30))[..., None]
        cos_s = -np.einsum("psc,sc->ps", w, lights.normal)
        omega = np.where(cos_s > 0, cos_s * lights.area / (r2 + lights.area / np.pi), 0.0)
        omega = omega * light_visibility(tracer, voxels, p, None, omega > 0)
        to_centre = centre[None] - p[:, None]                          # (P, U, 3)
        distance = np.linalg.norm(to_centre, axis=-1)
        far = distance > near_distance
        # far: one direction per (probe, emitting voxel), carrying the sum of its pieces
        power = np.stack([omega @ (select * lights.radiance[:, c:c + 1]) for c in range(3)], -1)  # (P, U, 3)
        basis_far = sh.basis(to_centre / np.maximum(distance, 1e-30)[..., None]) * far[..., None]
        out[s:s + per] = np.matmul(basis_far.transpose(0, 2, 1), power)
        # near: piece by piece, for the probes that have a near emitting voxel
        rows = np.nonzero((~far).any(axis=1))[0]
        if len(rows):
            near_pieces = ~far[rows][:, piece_of]                       # (R, S)
            weighted = (omega[rows] * near_pieces)[..., None] * sh.basis(w[rows])
            out[s + rows] += np.matmul(weighted.transpose(0, 2, 1), lights.radiance)
    return out


def _sun_sh(sun, points, tracer) -> np.ndarray:
    out = np.zeros((len(points), 9, 3))
    if sun is None or not np.any(sun.irradiance > 0):
        return out
    lit = tracer.escapes(points, sun.direction)
    out[lit] = sh.project_delta(sun.direction, sun.irradiance)
    return out

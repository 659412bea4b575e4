"""A final gather over the lightmap: each surface sample's indirect irradiance from the light its
surroundings reflect, read from the lightmap where the rays land, instead of interpolated between
probes.

Probes a few centimetres to decimetres apart cannot hold light that changes over less than their
spacing, and their L2 SH cannot say that part of a hemisphere is dark: a box face that looks out of
the Cornell box's open side, or down at a floor it stands on, gets the probes' blur. Lightmap bakers fix
this with a final gather. From each sample point, K cosine-weighted rays (one per cell of an r x 2r grid
of strata, the grid shifted at random per sample so that no fixed pattern errs alike over a whole face)
are cast against the scene's triangles once per geometry (`GatherRays.of`, through Embree where it is
installed: viewer/rays/cast.py); each remembers the
lightmap pixel it lands on, front or back side, or that it left the scene. Every GI update then sums

    E(p) = (1 / K) sum_k  albedo(x_k) (E_direct(x_k) + E_indirect(x_k))

the irradiance integral with cosine-weighted rays (each carries pi / K of it; a diffuse surface
reflects radiance albedo E / pi). E_direct is the baked direct lightmap (lamps and sun with their
shadows), E_indirect the probes' light at x_k: the probes carry the second bounce on, where their blur
is multiplied by the albedo and spread over the hemisphere. Emission is not gathered: the direct
lightmap holds the lamps' light. A ray that leaves the scene brings nothing (the scenes have no sky).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numba
import numpy as np

from viewer.gpu.gather_cast import (CHUNK, ESCAPED, cast_rays, direct_args, direction,  # noqa: F401 (ESCAPED)
                                   land_grid)
from viewer.rays.cast import TriangleCaster
from viewer.rays.embree import spread
from viewer.physical.geometry import tangent_frames

RAYS = 72
"""Gather rays per sample (RenderSettings.final_gather's default): 2 r^2, a grid of r x 2r strata in (u1, u2)."""
SCOUTS = 8
"""Rays of each sample cast first, spread over its strata: a sample all of whose scouts meet the backs of
faces is taken to lie inside a closed solid (the back side of a scanned mesh's surface, where nothing
is lit), and its other rays are not cast: they repeat the scouts' hits. On a closed mesh that is the
back half of its samples, so the gather casts about half the rays; a sample with a share b of its
hemisphere on backs is taken for enclosed with chance b^8 (4% at two thirds)."""


@dataclass(frozen=True)
class GatherRays:
    """The lightmap pixel (of the front | back image, row-major) that each of K rays of S samples lands
    on, ESCAPED for none."""

    hits: np.ndarray
    """(S, K) int32."""
    coarse: np.ndarray | None = None
    """(S,) bool or None: the samples that cast half their rays (`of`)."""

    @staticmethod
    def of(points: np.ndarray, normals: np.ndarray, caster: TriangleCaster, face_tile: np.ndarray,
           tile_origin: np.ndarray, tile_n: np.ndarray, width: int, lift: float, rays: int = RAYS,
           seed: int = 0, coarse: np.ndarray | None = None) -> "GatherRays":
        """points, normals (S, 3): the samples; caster: the scene's triangles (its faces are the scene's
        faces); face_tile (F,): each scene face's lightmap tile, -1 for none; tile_origin
        (tiles, 2) and tile_n (tiles,): the atlas layout (viewer.gpu.direct_bake.lightmap_layout),
        `width` texels a side; lift: how far off the surface the rays start. `coarse` (S,) bool: samples
        that cast only the strata of even number (and the scouts), each odd one repeating the hit of the
        stratum beside it in the same row (`paired_rays`): half the rays, for samples whose light the
        tent averages over many records anyway (a scanned mesh's)."""
        frame = _Frame.of(points, normals, rays, seed)
        hits = np.empty((frame.count, rays), np.int32)
        layout = (caster, face_tile, tile_origin, tile_n, width)
        coarse = None if coarse is None or not np.any(coarse) else np.asarray(coarse, np.bool_)
        _cast_samples(frame, lift, np.arange(frame.count), rays, layout, hits, coarse)
        return GatherRays(hits, coarse)

    def after_moving(self, sample_moved: np.ndarray, landed_moved: np.ndarray, landed_points: np.ndarray,
                     moved: np.ndarray, slack: float, points: np.ndarray, normals: np.ndarray, caster: TriangleCaster,
                     face_tile: np.ndarray, tile_origin: np.ndarray, tile_n: np.ndarray, width: int, lift: float,
                     seed: int = 0) -> "GatherRays":
        """The rays of the same samples after some faces moved (a lamp dragged: the same faces, the same
        lightmap layout), without tracing them all again. `points`, `normals`, `caster` and the layout are
        as for `of`, of the scene after the move; sample_moved (S,): the samples on moved faces;
        landed_moved (L,): which of the pixels these rays land on (`landing`'s, in its order) are of moved
        tiles; landed_points (L, 3): each one's world point before the move (within a texel of where a
        ray that landed on it met its face; read for the landed pixels alone, where an array over the
        whole atlas took a 68k-triangle scan's lamp move 90 ms to fill); moved
        (M, 3, 3): the moved faces' corners now. A ray is traced again if its sample moved, if it landed on
        a moved face, or if it meets a moved face where it is now less than `slack` beyond where it
        landed. The others cannot have changed: nothing moved into their way, and what they met is where
        it was. So the hits are those of `of` on the moved scene (tests/gpu/test_final_gather.py)."""
        rays = self.hits.shape[1]
        frame = _Frame.of(points, normals, rays, seed)
        corners = np.ascontiguousarray(moved, np.float64).reshape(-1, 3, 3)
        edges = (corners[:, 0], corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])   # v0, e1, e2
        todo = _affected(*frame.args(0.0), self.landing[1], np.ascontiguousarray(sample_moved, np.bool_),
                         np.ascontiguousarray(landed_moved, np.bool_), np.ascontiguousarray(landed_points, np.float64),
                         *edges, float(slack), _bounding_sphere(*edges))
        hits = self.hits.copy()
        layout = (caster, face_tile, tile_origin, tile_n, width)
        # a sample taken for enclosed is gathered again whole, scouts first, as `of` gathers it
        scouts = scout_rays(rays)
        enclosed = _all_backs(self.hits[:, scouts], int(width))
        again = np.flatnonzero(enclosed & todo.any(axis=1))
        todo[enclosed] = False
        coarse, repeated = self.coarse, paired_rays(rays)[1]
        if coarse is not None:   # a coarse sample's repeated rays take their partners' hits again below
            todo[np.ix_(np.flatnonzero(coarse), repeated)] = False
        rows = np.argwhere(todo).astype(np.int64)
        hits[todo] = ESCAPED
        _cast(frame, lift, rows, *layout, hits)
        _cast_samples(frame, lift, again, rays, layout, hits, coarse)
        closed = _all_backs(hits[:, scouts], int(width)) & ~enclosed   # enclosed by the move
        if coarse is not None:
            _repeat_pairs(hits, np.flatnonzero(coarse & ~closed & ~enclosed), rays)
        _repeat_scouts(hits, np.flatnonzero(closed), scouts)
        return GatherRays(hits, coarse)

    def inside(self, width: int) -> np.ndarray:
        """(S,) bool: the samples most of whose rays meet the backs of faces (inside a solid); `width`:
        lightmap texels a side (the back sides' pixels are the columns from `width` to 2 `width`)."""
        return _inside(self.hits, int(width))

    def irradiance(self, reflected: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
        """(S, 3) float32: each sample's irradiance from what the pixels the rays land on reflect,
        `reflected` (L, 3) float32 = albedo x (direct + indirect irradiance) at `landing`'s pixels (one
        array: the rays land anywhere, and each further array read costs a cache miss)."""
        if out is None:
            out = np.empty((len(self.hits), 3), np.float32)
        _sum(reflected, self.landing[1], self.landed, out)
        return out

    @cached_property
    def landing(self) -> tuple[np.ndarray, np.ndarray]:
        """(pixels (L,), hits (S, K) int32): the distinct pixels the rays land on, in image order, and each
        ray's row among them (ESCAPED for none). An update computes what those pixels reflect and nothing
        else: on the Cornell box 169k of the 562k covered pixels (both sides) that it computed before, and
        the sum's reads stay within 2 MB instead of 9 MB."""
        return _landing(self.hits)

    @cached_property
    def landed(self) -> np.ndarray:
        """The samples with a ray that landed (38% of the Cornell box's see nothing: the walls' backs)."""
        return np.flatnonzero((self.hits >= 0).any(axis=1))


@dataclass(frozen=True)
class _Frame:
    """The samples' ray frames: the same rays for the same samples and seed, whichever are traced."""

    points: np.ndarray
    normals: np.ndarray
    tangents: np.ndarray
    bitangents: np.ndarray
    rows: int
    shift: np.ndarray

    @property
    def count(self) -> int:
        return len(self.points)

    @staticmethod
    def of(points, normals, rays: int, seed: int) -> "_Frame":
        n = np.ascontiguousarray(normals, np.float64).reshape(-1, 3)
        t, b = tangent_frames(n)
        rows = int(round(np.sqrt(rays / 2.0)))
        if rows < 1 or 2 * rows * rows != rays:
            raise ValueError(f"gather rays must be 2 r^2 (a full grid of strata: 8, 32, 72, 128, ...), not {rays}")
        # one random shift of the strata per sample (Cranley-Patterson): unbiased over samples, where a
        # fixed pattern errs alike on a whole face (a face looking at a bright floor at grazing angles)
        shift = np.random.default_rng(seed).random((len(n), 2))
        return _Frame(np.ascontiguousarray(points, np.float64).reshape(-1, 3), n, np.ascontiguousarray(t),
                      np.ascontiguousarray(b), rows, shift)

    def args(self, lift: float) -> tuple:
        return self.points, self.normals, self.tangents, self.bitangents, self.rows, 2 * self.rows, self.shift, \
            float(lift)


def _cast(frame: "_Frame", lift: float, todo: np.ndarray, caster: TriangleCaster, face_tile, tile_origin, tile_n,
          width: int, hits: np.ndarray) -> None:
    """Cast the rays todo (N, 2) = (sample, ray) of `frame` and write the pixel each lands on into hits."""
    todo = np.ascontiguousarray(todo, np.int64)
    out = np.empty(len(todo), np.int32)
    cast_rays(frame.args(lift), todo, caster, face_tile, tile_origin, tile_n, width, out)
    hits[todo[:, 0], todo[:, 1]] = out


def scout_rays(rays: int) -> np.ndarray:
    """The SCOUTS rays cast first (indices into a sample's rays): spread evenly over the strata's rows
    (angle from the normal) and columns (azimuth)."""
    return np.unique(np.linspace(0, rays - 1, min(SCOUTS, rays)).round().astype(np.int64))


def paired_rays(rays: int) -> tuple[np.ndarray, np.ndarray]:
    """(cast, repeated): the rays a coarse sample casts, the even strata and the scouts, and those it
    repeats, each the odd stratum after an even one in the same row (a row has 2r strata) that is not
    a scout. The scouts are spread over the strata (`scout_rays`), so a repeated ray's partner is cast."""
    scouts = scout_rays(rays)
    index = np.arange(rays)
    repeated = index[(index % 2 == 1) & ~np.isin(index, scouts)]
    return np.setdiff1d(index, repeated), repeated


def _repeat_pairs(hits: np.ndarray, samples: np.ndarray, rays: int) -> None:
    """Every repeated ray of `samples` (`paired_rays`) takes its partner's hit."""
    repeated = paired_rays(rays)[1]
    hits[samples[:, None], repeated] = hits[samples[:, None], repeated - 1]


def _cast_samples(frame: "_Frame", lift: float, samples: np.ndarray, rays: int, layout: tuple,
                  hits: np.ndarray, coarse: np.ndarray | None = None) -> None:
    """Gather `samples` whole into hits: none for those that look out of the scene (`nothing_ahead`: the
    backs of a room's walls, a third of the Cornell box's samples), their scouts for the others, then the
    other rays of those not enclosed (the enclosed ones repeat their scouts' hits), of the `coarse` ones
    half (`paired_rays`)."""
    outward = layout[0].nothing_ahead(frame.points[samples], frame.normals[samples], 0.5 * lift)
    hits[samples[outward]] = ESCAPED
    samples = samples[~outward]
    scouts = scout_rays(rays)
    direct = direct_args(*layout)

    def cast(which: np.ndarray, these: np.ndarray) -> None:
        which = which[spread(len(which))]   # the threads' shares alike
        if direct is not None:   # the rays made, traced and landed in one compiled loop, on every core
            return land_grid(*frame.args(lift), np.ascontiguousarray(which, np.int64),
                             np.ascontiguousarray(these, np.int64), *direct, hits)
        for todo in _rays_of(which, these):
            _cast(frame, lift, todo, *layout, hits)

    cast(samples, scouts)
    enclosed = _all_backs(hits[samples[:, None], scouts], int(layout[-1]))
    open_ = samples[~enclosed]
    few = np.zeros(len(open_), bool) if coarse is None else coarse[open_]
    cast(open_[~few], np.setdiff1d(np.arange(rays), scouts))
    if few.any():
        cast(open_[few], np.setdiff1d(paired_rays(rays)[0], scouts))
        _repeat_pairs(hits, open_[few], rays)
    _repeat_scouts(hits, samples[enclosed], scouts)


def _repeat_scouts(hits: np.ndarray, samples: np.ndarray, scouts: np.ndarray) -> None:
    """Every ray of `samples` takes a scout's hit, the scouts in turn: what an enclosed sample keeps."""
    hits[samples] = hits[samples[:, None], scouts[np.arange(hits.shape[1]) % len(scouts)]]


def _rays_of(samples: np.ndarray, rays: np.ndarray):
    """(sample, ray) of the given rays of the given samples, about CHUNK at a time."""
    per = max(CHUNK // max(len(rays), 1), 1)
    for first in range(0, len(samples), per):
        s = samples[first:first + per]
        yield np.column_stack([np.repeat(s, len(rays)), np.tile(rays, len(s))])


def _all_backs(hits: np.ndarray, width: int) -> np.ndarray:
    """(S,) bool: every one of the hits (S, k) landed on the back side of a face (the back image's
    pixels are the columns from `width` to 2 `width` of each row)."""
    return np.all((hits >= 0) & (hits % (2 * width) >= width), axis=1)


@numba.njit(cache=True, nogil=True, parallel=True)
def _affected(points, normals, tangents, bitangents, rows, columns, shift, lift, hits, sample_moved, pixel_moved,
              pixel_points, v0, e1, e2, slack, sphere):
    """(S, K) bool: the rays that a move of the triangles (v0, e1, e2) (their places now) may change.

    The triangles lie in `sphere` (centre x, y, z, radius: `_bounding_sphere`): a ray whose line passes
    outside it cannot meet them, and a sample far from it skips whole rows of strata whose angle from
    the normal is too far from the sphere's (the sphere is widened past the edges' tolerance, so the rays
    skipped are only ones the exact test below would not mark)."""
    count, rays = hits.shape
    todo = np.zeros((count, rays), np.bool_)
    tolerance = 1e-4
    cx, cy, cz, radius = sphere
    for s in numba.prange(count):
        if sample_moved[s]:
            todo[s, :] = True
            continue
        ox, oy, oz = cx - points[s, 0], cy - points[s, 1], cz - points[s, 2]   # to the sphere's centre
        distance = np.sqrt(ox * ox + oy * oy + oz * oz)
        far_away = distance > radius + slack   # no ray can meet it behind its origin (t > -slack)
        polar = half = 0.0
        row_misses = False
        if far_away:
            cosine = (ox * normals[s, 0] + oy * normals[s, 1] + oz * normals[s, 2]) / distance
            polar = np.arccos(min(max(cosine, -1.0), 1.0))
            half = np.arcsin(min(radius / distance, 1.0))
        for k in range(rays):
            if far_away and k % columns == 0:   # a new row of strata: its angle from the normal, asin(sqrt(u1))
                u1 = (k // columns + shift[s, 0]) / rows
                row_misses = abs(np.arcsin(min(np.sqrt(u1), 1.0)) - polar) > half + 1e-9
            p = hits[s, k]
            if p >= 0 and pixel_moved[p]:
                todo[s, k] = True
                continue
            if far_away and row_misses:
                continue
            dx, dy, dz = direction(s, k, normals, tangents, bitangents, rows, columns, shift)
            along = ox * dx + oy * dy + oz * dz
            if distance * distance - along * along > radius * radius:
                continue   # the ray's line passes outside the sphere
            far = np.inf
            if p >= 0:
                far = np.sqrt((pixel_points[p, 0] - points[s, 0]) ** 2 + (pixel_points[p, 1] - points[s, 1]) ** 2
                              + (pixel_points[p, 2] - points[s, 2]) ** 2) + slack
            for f in range(v0.shape[0]):   # Moller-Trumbore, both sides, the edges widened a little
                px = dy * e2[f, 2] - dz * e2[f, 1]
                py = dz * e2[f, 0] - dx * e2[f, 2]
                pz = dx * e2[f, 1] - dy * e2[f, 0]
                det = e1[f, 0] * px + e1[f, 1] * py + e1[f, 2] * pz
                if det == 0.0:
                    continue
                inv = 1.0 / det
                tx, ty, tz = points[s, 0] - v0[f, 0], points[s, 1] - v0[f, 1], points[s, 2] - v0[f, 2]
                u = (tx * px + ty * py + tz * pz) * inv
                if u < -tolerance or u > 1.0 + tolerance:
                    continue
                qx = ty * e1[f, 2] - tz * e1[f, 1]
                qy = tz * e1[f, 0] - tx * e1[f, 2]
                qz = tx * e1[f, 1] - ty * e1[f, 0]
                v = (dx * qx + dy * qy + dz * qz) * inv
                if v < -tolerance or u + v > 1.0 + tolerance:
                    continue
                t = (e2[f, 0] * qx + e2[f, 1] * qy + e2[f, 2] * qz) * inv
                if -slack < t < far:
                    todo[s, k] = True
                    break
    return todo


def _bounding_sphere(v0: np.ndarray, e1: np.ndarray, e2: np.ndarray) -> tuple[float, float, float, float]:
    """(centre x, y, z, radius) of a sphere around the triangles (v0, e1, e2) and a margin past their
    edges: the box's centre, the farthest corner, plus 1% (the test's edge tolerance is 1e-4 of an edge).
    A radius of -1 for no triangles: every ray misses."""
    if len(v0) == 0:
        return 0.0, 0.0, 0.0, -1.0
    points = np.concatenate([v0, v0 + e1, v0 + e2])
    centre = 0.5 * (points.min(axis=0) + points.max(axis=0))
    radius = float(np.linalg.norm(points - centre, axis=1).max())
    return float(centre[0]), float(centre[1]), float(centre[2]), 1.01 * radius + 1e-12


@numba.njit(cache=True, nogil=True, parallel=True)
def _inside(hits, width):
    count, rays = hits.shape
    out = np.zeros(count, np.bool_)
    for s in numba.prange(count):
        back = 0
        for k in range(rays):
            p = hits[s, k]
            if p >= 0 and p % (2 * width) >= width:
                back += 1
        out[s] = back > 0.5 * rays
    return out


@numba.njit(cache=True, nogil=True, parallel=True)
def _sum(reflected, hits, cast, out):
    rays = hits.shape[1]
    out[:] = 0.0
    for i in numba.prange(cast.shape[0]):
        s = cast[i]
        r = g = b = np.float32(0.0)
        for k in range(rays):
            p = hits[s, k]
            if p >= 0:
                r += reflected[p, 0]
                g += reflected[p, 1]
                b += reflected[p, 2]
        out[s, 0], out[s, 1], out[s, 2] = r / rays, g / rays, b / rays


@numba.njit(cache=True, nogil=True, parallel=True)
def _landing(hits):
    count, rays = hits.shape
    size = hits.max() + 1 if hits.size else 0   # ESCAPED is -1: never below 0
    row = np.full(size, -1, np.int32)
    for s in numba.prange(count):
        for k in range(rays):
            if hits[s, k] >= 0:
                row[hits[s, k]] = 0
    pixels = np.empty(size, np.int64)
    used = 0
    for p in range(size):
        if row[p] == 0:
            row[p], pixels[used] = used, p
            used += 1
    compact = np.empty_like(hits)
    for s in numba.prange(count):
        for k in range(rays):
            p = hits[s, k]
            compact[s, k] = row[p] if p >= 0 else p
    return pixels[:used].copy(), compact

"""The lightmap's samples: which texels the probes' light and the final gather are evaluated at, how
every texel interpolates them, and the tent that filters the final gather's samples on their plane.

Apart from the bake's life cycle (viewer/gpu/indirect_bake.py) and from the passes of each update
(viewer/gpu/lightmap_update.py): the layout of the samples over the atlas (viewer/gpu/direct_bake.py).
"""

from __future__ import annotations

import numba
import numpy as np

from viewer.gpu.direct_bake import BakedDirectLight
from viewer.rays.cast import distinct_rows

SAMPLE_STRIDE = 2   # the texels at odd local coordinates: strided_samples is written for 2
"""The probes' light is evaluated at every SAMPLE_STRIDE-th texel of a tile along each axis (4 cm at the
default 2 cm texels, half a probe spacing of the Cornell box) and interpolated between: the
weights' visibility rays and each update cost a quarter (a ninth on the many small tiles of a detailed
mesh, which get one sample each)."""
FILTER_RADIUS = 1.5
"""The final gather's samples are averaged with those on their plane within this many sample spacings
(a tent): its noise falls about 4x, and light that changes over less than 6 cm is still resolved."""
FILTER_MAX = 16
"""The most samples averaged (the nearest; coincident samples repeat along the edges of a face's tiles)."""


def strided_samples(lightmap: BakedDirectLight, rows: np.ndarray, columns: np.ndarray):
    """For the covered texels (rows, columns) of the atlas, in that order: whether each is a sample (the
    texels at odd local coordinates of its tile; a tile whose triangle spans at most 2 texels has its
    centre texel (1, 1) alone), and the samples it interpolates, bilinearly within its tile: (T, 4)
    pixels of the (front | back) image's front half and (T, 4) weights (a sample: itself, weight 1)."""
    count = len(rows)
    sample, sources, weights = np.empty(count, np.bool_), np.empty((count, 4), np.int32), np.empty((count, 4), np.float32)
    _strided(np.ascontiguousarray(lightmap.texel_faces, np.int64), np.ascontiguousarray(lightmap.tile_origin, np.int64),
             np.ascontiguousarray(lightmap.tile_n, np.int64), np.asarray(rows, np.int64), np.asarray(columns, np.int64),
             lightmap.covered.shape[1], sample, sources, weights)
    return sample, sources, weights


@numba.njit(cache=True, nogil=True, inline="always")
def _between(local, tiny, last):
    """The samples on either side of a local coordinate along one axis, and the weight of the first."""
    if tiny:
        return 1, 1, 1.0
    if local % 2 == 1:
        return local, local, 1.0
    low, high = min(max(local - 1, 1), last), min(max(local + 1, 1), last)
    return low, high, 1.0 if low == high else 0.5


@numba.njit(cache=True, nogil=True, parallel=True)
def _strided(face, origin, tile_n, rows, columns, width, sample, sources, weights):
    """`strided_samples` texel by texel, on every core (35 ms of a new Cornell box's first frame as numpy,
    before the final gather can start)."""
    for t in numba.prange(face.shape[0]):
        f = face[t]
        x0, y0, span = origin[f, 0], origin[f, 1], tile_n[f] + 1   # span: the largest local coordinate
        last = span if span % 2 == 1 else span - 1                  # the last odd one
        tiny = tile_n[f] <= SAMPLE_STRIDE
        local_x, local_y = columns[t] - x0, rows[t] - y0
        lx, hx, wx = _between(local_x, tiny, last)
        ly, hy, wy = _between(local_y, tiny, last)
        sources[t, 0] = (y0 + ly) * 2 * width + x0 + lx
        sources[t, 1] = (y0 + ly) * 2 * width + x0 + hx
        sources[t, 2] = (y0 + hy) * 2 * width + x0 + lx
        sources[t, 3] = (y0 + hy) * 2 * width + x0 + hx
        weights[t, 0], weights[t, 1] = wx * wy, (1 - wx) * wy
        weights[t, 2], weights[t, 3] = wx * (1 - wy), (1 - wx) * (1 - wy)
        sample[t] = lx == local_x and hx == local_x and ly == local_y and hy == local_y


def texel_rows(sources: np.ndarray, weights: np.ndarray, pixels: np.ndarray, row_of: np.ndarray,
               width: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(rows (2T, 4) int32, weights (2T, 4) float32, pixels (2T,) int32): the samples' rows that each
    covered texel interpolates, their weights and the texel's pixel, front sides then back; `sources`
    and `weights` (T, 4): `strided_samples`' front pixels and weights; `pixels` (T,): the texels' front
    pixels; `row_of` (pixels,): each sample's pixel's row. In one parallel pass: the scan's 1.8 M texels
    took 66-78 ms on the render thread in numpy's copies, most of it first touches of their memory."""
    count, k = sources.shape
    rows, both, texels = np.empty((2 * count, k), np.int32), np.empty((2 * count, k), np.float32), \
        np.empty(2 * count, np.int32)
    _texel_rows(np.ascontiguousarray(sources), np.ascontiguousarray(weights, np.float32),
                np.ascontiguousarray(pixels), row_of, width, rows, both, texels)
    return rows, both, texels


@numba.njit(cache=True, nogil=True, parallel=True)
def _texel_rows(sources, weights, pixels, row_of, width, rows, both, texels):
    count = sources.shape[0]
    for t in numba.prange(count):
        texels[t], texels[count + t] = pixels[t], pixels[t] + width
        for k in range(sources.shape[1]):
            rows[t, k] = row_of[sources[t, k]]
            rows[count + t, k] = row_of[sources[t, k] + width]
            both[t, k] = both[count + t, k] = weights[t, k]


def dark_fill(lightmap: BakedDirectLight, samples: np.ndarray, pixels: np.ndarray,
              dark: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(pixels, sources): the samples that see no probe (`dark` (S,): a face's strip under the floor, the
    ceiling above a lamp) next to a lit sample of their tile, and that sample's pixel. samples (S / 2,):
    the sampled texels; pixels (S,): each sample's pixel in the (front | back) image."""
    height, width = lightmap.covered.shape
    tile = np.full(height * 2 * width, -1, np.int64)
    faces = lightmap.texel_faces[samples]
    tile[pixels] = np.concatenate([2 * faces, 2 * faces + 1])
    lit = np.zeros(height * 2 * width, bool)
    lit[pixels[~dark]] = True
    found, sources = [], []
    for step in (SAMPLE_STRIDE, -SAMPLE_STRIDE, 2 * width * SAMPLE_STRIDE, -2 * width * SAMPLE_STRIDE):
        candidate = pixels[dark] + step
        inside = (candidate >= 0) & (candidate < len(tile))
        candidate = np.where(inside, candidate, 0)
        ok = inside & lit[candidate] & (tile[candidate] == tile[pixels[dark]])
        found.append(pixels[dark][ok])
        sources.append(candidate[ok])
    found, sources = np.concatenate(found), np.concatenate(sources)
    first = np.unique(found, return_index=True)[1]
    return found[first], sources[first]


SMALL_RADIUS = 2.0
"""The tent's radius, in sample spacings, for the samples of tiles that hold one sample (triangles
narrower than two texels: a scanned mesh's): it reaches past the diagonal of their record's cell."""
SMALL_FACING = 0.95
"""Such a sample averages the records whose normals are within 18 degrees of its own (Ward's irradiance
caching bounds its records' reach alike): a curved surface has no plane to keep to."""
RECORD_CELL = 1.0
"""The cells that such samples keep one record of, in sample spacings along each axis ..."""
RECORD_NORMAL = 2.0
"""... and per direction of the normal, its components rounded to 1 / RECORD_NORMAL. Measured on the
68k-triangle scan against Mitsuba (the bunny's 140 x 155 pixels): 33.5 dB with every sample its own
record, 33.3-33.5 dB with records of half or whole spacings, normals rounded to halves or quarters; the
gather's rays 13.3 M -> 7.1 M. Rounded to halves rather than quarters, the scan's records are 40k a side
instead of 45.6k (the bunny's 12k become 6.5k) and a new scan settles 12% sooner (2.07 s against 2.35 s,
two alternate runs of `python -m viewer.bench.edits cornell --other scans/bunny-room-68k.obj --edits
"new scene" --repeats 6`), its image against Mitsuba's 1024 samples a pixel 38.90 dB against 38.91 dB
(the pixels that differ: 36.96 against 36.98 dB)."""


def small_tiles(lightmap: BakedDirectLight, samples: np.ndarray) -> np.ndarray:
    """(S,) bool: the samples of tiles that hold one sample (triangles narrower than two texels). Their
    records cast half the gather's rays (`GatherRays.of`'s `coarse`): each of their samples averages the
    records within SMALL_RADIUS, several, where a sample of a larger tile reads about one. On the
    68k-triangle scan their rays start among the scan's own triangles and cost four times a wall's
    (5.5 against 21.6 M rays a second on 2 cores): halved, the scan's gather takes 400 ms instead of
    470 ms."""
    return lightmap.tile_n[lightmap.texel_faces[samples]] <= SAMPLE_STRIDE


def weight_rows(small: np.ndarray, records: tuple[np.ndarray, np.ndarray] | None) -> tuple[np.ndarray, np.ndarray]:
    """(weighed, rows): the samples of both sides whose probe weights are computed, and for each sample of
    both sides the row of `weighed` whose weights it takes. A sample of a one-sample tile (`small` (S,))
    takes its record's (`gather_records`: the first sample of its cell of a sample spacing and normal),
    the others their own. The weights' visibility rays from a scan's surface are its costliest (the 68k
    triangle scan's weights took 91 ms on 2 cores, now 33 ms); the probes' light at a sample feeds only
    the light the gather's rays bring back from it, and the image against Mitsuba is the same (38.93
    against 38.89 dB). Without records (no final gather) every sample has its own."""
    count = len(small)
    share = np.arange(count)
    if records is not None and np.any(small):
        chosen, own = records
        share = np.where(small, np.asarray(chosen)[own], share)
    used = np.zeros(count, bool)
    used[share] = True
    half = np.flatnonzero(used)
    rows = (np.cumsum(used) - 1)[share]
    return np.concatenate([half, count + half]), np.concatenate([rows, len(half) + rows])


def gather_records(lightmap: BakedDirectLight, samples: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(records (R,), own (S,)): the samples that the final gather casts rays from (indices into
    `samples`), and the record each sample reads first (an index into `records`).

    A tile that holds more than one sample (a triangle wider than two texels) has as records the samples
    whose points lie in its triangle. The others, half of the tile beyond the triangle's long side, are
    pulled onto its edges, where the records on both sides of the edge lie within the tent's reach: they
    read those (`tent_neighbours`) instead of casting rays of their own from points that repeat along the
    edge (half the rays of a scene of large triangles: the Cornell box's 10.1 M become 4.9 M); their own
    record is their tile's first sample, for a tent that finds nothing.
    The tiles that hold one (a scanned mesh's triangles, millimetres wide beside 2 cm texels)
    keep one record per cell of a sample spacing and direction of the normal (RECORD_CELL,
    RECORD_NORMAL), and each of their samples reads the records near it: the gather's rays then follow the
    surface's area instead of its triangle count (on a 68k-triangle scan, 136k such samples a side make
    a few thousand records)."""
    face = lightmap.texel_faces[samples]
    small = small_tiles(lightmap, samples)
    own = np.arange(len(samples))
    if small.any():
        small = np.flatnonzero(small)
        cell = RECORD_CELL * SAMPLE_STRIDE * lightmap.texel
        keys = np.column_stack([np.floor(lightmap.texel_points[samples[small]] / cell),
                                np.round(RECORD_NORMAL * lightmap.texel_normals[samples[small]])]).astype(np.int64)
        first, cell = distinct_rows(keys)
        own[small] = small[first][cell]
    edge = borrowing(lightmap, samples)
    if edge.any():   # their tile's texel (1, 1), the first sample, always in its triangle
        texel = np.cumsum(lightmap.covered.ravel()) - 1
        origin = lightmap.tile_origin[face[edge]]
        first = texel[(origin[:, 1] + 1) * lightmap.covered.shape[1] + origin[:, 0] + 1]
        sample = np.full(len(lightmap.texel_faces), -1, np.int64)
        sample[samples] = np.arange(len(samples))
        own[edge] = sample[first]
    records, own = np.unique(own, return_inverse=True)
    return records, own.ravel()


def borrowing(lightmap: BakedDirectLight, samples: np.ndarray) -> np.ndarray:
    """(S,) bool: the samples of tiles with several whose points were pulled onto their triangle's edges
    (`gather_records`)."""
    return (lightmap.tile_n[lightmap.texel_faces[samples]] > SAMPLE_STRIDE) & ~lightmap.texel_inside[samples]


def sample_points(lightmap: BakedDirectLight, samples: np.ndarray, before: tuple | None = None) -> tuple[tuple, np.ndarray]:
    """((points (2S, 3), normals (N, 3), normal_id (2S,)), rounded): the samples of both sides, the distinct
    normals (the back sides' negated) and each sample's, and every face's normal of both sides rounded.
    `before`: this function's answer for the same samples before a move, whose distinct normals stay where
    no face turned (finding them is a sort: 34 ms of a 68k-triangle scan)."""
    faces = lightmap.texel_faces
    face_normal = np.zeros((int(faces.max()) + 1 if len(faces) else 0, 3))
    face_normal[faces] = lightmap.texel_normals
    rounded = np.round(np.concatenate([face_normal, -face_normal]), 6)
    if before is not None and np.array_equal(before[1], rounded):
        normals, normal_id = before[0][1:]
    else:
        first, ids = distinct_rows(rounded)   # a sort of numbers, not of rows: 0.3 s of a 68k-triangle scan
        faces = faces[samples]
        normals, normal_id = rounded[first], np.concatenate([ids[faces], ids[len(face_normal) + faces]])
    return (np.concatenate([lightmap.texel_points[samples]] * 2), normals, normal_id), rounded

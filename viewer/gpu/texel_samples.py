"""The lightmap's samples: which texels the probes' light and the final gather are evaluated at, how
every texel interpolates them, and the tent that filters the final gather's samples on their plane.

Apart from the bake's life cycle (viewer/gpu/indirect_bake.py): the layout of the samples over the atlas
(viewer/gpu/direct_bake.py) and the compiled loops that spread their light onto the texels.
"""

from __future__ import annotations

import numba
import numpy as np
from scipy.spatial import cKDTree

from viewer.gpu.direct_bake import BakedDirectLight
from viewer.gpu.final_gather import GatherRays
from viewer.rays.cast import distinct_rows
from viewer.scene.textures import relative_at

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
    sample, sources, weights = np.empty(count, np.bool_), np.empty((count, 4), np.int64), np.empty((count, 4), np.float32)
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


@numba.njit(cache=True, nogil=True, parallel=True)
def gather_texels(values, rows, weights, pixels, image):
    """image[pixels[i]] = sum_k weights[i, k] values[rows[i, k]]: each texel shows its samples' light."""
    for i in numba.prange(pixels.shape[0]):
        r, g, b = _texel(values, rows, weights, i)
        p = pixels[i]
        image[p, 0], image[p, 1], image[p, 2] = r, g, b


@numba.njit(cache=True, nogil=True, parallel=True)
def gather_reflected(values, rows, weights, pixels, albedo, reflected, out):
    """out[pixels[i]] = albedo x (sum_k weights[i, k] values[rows[i, k]]) + reflected there: what each
    texel reflects, its samples' light taken as `gather_texels` takes it, in one pass."""
    for i in numba.prange(pixels.shape[0]):
        r, g, b = _texel(values, rows, weights, i)
        p = pixels[i]
        out[p, 0] = albedo[p, 0] * r + reflected[p, 0]
        out[p, 1] = albedo[p, 1] * g + reflected[p, 1]
        out[p, 2] = albedo[p, 2] * b + reflected[p, 2]


@numba.njit(cache=True, nogil=True, inline="always")
def _texel(values, rows, weights, i):
    r = g = b = np.float32(0.0)
    for k in range(rows.shape[1]):
        w = weights[i, k]
        if w != 0.0:
            q = rows[i, k]
            r += w * values[q, 0]
            g += w * values[q, 1]
            b += w * values[q, 2]
    return r, g, b


SMALL_RADIUS = 2.0
"""The tent's radius, in sample spacings, for the samples of tiles that hold one sample (triangles
narrower than two texels: a scanned mesh's): it reaches past the diagonal of their record's cell."""
SMALL_FACING = 0.95
"""Such a sample averages the records whose normals are within 18 degrees of its own (Ward's irradiance
caching bounds its records' reach alike): a curved surface has no plane to keep to."""
RECORD_CELL = 1.0
"""The cells that such samples keep one record of, in sample spacings along each axis ..."""
RECORD_NORMAL = 4.0
"""... and per direction of the normal, its components rounded to 1 / RECORD_NORMAL. Measured on the
68k-triangle scan against Mitsuba (the bunny's 140 x 155 pixels): 33.5 dB with every sample its own
record, 33.3-33.5 dB with records of half or whole spacings, normals rounded to halves or quarters; the
gather's rays 13.3 M -> 7.1 M."""


def gather_records(lightmap: BakedDirectLight, samples: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(records (R,), own (S,)): the samples that the final gather casts rays from (indices into
    `samples`), and the record each sample reads first (an index into `records`).

    A tile that holds more than one sample (a triangle wider than two texels) has all of its samples as
    records. The tiles that hold one (a scanned mesh's triangles, millimetres wide beside 2 cm texels)
    keep one record per cell of a sample spacing and direction of the normal (RECORD_CELL,
    RECORD_NORMAL), and each of their samples reads the records near it: the gather's rays then follow the
    surface's area instead of its triangle count (on a 68k-triangle scan, 136k such samples a side make
    a few thousand records)."""
    face = lightmap.texel_faces[samples]
    small = np.flatnonzero(lightmap.tile_n[face] <= SAMPLE_STRIDE)
    own = np.arange(len(samples))
    if len(small):
        cell = RECORD_CELL * SAMPLE_STRIDE * lightmap.texel
        keys = np.column_stack([np.floor(lightmap.texel_points[samples[small]] / cell),
                                np.round(RECORD_NORMAL * lightmap.texel_normals[samples[small]])]).astype(np.int64)
        first, cell = distinct_rows(keys)
        own[small] = small[first][cell]
    records, own = np.unique(own, return_inverse=True)
    return records, own.ravel()


@numba.njit(cache=True, nogil=True, parallel=True)
def reflectance(pixels, faces, face_albedo, ratio, direct, albedo, reflected):
    """albedo[pixels[i]] = face_albedo[faces[i]] (times ratio[i], the texture where a scene has one, at most
    0.999) and reflected = albedo x direct there: what each covered pixel of the (front | back) image
    reflects, once per colour edit or bake, in one pass (4 ms for the Cornell box's 1.2 M pixels on one
    core, where numpy's fancy indexing took 30 ms)."""
    textured = ratio.shape[0] > 0
    for i in numba.prange(pixels.shape[0]):
        p, f = pixels[i], faces[i]
        for c in range(3):
            a = face_albedo[f, c]
            if textured:
                a = min(a * ratio[i, c], np.float32(0.999))
            albedo[p, c] = a
            reflected[p, c] = a * direct[p, c]


@numba.njit(cache=True, nogil=True)
def record_tent(points, normals, record_points, record_normals, distance, near, reach, small):
    """(S, K) float32 tent weights 1 - distance / reach of the records `near` (S, K) that a sample may
    average: those on its plane (normals within 0.999, off it by under 5% of the reach), or for a `small`
    sample those whose normals are within SMALL_FACING and that lie within half the reach of its plane;
    0 for the others, and `near` set to 0 where the query found none (numbered len(record_points))."""
    count = record_points.shape[0]
    tent = np.zeros(near.shape, np.float32)
    for s in range(points.shape[0]):   # once a geometry, a few operations a neighbour: one thread
        facing_min, off_max = (SMALL_FACING, 0.5 * reach[s]) if small[s] else (0.999, 0.05 * reach[s])
        for k in range(near.shape[1]):
            j = near[s, k]
            if j >= count:
                near[s, k] = 0
                continue
            facing = (record_normals[j, 0] * normals[s, 0] + record_normals[j, 1] * normals[s, 1]
                      + record_normals[j, 2] * normals[s, 2])
            off = ((record_points[j, 0] - points[s, 0]) * normals[s, 0]
                   + (record_points[j, 1] - points[s, 1]) * normals[s, 1]
                   + (record_points[j, 2] - points[s, 2]) * normals[s, 2])
            if facing > facing_min and abs(off) < off_max and distance[s, k] < reach[s]:
                tent[s, k] = 1.0 - distance[s, k] / reach[s]
    return tent


def tent_neighbours(lightmap: BakedDirectLight, samples: np.ndarray, records: np.ndarray, own: np.ndarray,
                    rays: GatherRays) -> tuple[np.ndarray, np.ndarray]:
    """(2S, K) the records (`gather_records`) each sample of both sides averages, rows of the gather's
    (2R) samples, 0 with weight 0 past the last, and their tent weights 1 - distance / reach, normalized.
    A sample of a tile with several reads the records within FILTER_RADIUS sample spacings on its plane
    and side (coplanar, the same normal: across the edges of a face's triangles too); one of a tile with
    one reads those within SMALL_RADIUS whose normals are near its own. Records inside a solid (most of
    their rays meet the backs of faces: the floor under a box) are nobody's neighbours but their own
    samples', so that their darkness does not spread onto the visible floor beside."""
    points = lightmap.texel_points[samples].astype(np.float64)     # the front sides'; the back
    normals = lightmap.texel_normals[samples].astype(np.float64)   # sides' are the same again
    small = lightmap.tile_n[lightmap.texel_faces[samples]] <= SAMPLE_STRIDE
    spacing = SAMPLE_STRIDE * lightmap.texel
    reach = np.where(small, SMALL_RADIUS, FILTER_RADIUS) * spacing
    distance, near = cKDTree(points[records]).query(points, FILTER_MAX, distance_upper_bound=float(reach.max()),
                                                    workers=-1)
    tent = record_tent(points, normals, points[records], normals[records], distance, near, reach, small)
    count = len(records)
    near, tent = np.concatenate([near, near + count]), np.concatenate([tent, tent])
    own = np.concatenate([own, own + count])
    mine = near == own[:, None]
    tent[rays.inside(lightmap.covered.shape[1])[near] & ~mine] = 0.0
    alone = tent.sum(axis=1) == 0.0      # (among more coincident samples than FILTER_MAX, or none near)
    near[alone, 0], tent[alone, 0] = own[alone], 1.0
    return near, tent / tent.sum(axis=1, keepdims=True)


def texture_ratio(scene, lightmap: BakedDirectLight, faces: np.ndarray) -> np.ndarray | None:
    """(pixels, 3) float32 texture(uv) / its mean at the point of each covered pixel of the (front | back)
    image (1 on plain faces), whose faces among the non-degenerate ones are `faces`: what a pixel's albedo
    is its face's times. None for a scene without textures."""
    if not scene.textured:
        return None
    kept = np.flatnonzero(scene.face_areas > 0)
    points = np.concatenate([lightmap.texel_points] * 2)
    return relative_at(scene, kept[faces], points).astype(np.float32)

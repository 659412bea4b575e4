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
    face = lightmap.texel_faces
    x0, y0 = lightmap.tile_origin[face, 0], lightmap.tile_origin[face, 1]
    span = lightmap.tile_n[face] + 1                       # the largest local coordinate
    last = np.where(span % 2 == 1, span, span - 1)         # the last odd one
    tiny = lightmap.tile_n[face] <= SAMPLE_STRIDE
    local_x, local_y = columns - x0, rows - y0

    def between(local):
        """The samples on either side along one axis, and the weight of the first."""
        odd = local % 2 == 1
        low = np.where(tiny, 1, np.where(odd, local, np.clip(local - 1, 1, last)))
        high = np.where(tiny, 1, np.where(odd, local, np.clip(local + 1, 1, last)))
        return low, high, np.where(low == high, 1.0, 0.5)

    lx, hx, wx = between(local_x)
    ly, hy, wy = between(local_y)
    width = lightmap.covered.shape[1]
    pixel = lambda sx, sy: (y0 + sy) * 2 * width + x0 + sx                      # noqa: E731
    sources = np.stack([pixel(lx, ly), pixel(hx, ly), pixel(lx, hy), pixel(hx, hy)], axis=1)
    weights = np.stack([wx * wy, (1 - wx) * wy, wx * (1 - wy), (1 - wx) * (1 - wy)], axis=1)
    sample = (lx == local_x) & (hx == local_x) & (ly == local_y) & (hy == local_y)
    return sample, sources, weights.astype(np.float32)


@numba.njit(cache=True, nogil=True, parallel=True)
def gather_texels(values, rows, weights, pixels, image):
    """image[pixels[i]] = sum_k weights[i, k] values[rows[i, k]]: each texel shows its samples' light."""
    for i in numba.prange(pixels.shape[0]):
        p = pixels[i]
        r = g = b = np.float32(0.0)
        for k in range(rows.shape[1]):
            w = weights[i, k]
            if w != 0.0:
                q = rows[i, k]
                r += w * values[q, 0]
                g += w * values[q, 1]
                b += w * values[q, 2]
        image[p, 0], image[p, 1], image[p, 2] = r, g, b


@numba.njit(cache=True, nogil=True)
def coplanar_tent(points, normals, distance, near, radius):
    """(S, K) float32 tent weights 1 - distance / radius of the neighbours `near` (S, K) that share a
    sample's plane (normals within 0.999, off its plane by under 5% of the radius), 0 for the others;
    `near` is set to 0 where the query found none (numbered len(points))."""
    count = points.shape[0]
    tent = np.zeros(near.shape, np.float32)
    for s in range(count):   # once a geometry, a few operations a neighbour: one thread
        for k in range(near.shape[1]):
            j = near[s, k]
            if j >= count:
                near[s, k] = 0
                continue
            facing = normals[j, 0] * normals[s, 0] + normals[j, 1] * normals[s, 1] + normals[j, 2] * normals[s, 2]
            off = ((points[j, 0] - points[s, 0]) * normals[s, 0] + (points[j, 1] - points[s, 1]) * normals[s, 1]
                   + (points[j, 2] - points[s, 2]) * normals[s, 2])
            if facing > 0.999 and abs(off) < 0.05 * radius:
                tent[s, k] = 1.0 - distance[s, k] / radius
    return tent


def tent_neighbours(lightmap: BakedDirectLight, samples: np.ndarray,
                    rays: GatherRays) -> tuple[np.ndarray, np.ndarray]:
    """(S, K) the `samples` within FILTER_RADIUS sample spacings of each sample on its plane and side
    (coplanar, the same normal: across the edges of a face's triangles too), 0 with weight 0 past
    the last, and their tent weights 1 - distance / radius, normalized. Samples inside a solid (most
    of their rays meet the backs of faces: the floor under a box) are nobody's neighbours, so that
    their darkness does not spread onto the visible floor beside."""
    points = lightmap.texel_points[samples].astype(np.float64)     # the front sides'; the back
    normals = lightmap.texel_normals[samples].astype(np.float64)   # sides' are the same again
    radius = FILTER_RADIUS * SAMPLE_STRIDE * lightmap.texel
    distance, near = cKDTree(points).query(points, FILTER_MAX, distance_upper_bound=radius, workers=-1)
    tent = coplanar_tent(points, normals, distance, near, radius)   # and the missing (len(points)) -> 0
    near, tent = np.concatenate([near, near + len(points)]), np.concatenate([tent, tent])
    own = near == np.arange(len(near))[:, None]
    tent[rays.inside(lightmap.covered.shape[1])[near] & ~own] = 0.0
    tent[tent.sum(axis=1) == 0.0, 0] = 1.0        # (a sample among more coincident ones than FILTER_MAX)
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

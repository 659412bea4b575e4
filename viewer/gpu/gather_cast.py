"""The final gather's rays themselves (viewer/gpu/final_gather.py): each ray's origin and direction from
its sample's frame and stratum, and the lightmap pixel it lands on, cast here or in a worker process
(viewer/gpu/gather_workers.py), which imports this and not the gather."""

from __future__ import annotations

import numba
import numpy as np

ESCAPED = -1
"""GatherRays.hits of a ray that leaves the scene (or lands on a face without a tile)."""

CHUNK = 1 << 18
"""Rays cast at a time: their origins and directions take 12 MB, where all of a detailed mesh's take a gigabyte."""


@numba.njit(cache=True, nogil=True, inline="always")
def direction(s, k, normals, tangents, bitangents, rows, columns, shift):
    """Ray k of sample s: stratum (k // columns, k % columns) of (u1, u2), shifted by the sample's shift,
    cosine-weighted (r = sqrt(u1), phi = 2 pi u2)."""
    u1 = (k // columns + shift[s, 0]) / rows
    u2 = (k % columns + shift[s, 1]) / columns
    r, phi = np.sqrt(u1), 2.0 * np.pi * u2
    lx, ly, lz = r * np.cos(phi), r * np.sin(phi), np.sqrt(max(1.0 - u1, 0.0))
    dx = lx * tangents[s, 0] + ly * bitangents[s, 0] + lz * normals[s, 0]
    dy = lx * tangents[s, 1] + ly * bitangents[s, 1] + lz * normals[s, 1]
    dz = lx * tangents[s, 2] + ly * bitangents[s, 2] + lz * normals[s, 2]
    return dx, dy, dz


@numba.njit(cache=True, nogil=True, parallel=True)
def rays_of(points, normals, tangents, bitangents, rows, columns, shift, lift, todo):
    """The origins (lifted off the surface) and directions of the rays todo (N, 2) = (sample, ray)."""
    origins = np.empty((todo.shape[0], 3))
    directions = np.empty((todo.shape[0], 3))
    for i in numba.prange(todo.shape[0]):
        s, k = todo[i, 0], todo[i, 1]
        for a in range(3):
            origins[i, a] = points[s, a] + lift * normals[s, a]
        directions[i, 0], directions[i, 1], directions[i, 2] = direction(s, k, normals, tangents, bitangents, rows,
                                                                          columns, shift)
    return origins, directions


@numba.njit(cache=True, nogil=True)
def pixels_of(face, u, v, front, face_tile, tile_origin, tile_n, width):
    """The lightmap pixel of each hit (face, barycentrics u, v, side), ESCAPED for none or a face without
    a tile: the front image's for a front hit, the back image's (`width` further along the row) else.
    One thread: a few nanoseconds a ray beside Embree's microsecond, and a parallel loop would add
    seconds to a first run's compile."""
    out = np.empty(face.shape[0], np.int32)
    for r in range(face.shape[0]):
        f = face[r]
        if f < 0 or face_tile[f] < 0:
            out[r] = ESCAPED
            continue
        tile = face_tile[f]
        m = tile_n[tile]
        # texel k of a tile holds the point at (k - 0.5) / m: the nearest to u is floor(u m + 1)
        ku = min(max(int(np.floor(u[r] * m + 1.0)), 0), m + 1)
        kv = min(max(int(np.floor(v[r] * m + 1.0)), 0), m + 1)
        side = 0 if front[r] else width
        out[r] = (tile_origin[tile, 1] + kv) * 2 * width + tile_origin[tile, 0] + ku + side
    return out


def cast_rays(frame_args: tuple, todo: np.ndarray, caster, face_tile, tile_origin, tile_n,
              width: int, out: np.ndarray) -> None:
    """out[i]: the pixel that ray todo[i] = (sample, ray) of the frame (`_Frame.args`) lands on, CHUNK
    rays at a time (here, or in a worker process: viewer/gpu/gather_workers.py)."""
    face_tile = np.ascontiguousarray(face_tile, np.int64)
    tile_origin, tile_n = np.ascontiguousarray(tile_origin, np.int64), np.ascontiguousarray(tile_n, np.int64)
    for start in range(0, len(todo), CHUNK):
        part = np.ascontiguousarray(todo[start:start + CHUNK], np.int64)
        origins, directions = rays_of(*frame_args, part)
        found = caster.closest_hits(origins, directions)
        out[start:start + len(part)] = pixels_of(found.face, found.u, found.v, found.front, face_tile, tile_origin,
                                                  tile_n, int(width))

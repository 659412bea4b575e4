"""The final gather's rays themselves (viewer/gpu/final_gather.py): each ray's origin and direction from
its sample's frame and stratum, and the lightmap pixel it lands on: with Embree, made, traced and landed
in compiled loops on every core, without Python's lock; and the caster they are traced with."""

from __future__ import annotations

from concurrent.futures import Future

import numba
import numpy as np

from viewer.rays import dda, embree
from viewer.rays.cast import TriangleCaster, embree_available
from viewer.rays.sides import first_face
from viewer.rays.voxels import grid_frame
from viewer.scene import Scene

ESCAPED = -1
"""GatherRays.hits of a ray that leaves the scene (or lands on a face without a tile)."""

VISIBILITY_VOXELS = 32
"""Cells per axis of the triangle grid that the probes' visibility is traced in."""

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


@numba.njit(cache=True, nogil=True, inline="always")
def pixel_of(f, u, v, front, face_tile, tile_origin, tile_n, width):
    """The lightmap pixel of a hit (face f, barycentrics u, v, side), ESCAPED for none or a face without a
    tile: the front image's for a front hit, the back image's (`width` further along the row) else."""
    if f < 0 or face_tile[f] < 0:
        return ESCAPED
    tile = face_tile[f]
    m = tile_n[tile]
    # texel k of a tile holds the point at (k - 0.5) / m: the nearest to u is floor(u m + 1)
    ku = min(max(int(np.floor(u * m + 1.0)), 0), m + 1)
    kv = min(max(int(np.floor(v * m + 1.0)), 0), m + 1)
    side = 0 if front else width
    return (tile_origin[tile, 1] + kv) * 2 * width + tile_origin[tile, 0] + ku + side


@numba.njit(cache=True, nogil=True)
def pixels_of(face, u, v, front, face_tile, tile_origin, tile_n, width):
    """`pixel_of` each hit. One thread: a few nanoseconds a ray beside Embree's microsecond, and a parallel
    loop would add seconds to a first run's compile."""
    out = np.empty(face.shape[0], np.int32)
    for r in range(face.shape[0]):
        out[r] = pixel_of(face[r], u[r], v[r], front[r], face_tile, tile_origin, tile_n, width)
    return out


@numba.njit(cache=True, nogil=True, inline="always")
def land(s, k, points, normals, tangents, bitangents, rows, columns, shift, lift, intersect, scene, record, faces,
         e1, e2, twin, v0, face_tile, tile_origin, tile_n, width):
    """The pixel that ray k of sample s lands on, traced through Embree as it is made (viewer.rays.embree)."""
    dx, dy, dz = direction(s, k, normals, tangents, bitangents, rows, columns, shift)
    f, _, u, v, front = first_face(intersect, scene, record, faces, e1, e2, twin, v0,
                                   points[s, 0] + lift * normals[s, 0], points[s, 1] + lift * normals[s, 1],
                                   points[s, 2] + lift * normals[s, 2], dx, dy, dz, np.inf)
    return pixel_of(f, u, v, front, face_tile, tile_origin, tile_n, width)


@numba.njit(cache=True, nogil=True, parallel=True)
def land_grid(points, normals, tangents, bitangents, rows, columns, shift, lift, samples, rays, intersect, scene, faces,
              e1, e2, twin, v0, face_tile, tile_origin, tile_n, width, hits):
    """hits[s, k] for every ray k of `rays` of every sample s of `samples`, on all cores."""
    for i in numba.prange(samples.shape[0]):
        record = embree.record()
        s = samples[i]
        for k in rays:
            hits[s, k] = land(s, k, points, normals, tangents, bitangents, rows, columns, shift, lift, intersect, scene,
                              record, faces, e1, e2, twin, v0, face_tile, tile_origin, tile_n, width)


@numba.njit(cache=True, nogil=True, parallel=True)
def land_listed(points, normals, tangents, bitangents, rows, columns, shift, lift, todo, intersect, scene, faces,
                e1, e2, twin, v0, face_tile, tile_origin, tile_n, width, out):
    """out[i]: the pixel ray todo[i] = (sample, ray) lands on, on all cores."""
    count = todo.shape[0]
    for block in numba.prange((count + embree.BLOCK - 1) // embree.BLOCK):
        record = embree.record()
        for i in range(block * embree.BLOCK, min(count, (block + 1) * embree.BLOCK)):
            out[i] = land(todo[i, 0], todo[i, 1], points, normals, tangents, bitangents, rows, columns, shift, lift,
                          intersect, scene, record, faces, e1, e2, twin, v0, face_tile, tile_origin, tile_n, width)


def direct_args(caster, face_tile, tile_origin, tile_n, width: int) -> tuple | None:
    """The arguments after the rays of `land_grid` and `land_listed` for a caster that calls Embree from
    compiled loops (None for another: the DDA, embreex's binding)."""
    if caster.direct is None:
        return None
    return (*caster.direct.handle, caster.faces, caster.e1, caster.e2, caster.twin, caster.v0,
            np.ascontiguousarray(face_tile, np.int64), np.ascontiguousarray(tile_origin, np.int64),
            np.ascontiguousarray(tile_n, np.int64), int(width))


def cast_rays(frame_args: tuple, todo: np.ndarray, caster, face_tile, tile_origin, tile_n,
              width: int, out: np.ndarray) -> None:
    """out[i]: the pixel that ray todo[i] = (sample, ray) of the frame (`_Frame.args`) lands on, CHUNK
    rays at a time."""
    direct = direct_args(caster, face_tile, tile_origin, tile_n, width)
    if direct is not None:   # made and traced in one compiled loop
        land_listed(*frame_args, np.ascontiguousarray(todo, np.int64), *direct, out)
        return
    face_tile = np.ascontiguousarray(face_tile, np.int64)
    tile_origin, tile_n = np.ascontiguousarray(tile_origin, np.int64), np.ascontiguousarray(tile_n, np.int64)
    for start in range(0, len(todo), CHUNK):
        part = np.ascontiguousarray(todo[start:start + CHUNK], np.int64)
        origins, directions = rays_of(*frame_args, part)
        found = caster.closest_hits(origins, directions)
        out[start:start + len(part)] = pixels_of(found.face, found.u, found.v, found.front, face_tile, tile_origin,
                                                  tile_n, int(width))


def caster_of(scene: Scene, early: tuple[Scene, Future] | None = None,
              previous: TriangleCaster | None = None) -> TriangleCaster:
    """The rays' caster of a geometry, for the gather and the weights: Embree where it is installed (no
    cells to list: 20-125 ms of a new Cornell box), else the DDA over a VISIBILITY_VOXELS grid of cells;
    `early`'s, (scene, future), where it was started for this scene. `previous`: the caster of the same
    faces before some moved (a dragged lamp), whose hierarchy of the others Embree keeps."""
    if early is not None and early[0] is scene:
        return early[1].result()
    if embree_available():
        return TriangleCaster(scene, previous=previous)
    return TriangleCaster(scene, dda.Cells.blocking(scene, *grid_frame(scene, VISIBILITY_VOXELS), VISIBILITY_VOXELS))

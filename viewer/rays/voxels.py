"""Scene -> VoxelGrid: an N^3 grid over the scene, with only the occupied voxels stored.

Each stored voxel carries the paper's attributes (eq. 2: position, albedo, emission; eq. 4: hash id
`x + y*N + z*N*N`, see docs/ARCHITECTURE.md for the typo in the paper) plus the normal and the surface
area it covers. A cell that holds surfaces facing different ways (a room corner, both sides of a thin wall)
stores one voxel per facing: the six signed axes bin the surface normals. A single averaged normal
would cancel out on a thin wall and point nowhere useful in a corner, and light transport needs a
meaningful facing per patch; the paper's per-cell view is `cells()`.

Voxelization splits every triangle until its edges are shorter than a quarter voxel and bins the pieces
by centroid, so areas are exact up to the pieces cut by cell faces (compiled: viewer.rays.pieces).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numba
import numpy as np

from viewer.scene import Scene
from viewer.threads import cores_for
from viewer.rays.moved_faces import changed_rows
from viewer.rays.pieces import PIECE_EDGE, face_pairs, piece_centroids, piece_levels
from viewer.scene.textures import relative_at, textured_faces

if TYPE_CHECKING:  # scipy is imported when a voxelization needs it
    from scipy import sparse

MAX_LIGHT_SAMPLES = 2048
SURFACE_OFFSET = 0.1
"""Rays from a voxel's surface (to the lamps, the sun, other voxels) start this many voxels off it along
its normal, in front of its own surface; further off, the outer face of a room's wall would start
outside the scene. The physical solver and the neural encoding both use it."""
FACINGS = np.array([[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]], np.float64)


@dataclass(frozen=True)
class VoxelGrid:
    lo: np.ndarray
    """(3,) lower corner of the grid (a cube around the scene, padded by half a voxel each side)."""
    voxel_size: float
    """Edge length h of one cubic voxel."""
    resolution: int
    """N: voxels per axis."""
    coords: np.ndarray
    """(K, 3) int64 integer voxel coordinates (x, y, z); sorted by hash id."""
    position: np.ndarray
    """(K, 3) area-weighted centroid of the surface inside the voxel (world units)."""
    normal: np.ndarray
    """(K, 3) unit surface normal (front side)."""
    area: np.ndarray
    """(K,) surface area covered."""
    albedo: np.ndarray
    """(K, 3) area-weighted mean albedo."""
    emission: np.ndarray
    """(K, 3) area-weighted mean emitted radiance (front side)."""
    lights: "LightSamples"
    """The emitting surface in pieces finer than the voxels, for direct light (see LightSamples)."""

    def __post_init__(self):
        for name in ("coords", "position", "normal", "area", "albedo", "emission"):
            getattr(self, name).setflags(write=False)

    @property
    def count(self) -> int:
        return len(self.area)

    @property
    def hash_id(self) -> np.ndarray:
        """Eq. 4: x + y*N + z*N*N."""
        n = self.resolution
        c = self.coords
        return c[:, 0] + c[:, 1] * n + c[:, 2] * n * n

    @property
    def hi(self) -> np.ndarray:
        return self.lo + self.voxel_size * self.resolution

    @property
    def centers(self) -> np.ndarray:
        """(K, 3) centres of the voxels' cells (the paper's voxel position)."""
        return self.lo + (self.coords + 0.5) * self.voxel_size

    @property
    def occupancy(self) -> np.ndarray:
        """(N, N, N) bool, indexed [x, y, z]."""
        occ = np.zeros((self.resolution,) * 3, bool)
        occ[tuple(self.coords.T)] = True
        return occ

    def cell_of(self, points: np.ndarray) -> np.ndarray:
        """Integer cell coordinates of world points (may be outside 0..N-1)."""
        return np.floor((np.asarray(points) - self.lo) / self.voxel_size).astype(np.int64)

    def cells(self) -> dict[str, np.ndarray]:
        """The paper's one-voxel-per-cell view: hash id, cell centre, area-weighted albedo and emission,
        total area, for every occupied cell."""
        ids, inverse = np.unique(self.hash_id, return_inverse=True)
        area = np.bincount(inverse, self.area)
        w = self.area[:, None]
        albedo = np.stack([np.bincount(inverse, (self.albedo * w)[:, c]) for c in range(3)], 1) / area[:, None]
        emission = np.stack([np.bincount(inverse, (self.emission * w)[:, c]) for c in range(3)], 1) / area[:, None]
        n = self.resolution
        coords = np.stack([ids % n, (ids // n) % n, ids // (n * n)], axis=1)
        return {"hash_id": ids, "center": self.lo + (coords + 0.5) * self.voxel_size, "area": area,
                "albedo": albedo, "emission": emission}


@dataclass(frozen=True)
class LightSamples:
    """Emitting triangles cut into pieces of at most half a voxel: the quadrature for direct light.

    A lamp is small and bright; seen from a point a few centimetres away, one point-to-patch term per
    voxel misjudges its solid angle badly, while the pieces keep it within a few percent. Visibility is
    still traced once per emitting voxel (`voxel`), shared by its pieces.
    """

    position: np.ndarray
    """(S, 3) piece centroids."""
    normal: np.ndarray
    """(S, 3) front normals."""
    area: np.ndarray
    """(S,) piece areas."""
    radiance: np.ndarray
    """(S, 3) emitted radiance."""
    voxel: np.ndarray
    """(S,) index of the voxel that holds the piece."""
    face: np.ndarray | None = None
    """(S,) the scene face each piece was cut from (its radiance follows that face's emission)."""

    @property
    def count(self) -> int:
        return len(self.area)


def grid_frame(scene: Scene, resolution: int) -> tuple[np.ndarray, float]:
    """(lo, h): a cube around the scene bounds with half a voxel of padding on every side, so that
    walls on the bounds lie inside the outer layer of voxels."""
    lo, hi = scene.bounds
    extent = float(np.max(hi - lo))
    if extent <= 0:
        extent = 1.0
    size = extent * resolution / max(resolution - 1, 1)
    centre = 0.5 * (lo + hi)
    return centre - 0.5 * size, size / resolution


def subdivide(tri: np.ndarray, max_edge: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Split triangles until every edge is <= max_edge: (centroids (P, 3), area (P,), source index (P,)),
    the same pieces as viewer.rays.pieces bins."""
    edges = np.stack([tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 1], tri[:, 0] - tri[:, 2]], axis=1)
    area = 0.5 * np.linalg.norm(np.cross(edges[:, 0], -edges[:, 2]), axis=1)
    level = piece_levels(tri, max_edge)
    centroids, areas, sources = [], [], []
    for k in np.unique(level):
        group = np.nonzero(level == k)[0]
        bary = piece_centroids(int(k))
        corners = tri[group][:, None]   # each centroid as the compiled binning computes it, to the last bit
        centroids.append((bary[:, :1] * corners[:, :, 0] + bary[:, 1:2] * corners[:, :, 1]
                          + bary[:, 2:] * corners[:, :, 2]).reshape(-1, 3))
        areas.append(np.repeat(area[group] / len(bary), len(bary)))
        sources.append(np.repeat(group, len(bary)))
    return np.concatenate(centroids), np.concatenate(areas), np.concatenate(sources)


def _sorted_unique(codes: np.ndarray, bound: int) -> tuple[np.ndarray, np.ndarray]:
    """np.unique(codes, return_inverse=True) for integer codes in [0, bound): by counting instead of
    sorting when the table is small (10x faster for the pieces of a 16^3 or 32^3 voxelization)."""
    if bound > 1 << 23:
        return np.unique(codes, return_inverse=True)
    keys = np.flatnonzero(np.bincount(codes, minlength=bound))
    index = np.zeros(bound, np.int64)
    index[keys] = np.arange(len(keys))
    return keys, index[codes]


def voxelize(scene: Scene, resolution: int = 32, normal_mode: str = "area") -> VoxelGrid:
    """Voxelize a scene into an N^3 grid.

    normal_mode: "area" (area-weighted mean of the surface normals in the voxel) or "paper" (eq. 3:
    the plain mean of the normals of the triangles that touch the voxel, normalized).
    """
    return _voxelize(scene, resolution, normal_mode)[0]


@dataclass(frozen=True)
class Voxelization:
    """A VoxelGrid with what it was made from: for colour edits without voxelizing again
    (viewer.physical.relight) and for tracing rays against the scene's own triangles (viewer.rays.dda)."""

    grid: VoxelGrid
    faces: "sparse.csr_matrix"
    """(K, F) share of each voxel's area that each scene face covers: voxel albedo = faces @ face albedo."""
    keys: np.ndarray
    """(K,) sorted voxel keys: flat cell index * 6 + facing (the index of FACINGS)."""
    tint: tuple | None = None
    """Textured faces: per RGB channel a (K, F) matrix of each voxel's share of each face times the face's
    texture over its mean there, less 1 (see `voxel_albedo`); None for a scene without textures."""


def voxel_albedo(faces: "sparse.csr_matrix", tint: tuple | None, scene: Scene) -> np.ndarray:
    """(K, 3) voxel albedo from per-face albedo: the faces' area shares, plus on textured faces what their
    texture adds where each voxel lies (a recoloured group scales its texture with its colour, so the
    shares stay true; a group whose texture was dropped counts as plain)."""
    albedo = faces @ scene.albedo
    if tint is not None and scene.textured:
        textured = scene.albedo * textured_faces(scene)[:, None]
        albedo = np.minimum(albedo + np.stack([tint[c] @ textured[:, c] for c in range(3)], axis=1), 0.999)
    return albedo


EDITED_SHARE = 0.25
"""`VoxelAlbedo` sums again only the voxels of the faces whose albedo changed while they are at most this
share of the faces; past it, all of them."""


class VoxelAlbedo:
    """`voxel_albedo` of one voxelization, kept across albedo edits: an edit that recolours a few faces (a
    wall of a room whose scan is a million triangles) sums again only the voxels those faces reach, each
    from all its faces as the whole product sums it, so the answer is the same to the bit (the largest
    wall of a million-triangle scan's room: the whole product took 9 ms)."""

    def __init__(self, faces: "sparse.csr_matrix", tint: tuple | None, scene: Scene, albedo: np.ndarray):
        """`albedo`: `voxel_albedo(faces, tint, scene)`, already made."""
        self.faces, self.tint = faces, tint
        self._columns = None   # the shares by face (CSC), made at the first edit of a few faces
        self._last = (scene.albedo, albedo)

    def of(self, scene: Scene) -> np.ndarray:
        """(K, 3) `voxel_albedo` for `scene` (the voxelized one, its colours edited): the last answer's array
        itself while the albedo stays the same."""
        before, albedo = self._last
        if scene.albedo is before:
            return albedo
        changed = np.flatnonzero(changed_rows((before, scene.albedo))) if before.shape == scene.albedo.shape else None
        if changed is not None and len(changed) == 0:
            self._last = (scene.albedo, albedo)
            return albedo
        if changed is None or len(changed) > EDITED_SHARE * len(before) or (self.tint is not None and scene.textured):
            albedo = voxel_albedo(self.faces, self.tint, scene)
        else:
            if self._columns is None:
                self._columns = self.faces.tocsc()
            start = self._columns.indptr[changed]
            length = self._columns.indptr[changed + 1] - start
            within = np.arange(length.sum()) - np.repeat(np.cumsum(length) - length, length)
            rows = np.unique(self._columns.indices[np.repeat(start, length) + within])   # the voxels they reach
            albedo = albedo.copy()
            albedo[rows] = self.faces[rows] @ scene.albedo
        self._last = (scene.albedo, albedo)
        return albedo


def voxelize_with_faces(scene: Scene, resolution: int = 32, normal_mode: str = "area") -> Voxelization:
    """`voxelize`, keeping the pieces and the face shares (see Voxelization)."""
    from scipy import sparse

    grid, inverse, piece_face, piece_area, keys, piece_tint = _voxelize(scene, resolution, normal_mode)
    share = piece_area / np.maximum(grid.area[inverse], 1e-300)
    shape = (grid.count, len(scene.faces))
    faces = sparse.csr_matrix((share, (inverse, piece_face)), shape=shape)
    tint = None if piece_tint is None else tuple(
        sparse.csr_matrix((share * (piece_tint[:, c] - 1.0), (inverse, piece_face)), shape=shape) for c in range(3))
    return Voxelization(grid, faces, keys, tint)


def face_facing(normals: np.ndarray, rows: np.ndarray | None = None) -> np.ndarray:
    """(F,) index into FACINGS of the signed axis closest to each normal (the voxel a face's pieces join):
    the largest of its dot products with FACINGS, the first of equals, found from |n| in one compiled
    pass (numpy's argmax along rows of three took 6.7 ms on a 272k-face scan, and a moved scan asks
    several times; a matrix product waits for BLAS's threads after the compiled loops' parallel work).
    `rows`: of those normals alone, read in place."""
    normals = np.ascontiguousarray(normals, np.float64).reshape(-1, 3)
    rows = np.arange(len(normals)) if rows is None else np.asarray(rows, np.int64)
    out = np.empty(len(rows), np.int64)
    with cores_for(len(rows)):
        _facing(normals, rows, out)
    return out


@numba.njit(cache=True, nogil=True, parallel=True)
def _facing(normals, rows, out):
    for i in numba.prange(len(rows)):
        f = rows[i]
        x, y, z = normals[f, 0], normals[f, 1], normals[f, 2]
        ax, ay, az = abs(x), abs(y), abs(z)
        if ax >= ay and ax >= az:
            out[i] = 1 if x < 0 else 0
        elif ay >= az:
            out[i] = 3 if y < 0 else 2
        else:
            out[i] = 5 if z < 0 else 4


def _voxelize(scene: Scene, resolution: int, normal_mode: str):
    if resolution < 2:
        raise ValueError("voxel resolution must be at least 2")
    if normal_mode not in ("area", "paper"):
        raise ValueError(f"normal_mode must be 'area' or 'paper', not {normal_mode!r}")
    lo, h = grid_frame(scene, resolution)
    areas = scene.face_areas
    keep = areas > 1e-12 * max(float(areas.max()), 1e-30)
    face_ids = np.nonzero(keep)[0]
    face_normal = scene.face_normals
    facing = face_facing(face_normal, face_ids)
    # Items binned per voxel: a plain scene's (voxel, face) pairs, summed as its pieces are made
    # (viewer.rays.pieces); a textured one's pieces themselves, each taking its texture where it lies.
    piece_tint = None
    if scene.textured:
        centroid, piece_area, source = subdivide(scene.triangles[keep], PIECE_EDGE * h)
        coords = np.clip(np.floor((centroid - lo) / h).astype(np.int64), 0, resolution - 1)
        item_key = coords[:, 0] + coords[:, 1] * resolution + coords[:, 2] * resolution ** 2
        item_key = item_key * 6 + facing[source]
        moment = centroid * piece_area[:, None]
        piece_tint = relative_at(scene, face_ids[source], centroid)
    else:
        item_key, source, piece_area, moment = face_pairs(scene.triangles, areas, facing, lo, h, resolution, face_ids)
    piece_face = face_ids[source]
    keys, inverse = _sorted_unique(item_key, resolution ** 3 * 6)

    def total(values, per_face=True):
        """Area-weighted sums per voxel-facing, one contiguous column at a time (4x faster than
        weighting the (items, 3) array; values per face are gathered per column)."""
        columns = np.asarray(values, np.float64).T
        return np.stack([np.bincount(inverse, (column[piece_face] if per_face else column) * piece_area,
                                     minlength=len(keys)) for column in columns], 1)

    area = np.bincount(inverse, piece_area, minlength=len(keys))
    safe = np.maximum(area, 1e-30)[:, None]
    position = np.stack([np.bincount(inverse, column, minlength=len(keys)) for column in moment.T], 1) / safe
    if piece_tint is None:
        albedo = total(scene.albedo) / safe
    else:
        albedo = np.minimum(total(scene.albedo[piece_face] * piece_tint, per_face=False) / safe, 0.999)
    emission = total(scene.emission) / safe
    if normal_mode == "area":
        n = total(face_normal)
    else:  # eq. 3: unweighted mean over the distinct triangles touching the voxel
        pairs = np.unique(np.stack([inverse, piece_face], 1), axis=0)
        n = np.stack([np.bincount(pairs[:, 0], face_normal[pairs[:, 1], c], minlength=len(keys))
                      for c in range(3)], 1)
    length = np.linalg.norm(n, axis=1, keepdims=True)
    n = np.where(length > 1e-12, n / np.maximum(length, 1e-30), FACINGS[keys % 6])
    cell_id = keys // 6
    vox_coords = np.stack([cell_id % resolution, (cell_id // resolution) % resolution,
                           cell_id // resolution ** 2], axis=1)
    grid = VoxelGrid(lo=lo, voxel_size=h, resolution=resolution, coords=vox_coords, position=position,
                     normal=n, area=area, albedo=albedo, emission=emission,
                     lights=light_samples(scene, face_ids, lo, h, resolution, keys))
    return grid, inverse, piece_face, piece_area, keys, piece_tint


def light_samples(scene: Scene, face_ids, lo, h, resolution, keys) -> LightSamples:
    emitting = face_ids[scene.emitting[face_ids]]
    if not len(emitting):
        empty = np.zeros((0, 3))
        return LightSamples(empty, empty, np.zeros(0), empty, np.zeros(0, np.int64), np.zeros(0, np.int64))
    # Half a voxel, unless the emitters are large (a glowing wall): then about MAX_LIGHT_SAMPLES pieces,
    # since a large emitter is no longer small next to the voxels anyway.
    total = float(scene.face_areas[emitting].sum())
    centroid, area, source = subdivide(scene.triangles[emitting], max(0.5 * h, 2.0 * np.sqrt(total / MAX_LIGHT_SAMPLES)))
    face = emitting[source]
    normal = scene.face_normals[face]
    coords = np.clip(np.floor((centroid - lo) / h).astype(np.int64), 0, resolution - 1)
    cell = coords[:, 0] + coords[:, 1] * resolution + coords[:, 2] * resolution ** 2
    key = cell * 6 + face_facing(scene.face_normals, emitting)[source]
    voxel = np.minimum(np.searchsorted(keys, key), len(keys) - 1)
    stray = keys[voxel] != key
    if stray.any():
        # a sliver of emitter whose piece landed in a cell where the finer voxel pieces did not:
        # give it the nearest voxel of the same facing
        centres = np.stack([keys // 6 % resolution, keys // 6 // resolution % resolution,
                            keys // 6 // resolution ** 2], axis=1)
        for s in np.nonzero(stray)[0]:
            same = np.nonzero(keys % 6 == key[s] % 6)[0]
            voxel[s] = same[np.argmin(np.linalg.norm(centres[same] - coords[s], axis=1))]
    return LightSamples(centroid, normal, area, scene.emission[face], voxel, face)

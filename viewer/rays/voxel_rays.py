"""Rays that land on voxels: the physical solver's gather rays, probe rays, and lamp and sun visibility,
cast on the ray layer of viewer.rays.cast.

The solver needs more than the face a ray meets first: it needs the voxel of the grid that carries that
piece of surface, the one the DDA of viewer.rays.dda names when it marches the same ray, since each
cell of its listing pairs a triangle with its voxel there. With Embree the ray is cast against the
triangles, and the voxel is then read from the same listing: the entry of the hit's face in the cell
where the hit lies. So both backends name the same voxel, or BACKFACE for a face met from behind, for
every ray whose hit is not on a face's edge or a cell's boundary (tests/rays/test_voxel_rays.py),
while Embree's cost grows with log(faces) where the DDA's grows with the triangles listed per cell.

Embree is also why the first run is short: the DDA's march compiles into every kernel that traces (a
minute of CPU on an empty cache), where the lookup below compiles in about a second.
"""

from __future__ import annotations

from functools import cached_property
from typing import NamedTuple

import numba
import numpy as np

from viewer.rays import dda, embree
from viewer.rays.cast import TriangleCaster, embree_available
from viewer.rays.landing import FAR, bundle, bundle_kept, bundle_packed, landed, tallied
from viewer.rays.packets import LANES, occluded8, packet
from viewer.threads import cores_for


RAYS_PER_CALL = 1 << 18
"""Rays cast at a time: their hits take about 10 MB, however many rays a scene's bundle holds."""
HAIR = 1e-6
"""Cells by which `_held` widens each triangle's box and `empty_box` each segment's, so that a point on a
cell's face counts both cells."""
HELD_EVERYWHERE = np.zeros((0, 0, 0), np.int32)
"""An `occupied` table of no cells: `empty_box` finds no box empty, so every segment is traced."""


class Landed(NamedTuple):
    """`VoxelRays.kept_bundle`'s rays, (P, D) for D rays from each of P origins."""

    hits: np.ndarray
    """int32: the voxel each ray met first, dda.MISS or dda.BACKFACE."""
    faces: np.ndarray | None
    """int32: the face each ray met (None where the rays are not traced through Embree from compiled code)."""
    t: np.ndarray | None
    """float64: how far each ray went to it (None as `faces`)."""
    traced: int
    """How many of the rays were traced (the others kept their face, `kept_bundle`'s `before`)."""
    sources: np.ndarray
    """int32: `hits` with the call's `none` where a ray met no front face: the row it gathers light from."""
    backs: np.ndarray
    """(P,) int64: how many of each origin's rays met a face from behind."""


class VoxelRays:
    """A scene's triangles and the voxel listing of its grid, ready for rays that land on voxels."""

    def __init__(self, scene, cells: dda.Cells, backend: str | None = None, caster: TriangleCaster | None = None,
                 previous: "VoxelRays | None" = None, quick: bool | None = False):
        """`backend`: "embree", "dda", or None for Embree where it is installed. `caster`: the Embree
        hierarchy of the same triangles, when another listing of them already built one. `previous`: the
        rays of the same faces before some of them moved, whose hierarchy of the others is kept
        (`TriangleCaster`); `quick`: Embree built quickly (`TriangleCaster`)."""
        self.cells = cells
        self.backend = backend or ("embree" if embree_available() else "dda")
        if self.backend == "embree":
            self.caster = caster if caster is not None and caster.backend == "embree" else TriangleCaster(
                scene, cells, self.backend, None if previous is None else previous.caster, quick)
        else:
            self.caster = None

    @cached_property
    def occupied(self) -> np.ndarray:
        """(N+1, N+1, N+1) int32 [z, y, x]: how many of the grid's cells below and before each corner some
        triangle's bounding box reaches into (a summed-volume table): a box of cells that none reaches, read
        in eight lookups, is one no segment within it can meet."""
        c = self.cells
        held = np.zeros((c.n, c.n, c.n), np.uint8)
        with cores_for(len(c.v0)):   # a box room's few dozen faces on this thread
            _held(c.v0, c.e1, c.e2, np.asarray(c.lo, np.float64), float(c.h), held)
        out = np.zeros((c.n + 1, c.n + 1, c.n + 1), np.int32)
        _summed_volume(held, out)
        return out

    def box_table(self, segments: int) -> np.ndarray:
        """The table `empty_box` reads for `segments` segments: `occupied` where they outnumber the
        triangles, since it costs a pass over them (12 ms for a million), else HELD_EVERYWHERE."""
        return self.occupied if segments > 4 * len(self.cells.v0) else HELD_EVERYWHERE

    def first_hits(self, origins: np.ndarray, directions: np.ndarray) -> np.ndarray:
        """(R,) int64: the voxel each ray o + t d (t > 0, unit d) meets first, dda.MISS or dda.BACKFACE."""
        o = np.ascontiguousarray(origins, np.float64).reshape(-1, 3)
        d = np.ascontiguousarray(directions, np.float64).reshape(-1, 3)
        if self.caster is None:
            return dda.first_hits(self.cells, o, d)
        out = np.empty(len(o), np.int64)
        for start in range(0, len(o), RAYS_PER_CALL):
            part = slice(start, start + RAYS_PER_CALL)
            hits = self.caster.closest_hits(o[part], d[part])
            c = self.cells
            out[part] = landed(o[part], d[part], hits.face, hits.t, hits.front, c.lo, c.h, c.n, c.first, c.triangle,
                               c.voxel)
        return out

    def bundle_hits(self, origins: np.ndarray, directions: np.ndarray) -> np.ndarray:
        """(P, D) int32 first hits of D rays from each of P origins: `directions` is (D, 3) shared by all
        origins or (P, D, 3) one set each."""
        o = np.ascontiguousarray(origins, np.float64).reshape(-1, 3)
        d = np.asarray(directions, np.float64)
        if self.caster is None:
            return dda.bundle_hits(self.cells, o, d)
        count = d.shape[-2]
        if self.caster.direct is not None:   # traced and looked up in one compiled loop
            out = np.empty((len(o), count), np.int32)
            c, caster = self.cells, self.caster
            bundle(o, np.ascontiguousarray(d[None] if d.ndim == 2 else d), *caster.direct.handle, caster.faces,
                   caster.e1, caster.e2, caster.twin, caster.v0, c.lo, c.h, c.n, c.first, c.triangle, c.voxel, out)
            return out
        d = np.broadcast_to(d[None] if d.ndim == 2 else d, (len(o), count, 3))
        out = np.empty((len(o), count), np.int32)
        rows = max(1, RAYS_PER_CALL // max(count, 1))
        for start in range(0, len(o), rows):
            part = slice(start, start + rows)
            starts = np.repeat(o[part], count, axis=0)
            out[part] = self.first_hits(starts, d[part].reshape(-1, 3)).reshape(-1, count)
        return out

    def kept_bundle(self, origins: np.ndarray, directions: np.ndarray, before=None, box=None, packets=None,
                    which: np.ndarray | None = None, none: int = dda.MISS, in_place: bool = False) -> "Landed":
        """`bundle_hits` for (P, D, 3) `directions`, with what a later call needs to keep them (`Landed`).
        `before`: the (faces, t) of the same rays in a scene where only the triangles in `box` ((lo, hi):
        their old and new places, with room for a cell's neighbours) moved; a ray that does not pass
        through the box before its old hit meets the same face at the same t, and only its voxel is looked
        up again in this listing; the others are traced again. `before` may add (hits, remap): the voxel
        each ray landed on then and the new index of each old voxel (-1 where it changed), so that a kept
        ray takes its old voxel's new index without a lookup (the same voxel: its face did not move, nor
        did its cell's surface). `packets`: (N, LANES) flat ray indices (origin x D + ray, -1 for none)
        that cover every ray once, traced a packet at a time where all are traced
        (`landing.bundle_packed`): parallel rays from nearby origins, the same hits. `which`: (P,) the
        row of `directions` (S, D, 3) each origin casts (None: one row each). `none`: what `Landed.sources`
        holds for a ray that meets no front face. `in_place`: `before`'s (faces, t, hits) become the
        result's, updated where they change (their owner drops them: a move of a 24^3 lattice's rays then
        reads and writes a third of the memory)."""
        o = np.ascontiguousarray(origins, np.float64).reshape(-1, 3)
        d = np.ascontiguousarray(directions, np.float64)
        which = (np.arange(len(o), dtype=np.int32) if which is None
                 else np.ascontiguousarray(which, np.int32))
        shape = (len(o), d.shape[1])
        sources, backs = np.empty(shape, np.int32), np.empty(len(o), np.int64)
        if self.caster is None or self.caster.direct is None:
            out = self.bundle_hits(o, d[which])
            tallied(out, none, sources, backs)
            return Landed(out, None, None, shape[0] * shape[1], sources, backs)
        c, caster = self.cells, self.caster
        if in_place and before is not None and len(before) == 4:
            face, t, out = before[0], before[1], before[2]
            if not all(a.flags.c_contiguous and a.shape == shape and a.dtype == kind
                       for a, kind in ((face, np.int32), (t, np.float64), (out, np.int32))):
                raise ValueError("rays updated in place take C-contiguous (P, D) faces, distances and hits")
        else:
            out, face, t = np.empty(shape, np.int32), np.empty(shape, np.int32), np.empty(shape, np.float64)
            in_place = False
        if before is None and packets is not None:
            if len(d) != len(o):
                raise ValueError("rays in packets take a row of directions for each origin")
            bundle_packed(o, d.reshape(-1, 3), d.shape[1], packets, *caster.direct.packets, caster.faces, caster.e1,
                          caster.e2, caster.twin, c.lo, c.h, c.n, c.first, c.triangle, c.voxel, out.reshape(-1),
                          face.reshape(-1), t.reshape(-1))
            tallied(out, none, sources, backs)
            return Landed(out, face, t, out.size, sources, backs)
        if before is None:   # every ray traced
            lo, hi, kept, old_face, old_t = np.full(3, -np.inf), np.full(3, np.inf), False, face, t
        else:
            old_face, old_t = np.ascontiguousarray(before[0], np.int32), np.ascontiguousarray(before[1], np.float64)
            lo, hi, kept = np.asarray(box[0], np.float64), np.asarray(box[1], np.float64), True
        old_hits, remap = (before[2:] if before is not None and len(before) == 4
                           else (np.zeros((0, 0), np.int32), np.zeros(0, np.int32)))
        traced = bundle_kept(o, d, which, kept, lo, hi, old_face, old_t, np.ascontiguousarray(old_hits, np.int32),
                             np.ascontiguousarray(remap, np.int32), *caster.direct.handle, caster.faces, caster.e1,
                             caster.e2, caster.twin, caster.v0, c.lo, c.h, c.n, c.first, c.triangle, c.voxel, out, face,
                             t, none, sources, backs, in_place)
        return Landed(out, face, t, int(traced.sum()), sources, backs)

    def escapes(self, origins: np.ndarray, direction: np.ndarray) -> np.ndarray:
        """(R,) bool: a ray from each origin along one direction meets no surface (it leaves the scene)."""
        o = np.ascontiguousarray(origins, np.float64).reshape(-1, 3)
        if self.caster is None:
            return dda.escapes(self.cells, o, direction)
        d = np.broadcast_to(np.asarray(direction, np.float64) / np.linalg.norm(direction), o.shape)
        return ~self.caster.blocked(o, d, FAR)

    def segments_clear(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        """(R,) bool: the segment a -> b crosses no surface, from either side."""
        a = np.ascontiguousarray(a, np.float64).reshape(-1, 3)
        if self.caster is None:
            return dda.segments_clear(self.cells, a, b)
        if self.caster.direct is not None:   # one compiled pass, the segments in empty cells untraced
            out = np.empty(len(a), np.bool_)
            with cores_for(len(a)):   # the few shadow segments a move traces again
                _segments_clear(*self.caster.direct.occlusion, a,
                                np.ascontiguousarray(np.broadcast_to(np.asarray(b, np.float64).reshape(-1, 3), a.shape)),
                                self.box_table(len(a)), self.cells.lo, self.cells.h, out)
            return out
        d = np.asarray(b, np.float64).reshape(-1, 3) - a
        length = np.linalg.norm(d, axis=1)
        d /= np.maximum(length, 1e-300)[:, None]
        return ~self.caster.blocked(a, d, length) | (length <= 0)

    def pairs_clear(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        """(A, B) float32: 1 where the segment from a[i] to b[j] crosses no surface, from either side."""
        a = np.ascontiguousarray(a, np.float64).reshape(-1, 3)
        b = np.ascontiguousarray(b, np.float64).reshape(-1, 3)
        if self.caster is None:
            return dda.pairs_clear(self.cells, a, b)
        out = np.empty((len(a), len(b)), np.float32)
        if self.caster.direct is not None:
            _pairs_clear(*self.caster.direct.occlusion8, a, b, self.box_table(len(a) * len(b)), self.cells.lo,
                         self.cells.h, out)
            return out
        rows = max(1, RAYS_PER_CALL // max(len(b), 1))
        for start in range(0, len(a), rows):
            part = a[start:start + rows]
            out[start:start + rows] = self.segments_clear(np.repeat(part, len(b), axis=0),
                                                          np.tile(b, (len(part), 1))).reshape(len(part), len(b))
        return out


@numba.njit(cache=True, nogil=True, parallel=True)
def _segments_clear(query, scene, a, b, occupied, lo, h, out):
    """`segments_clear` through Embree: a segment whose box of cells holds no triangle (`occupied`) is
    clear untraced, the others cast as the caster's `blocked` casts them (the direction divided by the
    length, in double precision)."""
    count = a.shape[0]
    for block in numba.prange((count + embree.BLOCK - 1) // embree.BLOCK):
        record = embree.record()
        for i in range(block * embree.BLOCK, min(count, (block + 1) * embree.BLOCK)):
            dx, dy, dz = b[i, 0] - a[i, 0], b[i, 1] - a[i, 1], b[i, 2] - a[i, 2]
            length = np.sqrt(dx * dx + dy * dy + dz * dz)
            if length <= 0.0 or empty_box(occupied, lo, h, a[i, 0], a[i, 1], a[i, 2], b[i, 0], b[i, 1], b[i, 2]):
                out[i] = True
                continue
            scale = max(length, 1e-300)
            out[i] = not embree.occluded(query, scene, record, a[i, 0], a[i, 1], a[i, 2], dx / scale, dy / scale,
                                         dz / scale, length)


@numba.njit(cache=True, nogil=True, parallel=True)
def _pairs_clear(query8, scene, a, b, occupied, lo, h, out):
    """`pairs_clear` through Embree, each segment made and cast in one compiled pass (repeating, tiling
    and normalizing (A x B, 3) arrays in numpy first took a third of a moved lamp's shadow rays). A
    segment whose box of cells holds no triangle (`occupied`, `VoxelRays.occupied`) is clear untraced:
    from a probe in a room's open middle to a lamp, most are. The others go LANES at a time, the
    segments of consecutive points a (a lattice's row, voxels in hash id order: near each other) to one
    point b, nearly parallel, through rtcOccluded8: the same answers as one by one, in 0.6-0.75 of the
    time (the Cornell box's probes to its lamp's 16 ray ends 5.7 -> 3.6 ms, a validation room's 2,454
    voxels to 129 ends 12.9 -> 7.8)."""
    lanes = LANES
    for block in numba.prange((a.shape[0] + lanes - 1) // lanes):
        record = packet()
        o, d = np.empty((lanes, 3)), np.empty((lanes, 3))
        length, traced, blocked = np.empty(lanes), np.empty(lanes, np.bool_), np.empty(lanes, np.bool_)
        start = block * lanes
        for j in range(b.shape[0]):
            some = False
            for lane in range(lanes):
                i = start + lane
                traced[lane] = i < a.shape[0] and segment_lane(o, d, length, lane, occupied, lo, h, a[i, 0], a[i, 1],
                                                               a[i, 2], b[j, 0], b[j, 1], b[j, 2])
                if i < a.shape[0] and not traced[lane]:
                    out[i, j] = 1.0
                some |= traced[lane]
            if some:
                occluded8(query8, scene, record, o, d, length, traced, blocked)
                for lane in range(lanes):
                    if traced[lane]:
                        out[start + lane, j] = 0.0 if blocked[lane] else 1.0


@numba.njit(cache=True, nogil=True, inline="always")
def segment_lane(o, d, length, lane, occupied, lo, h, ax, ay, az, bx, by, bz):
    """Put the segment a -> b into lane `lane` of a packet's origins, unit directions and lengths (each
    (LANES, ...)); False, and nothing put, where it is clear untraced: no length, or a box of cells no
    triangle reaches (`empty_box`), as `segment_clear` takes it."""
    dx, dy, dz = bx - ax, by - ay, bz - az
    size = np.sqrt(dx * dx + dy * dy + dz * dz)
    if size <= 0.0 or empty_box(occupied, lo, h, ax, ay, az, bx, by, bz):
        return False
    inv = 1.0 / size
    o[lane, 0], o[lane, 1], o[lane, 2] = ax, ay, az
    d[lane, 0], d[lane, 1], d[lane, 2] = dx * inv, dy * inv, dz * inv
    length[lane] = size
    return True


@numba.njit(cache=True, nogil=True, inline="always")
def segment_clear(query, scene, record, occupied, lo, h, ax, ay, az, bx, by, bz):
    """Whether the segment a -> b crosses no surface, through Embree's occlusion query and an `embree.record`:
    clear untraced where its box of cells holds no triangle (`empty_box`)."""
    dx, dy, dz = bx - ax, by - ay, bz - az
    length = np.sqrt(dx * dx + dy * dy + dz * dz)
    if length <= 0.0 or empty_box(occupied, lo, h, ax, ay, az, bx, by, bz):
        return True
    inv = 1.0 / length
    return not embree.occluded(query, scene, record, ax, ay, az, dx * inv, dy * inv, dz * inv, length)


@numba.njit(cache=True, nogil=True, parallel=True)
def _held(v0, e1, e2, lo, h, held):
    """Mark in `held` (N, N, N) [z, y, x] every cell of each triangle's bounding box (HAIR wider)."""
    n, hair = held.shape[0], HAIR * h
    for t in numba.prange(v0.shape[0]):
        low, high = np.empty(3, np.int64), np.empty(3, np.int64)
        for axis in range(3):
            a, b, c = v0[t, axis], v0[t, axis] + e1[t, axis], v0[t, axis] + e2[t, axis]
            low[axis] = dda.cell_of(min(a, b, c) - hair, lo[axis], h, n)
            high[axis] = dda.cell_of(max(a, b, c) + hair, lo[axis], h, n)
        for z in range(low[2], high[2] + 1):
            for y in range(low[1], high[1] + 1):
                for x in range(low[0], high[0] + 1):
                    held[z, y, x] = 1


@numba.njit(cache=True, nogil=True)
def _summed_volume(held, out):
    """out[z + 1, y + 1, x + 1] = the sum of held (N, N, N) over [0, z] x [0, y] x [0, x] (`out`'s first
    layers stay 0): each plane summed along x and y, then the columns along z. A 48^3 grid: 0.08 ms on one
    core (0.8 in numpy's three cumsums and a widening copy); within a moved box's update the two cores
    sharing the planes took 0.24, too little work a plane to pay for waking the other (a 128^3 grid: 2 ms)."""
    n = held.shape[0]
    for z in range(n):
        for y in range(n):
            running = 0
            for x in range(n):
                running += held[z, y, x]
                out[z + 1, y + 1, x + 1] = running
        for y in range(1, n):
            for x in range(1, n + 1):
                out[z + 1, y + 1, x] += out[z + 1, y, x]
    for y in range(1, n + 1):
        for z in range(1, n):
            for x in range(1, n + 1):
                out[z + 1, y, x] += out[z, y, x]


@numba.njit(cache=True, nogil=True, inline="always")
def empty_box(occupied, lo, h, ax, ay, az, bx, by, bz):
    """Whether no cell of the box around points a and b (HAIR wider) holds a triangle: eight lookups of the
    summed-volume table."""
    n = occupied.shape[0] - 1
    if n < 1:
        return False
    hair = HAIR * h
    x0, x1 = dda.cell_of(min(ax, bx) - hair, lo[0], h, n), dda.cell_of(max(ax, bx) + hair, lo[0], h, n) + 1
    y0, y1 = dda.cell_of(min(ay, by) - hair, lo[1], h, n), dda.cell_of(max(ay, by) + hair, lo[1], h, n) + 1
    z0, z1 = dda.cell_of(min(az, bz) - hair, lo[2], h, n), dda.cell_of(max(az, bz) + hair, lo[2], h, n) + 1
    total = (occupied[z1, y1, x1] - occupied[z0, y1, x1] - occupied[z1, y0, x1] - occupied[z1, y1, x0]
             + occupied[z0, y0, x1] + occupied[z0, y1, x0] + occupied[z1, y0, x0] - occupied[z0, y0, x0])
    return total == 0


def keyed_cells(grid, keys: np.ndarray, scene) -> dda.Cells:
    """The cells of `grid` (a VoxelGrid, whose voxel k has the key `keys[k]`: flat cell x 6 + facing) for
    rays cast through Embree, without a listing: a hit's voxel is its face's facing's in the cell of the
    hit (`landing._keyed_voxel`), the voxel `dda.Cells.of` would list for the face there, and no triangle is
    listed in any cell (a million-triangle scan's listing took 80 ms a move). Not for the DDA, which
    marches the listing."""
    from viewer.rays.voxels import face_facing

    n = int(grid.resolution)
    table = dda.key_table(keys, n)
    facing = face_facing(scene.face_normals).astype(np.int64)
    return dda.Cells(np.asarray(grid.lo, np.float64), float(grid.voxel_size), n, np.zeros(0, np.int64), facing,
                     table, *scene.edges)



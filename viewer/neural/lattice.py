"""What an `Encoder` (viewer/neural/encoder.py) keeps between edits on one probe lattice: the splat and
the features that the voxels' geometry alone fixes, and the shadow rays that the occluders alone fix.
"""

from __future__ import annotations

import numba
import numpy as np
from scipy import sparse

from viewer.neural import encoding
from viewer.neural.encoding import CHANNELS
from viewer.rays import moved_faces
from viewer.rays.lattice_sight import LatticeSight, sweeps
from viewer.rays.sun import voxel_sun_cover
from viewer.rays.landing import meets_box
from viewer.rays.voxel_rays import VoxelRays
from viewer.rays.voxels import SURFACE_OFFSET, VoxelGrid
from viewer.neural.changes import same_voxels
from viewer.probes import sh
from viewer.threads import cores_for


GEOMETRY = slice(0, encoding.FEATURES.index("albedo"))
PLACE = slice(encoding.FEATURES.index("coord_x"), encoding.FEATURES.index("bounce_0"))
"""The features of `LatticeGeometry.features` that an encoding takes as they are (the others are its own)."""


class LatticeGeometry:
    """What the encoding takes from the voxels' geometry alone (positions, normals, areas) on one lattice."""

    def __init__(self, voxels: VoxelGrid, lo: np.ndarray, hi: np.ndarray, points: np.ndarray,
                 previous: "LatticeGeometry | None" = None):
        """`previous`: the same lattice's geometry for other voxels, whose coordinate and extent features
        are these too (made again, they took 0.4 ms of a moved object's 0.8 here)."""
        self.points = points
        self.position, self.normal, self.area = voxels.position, voxels.normal, voxels.area
        m = round(len(points) ** (1 / 3))
        spacing = (hi - lo) / m
        face_area = np.array([spacing[1] * spacing[2], spacing[0] * spacing[2], spacing[0] * spacing[1]])
        self.cell_area = float(np.mean(face_area))
        cells = m ** 3
        # the same splat as `encode`, its eight corners as the eight entries of each voxel's column (eight
        # distinct cells): the same numbers to round-off
        corners = encoding.splat(voxels.position, lo, spacing, m)
        rows = np.stack([index for index, _ in corners], axis=1).ravel()
        weights = np.stack([weight for _, weight in corners], axis=1).ravel()
        self.splat = sparse.csc_matrix((weights, rows, np.arange(0, len(rows) + 1, len(corners))),
                                       shape=(cells, voxels.count))
        self.cell = encoding.lattice_cells(voxels.position, lo, spacing, m)
        self.density = self.splat @ voxels.area
        self.safe = np.where(self.density > 0, self.density, 1.0)
        normals = self.splat @ (voxels.area[:, None] * voxels.normal)
        self.features = np.empty((CHANNELS, cells), np.float32)
        """The features that geometry alone fixes; the albedo, emission and direct rows are filled per
        encoding."""
        self.features[0] = self.density / self.cell_area
        self.features[1:4] = normals.T / self.cell_area
        if previous is not None and previous.points is points:
            self.features[PLACE] = previous.features[PLACE]
        else:
            self.features[15:18] = ((points - lo) / (hi - lo) * 2.0 - 1.0).T
            extent = hi - lo
            self.features[18:21] = (extent / extent.max())[:, None]
        self.spacing = spacing

    def fits(self, voxels: VoxelGrid) -> bool:
        return all(a is b or np.array_equal(a, b) for a, b in (
            (self.position, voxels.position), (self.normal, voxels.normal), (self.area, voxels.area)))

    def gather(self, values: np.ndarray) -> np.ndarray:
        """Area-weighted per-voxel values (K, C) splatted onto the lattice cells: (cells, C)."""
        return self.splat @ (self.area[:, None] * values)


class LatticeShadows:
    """What the encoding's shadows take from the occluders (`encoding.occluders`; None: nothing casts a
    shadow) on one lattice: the visibility rays of emitting patches, and the sun's visibility for the
    last direction asked.

    Made from the `previous` occluders' shadows when only some of the triangles moved (an object or a
    lamp dragged): a ray that meets neither where the moved triangles were nor where they are now meets
    the same triangles as before, so it keeps its answer, and only the rays through the box around the
    moved triangles' old and new places are traced again (`moved_box`). Shadows made `across` voxels
    keep the answers of the voxels that kept their surface in their cell (`changes.same_voxels`): the
    voxels the object left or entered, and the rays through the box, are traced again."""

    def __init__(self, blockers: VoxelRays | None, points: np.ndarray, lo: np.ndarray, spacing: np.ndarray,
                 previous: "LatticeShadows | None" = None, box=None, across: VoxelGrid | None = None):
        """`box`: `moved_box(previous.blockers, blockers)` where the caller has it already. `across`: the
        voxels whose surface points `points` are; the sun's visibility is then the share of each voxel's
        surface that sees it (`viewer.rays.sun`), not the one ray from its point."""
        self.blockers, self.points, self.lo, self.spacing = blockers, points, lo, spacing
        self.across = across
        self._sun: tuple[bytes, np.ndarray] | None = None
        self._rows: dict[bytes, tuple[np.ndarray, np.ndarray | None]] = {}
        """Each ray end's visibility (P,) and which of its segments were traced (None: all), for the shadows
        of the next move."""
        self._block = None
        """The ray ends of the last swept call, its rows and traced segments: the next move's, as they are,
        where it asks the same ends (a dragged object: no copy of a large lamp's rows)."""
        self._before = None
        """(box lo, box hi, the previous shadows' rows, their sun, their last block) when those answer every
        ray outside the box."""
        self._match = None
        """(P,) for shadows made `across` voxels after a move: the row of the previous shadows' voxel with
        the same surface in the same cell, -1 where none was (a voxel the moved object entered or left):
        the answers are kept there for the rays that miss the box."""
        same_points = previous is not None and np.array_equal(previous.points, points)
        if previous is not None and (same_points or (across is not None and previous.across is not None)):
            box = moved_box(previous.blockers, blockers) if box is None else box
            if box is not None:
                self._before = (*box, previous._rows, previous._sun, previous._block)
                if not same_points:
                    self._match = same_voxels(previous.across, across)
        self._sight: LatticeSight | None = None
        """The lattice's edges, where the probes' visibility is swept (`viewer.rays.lattice_sight`): made
        at the first ray end asked, from the previous shadows' where only the box's triangles moved."""
        self._previous_sight = None if self._before is None else previous._sight
        self.sweeping: bool | None = None
        """Whether the probes' visibility is swept (`viewer.rays.lattice_sight`) rather than every segment
        traced: with Embree, for the probes' lattice (not `across` voxels), where the scene's emitting
        patches have enough ray ends (`lattice_sight.sweeps`; decided at `targets`, else at the first call)."""
        self.switched = False
        """Whether the last `targets` changed `sweeping` (an emission edit that changed the count of ray
        ends): the rows kept so far are dropped, and every basis made from them is stale."""
        self._previous_sweeping = None if self._before is None else previous.sweeping
        self.retraced = 0
        """Rays traced again through the moved box (the others kept) by the last call."""

    def fits(self, blockers: VoxelRays | None) -> bool:
        """Whether `blockers` are these occluders: the same object, or equal arrays (a new listing of the
        same triangles)."""
        a, b = self.blockers, blockers
        if a is b:
            return True
        if a is None or b is None:
            return False
        return all(np.array_equal(x, y) for x, y in zip(a.cells.args(), b.cells.args()))

    def targets(self, position: np.ndarray, normal: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """`encoding.shadow_targets` of the emitting patches: (C, 3) where each cluster's ray ends, (E,)
        each patch's cluster (one cluster at the origin when nothing casts a shadow)."""
        if self.blockers is None:
            return np.zeros((min(len(position), 1), 3)), np.zeros(len(position), np.int64)
        target, cluster = encoding.shadow_targets(self.blockers, position, normal, self.lo, self.spacing)
        self._decide(len(target))
        return target, cluster

    def _decide(self, ends: int) -> None:
        """Set `sweeping` for a scene of `ends` ray ends (`switched` where it changes)."""
        sweeping = self.across is None and sweeps(self.blockers, ends)
        self.switched = self.sweeping is not None and sweeping != self.sweeping
        if self.switched:
            self._rows, self._block = {}, None
        self.sweeping = sweeping

    def _kept(self):
        """`_before` where the previous shadows found their rows the same way as these."""
        return self._before if self._previous_sweeping == self.sweeping else None

    def visibility(self, target: np.ndarray) -> np.ndarray:
        """(C, P) float32: 1 where probe p sees the end of ray c, as `encoding.lattice_visibility` finds it
        (each ray end on its own: any subset of the clusters gives their columns of the whole)."""
        if self.blockers is None:
            return np.ones((len(target), len(self.points)), np.float32)
        target = np.asarray(target, np.float64).reshape(-1, 3)
        if self.sweeping is None:
            self._decide(len(target))
        if self.sweeping:
            return self._swept(target)
        before = self._kept()
        out = np.empty((len(target), len(self.points)), np.float32)
        fresh, kept = [], []
        self.retraced = 0
        match = self._match
        for c, end in enumerate(target):
            row = None if before is None else before[2].get(end.tobytes())
            if row is None:
                fresh.append(c)
            else:
                out[c] = row[0] if match is None else np.where(match >= 0, row[0][match], 0.0)
                kept.append(c)
        if kept:   # the kept rows' rays through the moved box (and from points new here), traced again in one call
            with cores_for(len(self.points) * len(kept)):
                near = _segments_meet_box(self.points, target[kept], before[0], before[1])
            if match is not None:
                near |= (match < 0)[None, :]
            row, probe = np.nonzero(near)
            if len(row):
                ends = target[kept][row]
                out[np.asarray(kept)[row], probe] = self.blockers.segments_clear(self.points[probe], ends)
                self.retraced += len(row)
        if fresh:
            out[fresh] = self.blockers.pairs_clear(self.points, target[fresh]).T
            self.retraced += len(fresh) * len(self.points)
        for c, end in enumerate(target):
            self._rows[end.tobytes()] = (out[c].copy(), None)
        return out

    def _swept(self, target: np.ndarray) -> np.ndarray:
        """`visibility` swept over the lattice, the previous shadows' traced segments that miss the moved
        box kept."""
        kept = self._kept()
        if self._sight is None:
            box = None if kept is None else kept[:2]
            self._sight = LatticeSight(self.blockers, self.points, self.lo, self.spacing, self._previous_sight, box)
            self._previous_sight = None
        before = None
        keys = [end.tobytes() for end in target]
        if kept is not None and kept[4] is not None and kept[4][0] == keys:
            before = (*kept[:2], *kept[4][1:], np.ones(len(target), np.bool_))   # as they are
        elif kept is not None:
            rows = np.zeros((len(target), len(self.points)), np.float32)
            traced = np.zeros(rows.shape, np.bool_)
            reused = np.zeros(len(target), np.bool_)
            for c, end in enumerate(target):
                row = kept[2].get(end.tobytes())
                if row is not None:
                    rows[c], traced[c], reused[c] = row[0], True if row[1] is None else row[1], True
            before = (*kept[:2], rows, traced, reused)
        out, traced, self.retraced = self._sight.visibility(target, before)
        for c, key in enumerate(keys):
            self._rows[key] = (out[c], traced[c])
        self._block = (keys, out, traced)
        return out

    def sun_visibility(self, direction: np.ndarray) -> np.ndarray:
        """(P,) 1 where each point sees the sun past these occluders (`encoding.sun_visibility`), or for
        shadows made `across` voxels the share of each voxel's surface that does; kept for the last
        direction asked."""
        key = direction.tobytes()
        if self._sun is None or self._sun[0] != key:
            before = None if self._before is None else self._before[3]
            if self.across is not None:
                visible = self._voxel_sun(direction, None if before is None or before[0] != key else before[1])
            elif before is not None and before[0] == key and self.blockers is not None:
                visible = before[1].copy()
                unit = np.asarray(direction, np.float64) / np.linalg.norm(direction)
                with cores_for(len(self.points)):
                    near = np.flatnonzero(_rays_meet_box(self.points, unit, self._before[0], self._before[1]))
                visible[near] = encoding.sun_visibility(self.blockers, self.points[near], direction)
            else:
                visible = encoding.sun_visibility(self.blockers, self.points, direction)
            self._sun = (key, visible)
        return self._sun[1]

    def _voxel_sun(self, direction: np.ndarray, before: np.ndarray | None) -> np.ndarray:
        """`voxel_sun_cover` of the `across` voxels; after a move (`before`: the previous voxels' cover for
        the same direction) kept for each voxel at the same place whose nine rays and their starts miss the
        moved box: where every ray from its surface point misses the box widened by the starts' reach
        (a voxel and twice its surface offset), so do theirs."""
        if before is None or self._before is None or self.blockers is None:
            return voxel_sun_cover(self.blockers, self.across, direction)
        voxels, match = self.across, self._match
        if match is None:
            match = np.arange(len(self.points))
        reach = voxels.voxel_size * (1.0 + 2.0 * SURFACE_OFFSET)
        lo, hi = self._before[0] - reach, self._before[1] + reach
        unit = np.asarray(direction, np.float64) / np.linalg.norm(direction)
        cell = voxels.lo + voxels.coords * voxels.voxel_size
        with cores_for(len(self.points)):
            crossing = _rays_meet_box(self.points, unit, lo, hi)
        redo = ((match < 0) | crossing
                | np.all((cell < hi) & (cell + voxels.voxel_size > lo), axis=1))
        visible = np.where(match >= 0, before[np.maximum(match, 0)], 0.0)
        rows = np.flatnonzero(redo)
        visible[rows] = voxel_sun_cover(self.blockers, voxels, direction, rows)[rows]
        return visible


MOVED_SHARE = 1.0
"""Past this share of the triangles moved, the rays are traced afresh. A scan dragged across a room is
most of its triangles, and still only the rays through the box around its old and new places are traced
again: a 68k-triangle bunny moved took 92 ms to new probes, against 115 with the rays traced afresh past
half the triangles (the same probes, bit for bit; a million-triangle one 279 ms against 280-296)."""


def moved_box(before: VoxelRays | None, after: VoxelRays | None) -> tuple[np.ndarray, np.ndarray] | None:
    """(lo, hi) around the old and new places of the triangles that moved from `before` to `after` (the
    same triangles, in the same order), a hair wider; None when they are not the same triangles, none
    moved or most did."""
    if before is None or after is None:
        return None
    found = moved_faces.moved_box(before.cells, after.cells, after.cells.h, MOVED_SHARE)
    if found is None or found[1] is None:
        return None
    return found[1][0], found[1][1]


@numba.njit(cache=True, nogil=True, parallel=True)
def _rays_meet_box(points, direction, lo, hi):
    """(P,) bool: the ray from each point along `direction` passes through the box [lo, hi]."""
    out = np.empty(points.shape[0], np.bool_)
    for p in numba.prange(points.shape[0]):
        out[p] = meets_box(points[p, 0], points[p, 1], points[p, 2], direction[0], direction[1], direction[2],
                           np.inf, lo, hi)
    return out


@numba.njit(cache=True, nogil=True, parallel=True)
def _segments_meet_box(points, ends, lo, hi):
    """(C, P) bool: the segment from each point to each of `ends` passes through the box [lo, hi]."""
    out = np.empty((ends.shape[0], points.shape[0]), np.bool_)
    for p in numba.prange(points.shape[0]):
        x, y, z = points[p, 0], points[p, 1], points[p, 2]
        for c in range(ends.shape[0]):
            out[c, p] = meets_box(x, y, z, ends[c, 0] - x, ends[c, 1] - y, ends[c, 2] - z, 1.0, lo, hi)
    return out


def assemble(features: np.ndarray, albedo: np.ndarray, emitted: np.ndarray, direct: np.ndarray,
             bounce: np.ndarray, seen: np.ndarray, opened: np.ndarray, inv: np.ndarray, keep: np.ndarray,
             previous: np.ndarray | None) -> np.ndarray:
    """(3, CHANNELS, P) float32: the encoding's rows, one compiled pass shared among the cores: the
    geometry's rows of `features` (CHANNELS, P) as they are, the `albedo` (3, P), `emitted` (3, P) and
    `direct` (3, 9, P) float32, and the `bounce` and `seen` (P, 9, 3) gathers turned to rows, each pass's
    light times its `inv` (3,), the `opened` share (P,); the passes in `keep` (3,) bool copied from
    `previous` (3, CHANNELS, P). 0.83 ms for a 24^3 lattice on two cores, where the passes one after
    the other in numpy and a compiled transpose took 0.97."""
    out = np.empty((3, CHANNELS, features.shape[1]), np.float32)
    geometric = np.zeros(CHANNELS, np.bool_)
    geometric[GEOMETRY] = geometric[PLACE] = True
    kept = previous if previous is not None else out[:0]
    _assemble(features, geometric, np.ascontiguousarray(albedo, np.float32), np.asarray(emitted, np.float64),
              np.ascontiguousarray(direct, np.float32), bounce, seen, np.ascontiguousarray(opened, np.float32),
              np.asarray(inv, np.float64), np.asarray(keep, np.bool_) & (previous is not None), kept,
              encoding.FEATURES.index("albedo"), encoding.FEATURES.index("emission"), encoding.DIRECT.start,
              encoding.BOUNCE.start, encoding.SEEN.start, encoding.OPEN, out)
    return out


@numba.njit(cache=True, nogil=True, parallel=True)
def _assemble(features, geometric, albedo, emitted, direct, bounce, seen, opened, inv, keep, previous,
              albedo_row, emission_row, direct_row, bounce_row, seen_row, open_row, out):
    rows = out.shape[1]
    for job in numba.prange(3 * rows):
        c, f = job // rows, job % rows
        target = out[c, f]
        if keep[c]:
            target[:] = previous[c, f]
        elif geometric[f]:
            target[:] = features[f]
        elif f == albedo_row:
            target[:] = albedo[c]
        elif f == emission_row:
            for p in range(target.shape[0]):
                target[p] = emitted[c, p] * inv[c]
        elif direct_row <= f < direct_row + 9:
            scale = np.float32(inv[c])
            for p in range(target.shape[0]):
                target[p] = direct[c, f - direct_row, p] * scale
        elif bounce_row <= f < bounce_row + 9:
            for p in range(target.shape[0]):
                target[p] = bounce[p, f - bounce_row, c] * inv[c]
        elif seen_row <= f < seen_row + 9:
            for p in range(target.shape[0]):
                target[p] = seen[p, f - seen_row, c] * inv[c]
        elif f == open_row:
            target[:] = opened


def direct_light(bases: list[np.ndarray], radiances: list[np.ndarray], sun: np.ndarray | None,
                 visible: np.ndarray | None, probes: int) -> np.ndarray:
    """(3, 9, P) float32: the sum of each basis (9, P) times its radiance (3,), plus `sun` (3, 9) (the
    sun's SH per colour) times its `visible` share at each probe (P,), where given: one compiled pass a
    term on one core (a lamp and the sun on a 24^3 lattice: 0.26 -> 0.19 ms, where numpy made a product
    and a sum a colour; waking the other core for passes this short took longer than they do, 0.35)."""
    out = np.zeros((3, sh.SH_COUNT, probes), np.float32)
    for basis, radiance in zip(bases, radiances):
        _add_scaled(out, np.ascontiguousarray(basis, np.float32), np.asarray(radiance, np.float32))
    if sun is not None:
        _add_outer(out, np.asarray(sun, np.float32), np.ascontiguousarray(visible, np.float32))
    return out


@numba.njit(cache=True, nogil=True)
def _add_scaled(out, basis, radiance):
    """out[c, k] += radiance[c] x basis[k]."""
    rows = out.shape[1]
    for job in range(out.shape[0] * rows):
        c, k = job // rows, job % rows
        weight, target, source = radiance[c], out[c, k], basis[k]
        if weight != 0.0:
            for p in range(target.shape[0]):
                target[p] += weight * source[p]


@numba.njit(cache=True, nogil=True)
def _add_outer(out, weights, visible):
    """out[c, k] += weights[c, k] x visible."""
    rows = out.shape[1]
    for job in range(out.shape[0] * rows):
        c, k = job // rows, job % rows
        weight, target = weights[c, k], out[c, k]
        if weight != 0.0:
            for p in range(target.shape[0]):
                target[p] += weight * visible[p]

"""Which probes of a lattice see a point, swept outward from it, with rays traced only at shadows' edges.

A lamp's visibility from every probe of an m^3 lattice is m^3 segments a ray end: 1.8 million for a
ceiling lamp of 129 clusters on 24^3 probes, 60 ms of a new scene. Most of them say what their
neighbours say. So the probes are visited in shells of growing Chebyshev distance from the lattice point
nearest the end (its origin), and each takes the visibility of the probes one step back along its line to
the end (up to eight, weighted by where the line passes between them), each through the lattice edge
that joins them, traced once per geometry (`LatticeSight.clear`). Where that blend is 0 or 1 the probe
takes it; where the neighbours disagree, at a shadow's edge, its own segment is traced, so a blurred
penumbra never spreads further out. The probes within SEED_CELLS of the origin are traced.

The answers are those of `VoxelRays.pairs_clear` where traced; the others are inferred from the lattice
and differ from their own segments' in up to 3 pairs in 10,000 (a segment that grazes an object between
the lattice's edges; none in the Cornell box: tests/rays/test_lattice_sight.py), from 4-8% of the rays.
The generator's validation rooms: 48 -> 16 ms for 66 ray ends, 60 -> 23 ms for 129 (the edges included).

After a move the lattice's edges that miss the box around the moved triangles keep their answers, and a
ray end asked again starts from its previous answers and settles again only the probes whose answer can
have changed: those with a changed edge, those whose traced segment passes through the box, and those
that read a probe whose answer changed. A sphere moved in a room of 66 ray ends settles about 80 probes a
ray end of 13,824 (the sweep 5.1 -> 1.6 ms, the same answers as a fresh sweep).
"""

from __future__ import annotations

import numba
import numpy as np

from viewer.rays import embree, packets
from viewer.rays.landing import meets_box
from viewer.rays.voxel_rays import VoxelRays, segment_clear, segment_lane

SEED_CELLS = 2
"""Probes within this Chebyshev distance (lattice cells) of a ray end's origin trace their own segment:
near it the line to the origin and the line to the end part by more than a cell."""
SWEEP_ENDS = 24
"""Ray ends from which a scene's probe visibility is swept. The lattice's edges cost 3-4 ms on 24^3
probes, once per geometry, and a ray end swept 0.1-0.2 ms; traced in packets (`VoxelRays.pairs_clear`)
its segments cost 0.2-0.45 ms: the Cornell box's 16 ends 3.6 ms traced against 5.9 swept, a room's 18
ends 5.8 against 6.2, 42-49 ends 9-12 against 8-10, 66 ends 28.5 against 16.5."""
SOFT = 1e-4
"""A blend of the neighbours' visibility within this of 0 or 1 is taken as it is; between, the probe's
own segment is traced."""
SELF = 13
"""The index of the zero offset among the 27 neighbour offsets ((a + 1) x 9 + (b + 1) x 3 + (c + 1))."""


def sweeps(blockers: VoxelRays | None, ends: int) -> bool:
    """Whether a scene of `ends` ray ends has its probes' visibility swept (`LatticeSight`): SWEEP_ENDS of
    them or more, and occluders that Embree's compiled queries trace."""
    return (ends >= SWEEP_ENDS and blockers is not None and blockers.caster is not None
            and blockers.caster.direct is not None)


class LatticeSight:
    """The lattice's edges (which neighbouring probes see each other) for one set of occluders, and the
    sweep of a ray end's visibility over its probes."""

    def __init__(self, blockers: VoxelRays, points: np.ndarray, lo: np.ndarray, spacing: np.ndarray,
                 previous: "LatticeSight | None" = None, box=None):
        """`points` (m^3, 3): the lattice's probes, lo + (index + 0.5) x spacing at flat index (i x m + j) x m
        + k, as `ProbeGrid.positions_for` lays them out. `previous`, `box`: the same lattice's sight before
        only the triangles within the box (lo, hi) moved: the edges that miss the box keep their answers."""
        self.blockers, self.lo, self.spacing = blockers, np.asarray(lo, np.float64), np.asarray(spacing, np.float64)
        self.points = np.ascontiguousarray(points, np.float64)
        self.m = round(len(self.points) ** (1 / 3))
        if self.m ** 3 != len(self.points):
            raise ValueError(f"{len(self.points)} points are not a cubic lattice")
        cells = blockers.cells
        self._trace = (*blockers.caster.direct.occlusion, blockers.box_table(len(self.points) * 13),
                       np.asarray(cells.lo, np.float64), float(cells.h))
        kept = previous is not None and box is not None and np.array_equal(previous.points, self.points)
        self.clear = previous.clear.copy() if kept else np.zeros((len(self.points), 27), np.bool_)
        """(P, 27) whether the segment from each probe to each neighbour (offset index (a + 1) x 9 + (b + 1)
        x 3 + (c + 1)) crosses no surface; False past the lattice's faces."""
        box_lo, box_hi = ((np.asarray(box[0], np.float64), np.asarray(box[1], np.float64)) if kept
                          else (np.zeros(3), np.zeros(3)))
        query, scene, table, cell_lo, h = self._trace
        changed = np.ones(len(self.points), np.bool_) if not kept else np.zeros(len(self.points), np.bool_)
        _edges(query, scene, self.points, self.m, self.spacing, table, cell_lo, h, kept, box_lo, box_hi, self.clear,
               changed)
        self.changed_edges = np.flatnonzero(changed).astype(np.int32)
        """The probes any of whose edges changed from the previous sight's (all where there was none): a
        kept ray end's sweep settles them again."""

    def origins(self, targets: np.ndarray) -> np.ndarray:
        """(C, 3) int64 the lattice index nearest each ray end (C, 3), clamped to the lattice."""
        return np.clip(np.rint((targets - self.lo) / self.spacing - 0.5), 0, self.m - 1).astype(np.int64)

    def visibility(self, targets: np.ndarray, before=None) -> tuple[np.ndarray, np.ndarray, int]:
        """((C, P) float32 1 where probe p sees ray end c, (C, P) bool where its segment was traced, how
        many were traced). `before`: (box lo, box hi, rows (C, P), traced (C, P), kept (C,) bool), the
        answers of the same ends before only the triangles in the box moved: a segment traced then that
        does not pass through the box keeps its answer, so the sweep gives what a fresh one gives."""
        targets = np.ascontiguousarray(np.asarray(targets, np.float64).reshape(-1, 3))
        out = np.zeros((len(targets), len(self.points)), np.float32)
        traced = np.zeros(out.shape, np.bool_)
        count = np.zeros(len(targets), np.int64)
        if before is None:
            empty = np.zeros(3)
            before = (empty, empty, out[:0], traced[:0], np.zeros(len(targets), np.bool_))
        box_lo, box_hi, rows, marks, kept = before
        query, scene, table, cell_lo, h = self._trace
        coords = (targets - self.lo) / self.spacing - 0.5
        _sweep(query, scene, self.blockers.caster.direct.occlusion8[0], self.points, self.m, targets, coords,
               self.origins(targets), self.clear, table, cell_lo, h, SEED_CELLS, SOFT, np.asarray(box_lo, np.float64),
               np.asarray(box_hi, np.float64), rows, marks, np.asarray(kept, np.bool_), self.changed_edges,
               _spread(kept), out, traced, count)
        return out, traced, int(count.sum())


def _spread(kept: np.ndarray) -> np.ndarray:
    """The order the sweep takes its ray ends in: the fresh ones (a whole sweep each, where a kept one
    settles a few probes again) spread evenly through it, so that each core's even share of the tasks
    holds its share of them."""
    kept = np.asarray(kept, np.bool_)
    order = np.concatenate([np.flatnonzero(~kept), np.flatnonzero(kept)])
    return np.concatenate([order[0::2], order[1::2]])


@numba.njit(cache=True, nogil=True, parallel=True)
def _edges(query, scene, points, m, spacing, table, lo, h, kept, box_lo, box_hi, out, changed):
    """out[p, o]: the segment from probe p to its neighbour at offset o is clear (each edge traced once,
    from the probe at its negative end; with `kept`, only the edges through the box, the others as `out`
    holds them, and `changed` marks the probes at both ends of an edge whose answer changed)."""
    for p in numba.prange(points.shape[0]):
        record = embree.record()
        i, j, k = p // (m * m), (p // m) % m, p % m
        out[p, SELF] = True
        if kept:   # every edge of p lies within a cell of it
            apart = False
            for axis in range(3):
                if points[p, axis] - spacing[axis] > box_hi[axis] or points[p, axis] + spacing[axis] < box_lo[axis]:
                    apart = True
            if apart:
                continue
        for o in range(SELF + 1, 27):
            a, b, c = o // 9 - 1, (o // 3) % 3 - 1, o % 3 - 1
            qi, qj, qk = i + a, j + b, k + c
            if qi < 0 or qi >= m or qj < 0 or qj >= m or qk < 0 or qk >= m:
                continue
            q = (qi * m + qj) * m + qk
            if kept and not meets_box(points[p, 0], points[p, 1], points[p, 2], points[q, 0] - points[p, 0],
                                      points[q, 1] - points[p, 1], points[q, 2] - points[p, 2], 1.0, box_lo, box_hi):
                continue
            clear = segment_clear(query, scene, record, table, lo, h, points[p, 0], points[p, 1], points[p, 2],
                                   points[q, 0], points[q, 1], points[q, 2])
            if kept and clear != out[p, o]:
                changed[p] = True
                changed[q] = True
            out[p, o] = clear
            out[q, 26 - o] = clear


@numba.njit(cache=True, nogil=True, inline="always")
def _blend(row, clear, m, p, ui, uj, uk):
    """The visibility probe p takes from the probes one step back along the line to the ray end, which
    lies (ui, uj, uk) lattice cells away: a whole step along the axis the line runs most along, and
    along each other one the two lattice positions either side of where the line crosses, weighted
    linearly; each neighbour through its lattice edge."""
    ai, aj, ak = abs(ui), abs(uj), abs(uk)
    top = max(ai, aj, ak)
    si, sj, sk = (1 if ui > 0 else -1), (1 if uj > 0 else -1), (1 if uk > 0 else -1)
    fi, fj, fk = ai / top, aj / top, ak / top
    total = 0.0
    for bi in range(2):
        wi = fi if bi == 1 else 1.0 - fi
        if wi <= 0.0:
            continue
        for bj in range(2):
            wj = fj if bj == 1 else 1.0 - fj
            if wj <= 0.0:
                continue
            for bk in range(2):
                wk = fk if bk == 1 else 1.0 - fk
                if wk <= 0.0:
                    continue
                a, b, c = si * bi, sj * bj, sk * bk
                if clear[p, (a + 1) * 9 + (b + 1) * 3 + c + 1]:
                    total += wi * wj * wk * row[p + (a * m + b) * m + c]
    return total


@numba.njit(cache=True, nogil=True, inline="always")
def _blended(row, mark, clear, m, p, t, i, j, k, soft):
    """Settle probe p = (i, j, k) from the blend of the probes one step back towards the ray end (at
    lattice coordinates `t`) where that is within `soft` of 0 or 1; False, nothing settled, where they
    disagree (its own segment is to be traced)."""
    v = _blend(row, clear, m, p, t[0] - i, t[1] - j, t[2] - k)
    if v <= soft or v >= 1.0 - soft:
        row[p], mark[p] = (0.0 if v <= soft else 1.0), False
        return True
    return False


@numba.njit(cache=True, nogil=True, inline="always")
def _settle(query, scene, record, points, m, end, t, i, j, k, clear, table, lo, h, soft, box_lo, box_hi, old,
            old_traced, traced_near, row, mark):
    """Probe (i, j, k)'s visibility of ray end `end` (world) at lattice coordinates `t` again after a move,
    into row: traced where `traced_near` or the blend is neither 0 nor 1, the answer of `old` reused where
    that traced it and the segment misses the moved box. Returns 1 where a segment was traced."""
    p = (i * m + j) * m + k
    if not traced_near and _blended(row, mark, clear, m, p, t, i, j, k, soft):
        return 0
    mark[p] = True
    px, py, pz = points[p, 0], points[p, 1], points[p, 2]
    tx, ty, tz = end[0], end[1], end[2]
    if old_traced[p] and not meets_box(px, py, pz, tx - px, ty - py, tz - pz, 1.0, box_lo, box_hi):
        row[p] = old[p]
        return 0
    row[p] = 1.0 if segment_clear(query, scene, record, table, lo, h, px, py, pz, tx, ty, tz) else 0.0
    return 1


@numba.njit(cache=True, nogil=True, inline="always")
def _traced_together(query8, scene, packet, points, end, pending, count, table, lo, h, row, mark):
    """Trace the segments from the probes pending[:count] to `end` into row (1: clear) and mark them
    traced, packets.LANES at a time (rtcOccluded8; a segment in cells no triangle reaches is clear
    untraced, as `segment_clear` takes it). Returns count."""
    lanes = packets.LANES
    o, d = np.empty((lanes, 3)), np.empty((lanes, 3))
    length, asked, blocked = np.empty(lanes), np.empty(lanes, np.bool_), np.empty(lanes, np.bool_)
    for first in range(0, count, lanes):
        some = False
        for lane in range(lanes):
            asked[lane] = False
            if first + lane >= count:
                continue
            p = pending[first + lane]
            mark[p] = True
            asked[lane] = segment_lane(o, d, length, lane, table, lo, h, points[p, 0], points[p, 1], points[p, 2],
                                       end[0], end[1], end[2])
            if not asked[lane]:
                row[p] = 1.0
            some |= asked[lane]
        if some:
            packets.occluded8(query8, scene, packet, o, d, length, asked, blocked)
            for lane in range(lanes):
                if asked[lane]:
                    row[pending[first + lane]] = 0.0 if blocked[lane] else 1.0
    return count


@numba.njit(cache=True, nogil=True, inline="always")
def _order(i, j, k, oi, oj, ok):
    """The sweep's order of probe (i, j, k) about the origin (oi, oj, ok): 3 r + the count of the shell's
    faces it lies on, r its Chebyshev distance (the origin 3, then shell 1's faces, edges, corners...)."""
    di, dj, dk = abs(i - oi), abs(j - oj), abs(k - ok)
    r = max(di, dj, dk)
    return 3 * r + (di == r) + (dj == r) + (dk == r)


@numba.njit(cache=True, nogil=True, inline="always")
def _queue(p, m, oi, oj, ok, queued, head, following):
    if not queued[p]:
        _queued(p, _order(p // (m * m), (p // m) % m, p % m, oi, oj, ok), queued, head, following)


@numba.njit(cache=True, nogil=True, inline="always")
def _queued(p, key, queued, head, following):
    """Queue probe p, of order `key`, to be settled again."""
    queued[p] = True
    following[p] = head[key]
    head[key] = p


@numba.njit(cache=True, nogil=True, inline="always")
def _settle_again(query, scene, record, points, m, end, t, origin, clear, table, lo, h, seed, soft, box_lo, box_hi,
                  old, old_traced, changed_edges, row, mark):
    """A kept ray end's sweep (`row` and `mark` start as its previous answers): only the probes whose
    answer can have changed are settled again, in the sweep's order: those with a changed edge, those
    whose traced segment passes through the moved box, and those that read a probe whose answer changed
    (queued as it changes: a probe's readers come later in the order). Returns the segments traced."""
    oi, oj, ok = origin[0], origin[1], origin[2]
    count = points.shape[0]
    queued = np.zeros(count, np.bool_)
    following = np.empty(count, np.int32)
    head = np.full(3 * m + 4, -1, np.int32)
    for p in changed_edges:
        _queue(p, m, oi, oj, ok, queued, head, following)
    for p in range(count):
        if old_traced[p] and not queued[p]:
            px, py, pz = points[p, 0], points[p, 1], points[p, 2]
            if meets_box(px, py, pz, end[0] - px, end[1] - py, end[2] - pz, 1.0, box_lo, box_hi):
                _queue(p, m, oi, oj, ok, queued, head, following)
    n = 0
    for key in range(head.shape[0]):
        while head[key] >= 0:
            p = head[key]
            head[key] = following[p]
            i, j, k = p // (m * m), (p // m) % m, p % m
            near = max(abs(i - oi), abs(j - oj), abs(k - ok)) <= seed
            was = row[p]
            n += _settle(query, scene, record, points, m, end, t, i, j, k, clear, table, lo, h, soft, box_lo, box_hi,
                         old, old_traced, near, row, mark)
            if row[p] != was:
                for a in range(max(i - 1, 0), min(i + 2, m)):
                    for b in range(max(j - 1, 0), min(j + 2, m)):
                        for c in range(max(k - 1, 0), min(k + 2, m)):
                            # its order is known here: no 64-bit divisions to find it again (a floor
                            # lamp's ends under a moved wedge: their sweep 9-12% faster)
                            order, q = _order(a, b, c, oi, oj, ok), (a * m + b) * m + c
                            if order > key and not queued[q]:
                                _queued(q, order, queued, head, following)
    return n


@numba.njit(cache=True, nogil=True, parallel=True)
def _sweep(query, scene, query8, points, m, targets, coords, origins, clear, table, lo, h, seed, soft, box_lo,
           box_hi, old_rows, old_traced, kept, changed_edges, order, out, traced, count):
    """`LatticeSight.visibility`, one ray end a task: the shells around its origin in order of Chebyshev
    distance r, and in each shell first the probes on one of its faces alone, then those on two (its
    edges), then its corners, so that every probe a blend reads is settled before it (a probe's step
    back leaves it on the shell only along an axis where it is on the shell's face, and then on fewer of
    them). A fresh ray end's probes of one such class of a shell read none of each other, so those whose
    blend leaves them undecided are traced together after it, eight at a time (`_traced_together`). A
    kept ray end starts from its previous answers and settles again only the probes whose answer can
    have changed (`_settle_again`): after a small object moved, one to three in a hundred."""
    for task in numba.prange(targets.shape[0]):
        c = order[task]
        record, packet = embree.record(), packets.packet()
        end, t = targets[c], coords[c]
        oi, oj, ok = origins[c, 0], origins[c, 1], origins[c, 2]
        row, mark = out[c], traced[c]
        if kept[c]:
            row[:] = old_rows[c]
            mark[:] = old_traced[c]
            count[c] = _settle_again(query, scene, record, points, m, end, t, origins[c], clear, table, lo, h, seed,
                                     soft, box_lo, box_hi, old_rows[c], old_traced[c], changed_edges, row, mark)
            continue
        top = max(oi, m - 1 - oi, oj, m - 1 - oj, ok, m - 1 - ok)
        pending = np.empty(points.shape[0], np.int64)
        pending[0] = (oi * m + oj) * m + ok
        n = _traced_together(query8, scene, packet, points, end, pending, 1, table, lo, h, row, mark)
        for r in range(1, top + 1):
            near = r <= seed
            for faces in range(1, 4):
                waiting = 0
                for i in range(max(0, oi - r), min(m, oi + r + 1)):
                    for j in range(max(0, oj - r), min(m, oj + r + 1)):
                        on = (abs(i - oi) == r) + (abs(j - oj) == r)
                        if on == faces:   # off the shell's k faces
                            k0, k1, step = max(ok - r + 1, 0), min(ok + r - 1, m - 1), 1
                        elif on == faces - 1:   # on them
                            k0, k1, step = ok - r, ok + r, 2 * r
                        else:
                            continue
                        for k in range(k0, k1 + 1, step):
                            if 0 <= k < m:
                                p = (i * m + j) * m + k
                                if near or not _blended(row, mark, clear, m, p, t, i, j, k, soft):
                                    pending[waiting] = p
                                    waiting += 1
                n += _traced_together(query8, scene, packet, points, end, pending, waiting, table, lo, h, row, mark)
        count[c] = n

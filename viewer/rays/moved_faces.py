"""Which faces moved between two versions of a scene (a dragged lamp or object: the same faces, some
elsewhere), and the box around their old and new places: what every stage that keeps its work across
a move asks first (the ray casters, the voxels, the occluders' rays, the solver's retrace, the renderer's
gather rays and probe weights).
"""

from __future__ import annotations

import weakref

import numba
import numpy as np

from viewer.threads import RUNS, cores_for


def changed_rows(*pairs) -> np.ndarray:
    """(F,) bool: the rows where the two arrays of any pair (a, b), each (F, ...), differ: the faces that
    moved between two scenes, in one compiled pass (on a 272k-triangle scan 0.9 ms, where numpy's
    comparison and reduction took 5.3). The answer for read-only arrays is kept, read-only, for the next
    call with the same arrays: a move's stages (voxels, cells, ray casters, retrace) ask it of the same
    scenes' edges four or five times, 5 ms each on a million triangles."""
    global _last
    arrays = [x for pair in pairs for x in pair]
    kept = _last
    if kept is not None and len(kept[0]) == len(arrays) and all(r() is a for r, a in zip(kept[0], arrays)):
        return kept[1]
    out = np.zeros(len(pairs[0][0]), np.bool_)
    for a, b in pairs:
        if np.shape(a) != np.shape(b) or len(a) != len(out):
            raise ValueError(f"rows of shapes {np.shape(a)} and {np.shape(b)} cannot be compared row by row")
        if a is not b:
            with cores_for(np.size(a)):   # a box room's faces: fewer than waking the other threads takes
                _changed(np.ascontiguousarray(a).reshape(len(a), -1), np.ascontiguousarray(b).reshape(len(b), -1), out)
    if all(_frozen(a) for a in arrays):
        out.setflags(write=False)
        _last = ([weakref.ref(a) for a in arrays], out)
    return out


_last: tuple | None = None
"""(weak references to the arrays last compared, read-only, and the answer)."""


PARTIAL_SHARE, PARTIAL_FACES = 0.1, 32
"""A move of at most this share of the faces, or of at most this many whatever their share, traces again
only the final-gather rays it can change (viewer/gpu/indirect_bake.py): a ray near the moved faces is
tested against each of them (`GatherRays.after_moving`), a few nanoseconds a face, where tracing it again
through Embree takes a few hundred. A box room's moved box is 12 of its 36 faces: the Cornell box's
settled frame after it 460-491 -> 379-395 ms with the network, 578-605 -> 456-471 with the compute solver
(`python -m viewer.bench.edits cornell --edits "object move"`, by turns), where the share alone traced
every ray again."""


def few_moved(before: np.ndarray, after: np.ndarray, keep: np.ndarray) -> np.ndarray | None:
    """The places among the `keep` faces (F,) bool of those whose triangles (F, 3, 3) moved from `before` to
    `after`, where they are few enough to trace again only what they change (PARTIAL_SHARE,
    PARTIAL_FACES); None where they are not."""
    moved = np.flatnonzero(changed_rows((before, after))[keep])
    return moved if len(moved) <= max(PARTIAL_SHARE * keep.sum(), PARTIAL_FACES) else None


def _frozen(array) -> bool:
    """Whether nothing can change `array`'s values: it and every array it views into are read-only."""
    while isinstance(array, np.ndarray):
        if array.flags.writeable:
            return False
        array = array.base
    return True


@numba.njit(cache=True, nogil=True, parallel=True)
def _changed(a, b, out):
    for r in numba.prange(a.shape[0]):
        if not out[r]:
            for k in range(a.shape[1]):
                if a[r, k] != b[r, k]:
                    out[r] = True
                    break


def moved_box(before, after, least: float = 1e-9, most: float = 1.0) -> tuple[np.ndarray, np.ndarray | None] | None:
    """(moved, box) between `before` and `after`, each with the faces' (v0, e1, e2) (ray casters or cell
    listings of the same faces): the faces that moved, and (2, 3) the corners of a box around their old
    and new places, wider by a millionth of the larger of its extent and `least` (None where none moved).
    None where the faces differ, or where more than the share `most` of them moved (a caller that then
    starts afresh needs no box)."""
    if before.v0.shape != after.v0.shape:
        return None
    moved = np.flatnonzero(changed_rows((before.v0, after.v0), (before.e1, after.e1), (before.e2, after.e2)))
    if len(moved) > most * len(after.v0):
        return None
    if len(moved) == 0:
        return moved, None
    lo, hi = np.full(3, np.inf), np.full(3, -np.inf)
    for c in (before, after):
        with cores_for(len(moved)):
            parts = _corner_boxes(moved, *(np.ascontiguousarray(a, np.float64) for a in (c.v0, c.e1, c.e2)))
        lo, hi = np.minimum(lo, parts[:, 0].min(axis=0)), np.maximum(hi, parts[:, 1].max(axis=0))
    margin = 1e-6 * max(float((hi - lo).max()), least)
    return moved, np.array([lo - margin, hi + margin])


@numba.njit(cache=True, nogil=True, parallel=True)
def _corner_boxes(faces, v0, e1, e2):
    """(RUNS, 2, 3) the lowest and highest corners v0, v0 + e1, v0 + e2 of each run of `faces`: one
    pass over the moved faces on every core (numpy's reduction of a (3 F, 3) array down its rows took 116
    ms for a 272k-triangle scan moved; one core's pass, 9 ms for a million-triangle one)."""
    out = np.empty((RUNS, 2, 3))
    out[:, 0], out[:, 1] = np.inf, -np.inf
    step = (len(faces) + RUNS - 1) // RUNS
    for run in numba.prange(RUNS):
        for i in range(run * step, min((run + 1) * step, len(faces))):
            f = faces[i]
            for k in range(3):
                a = v0[f, k]
                b, c = a + e1[f, k], a + e2[f, k]
                out[run, 0, k] = min(out[run, 0, k], a, b, c)
                out[run, 1, k] = max(out[run, 1, k], a, b, c)
    return out


def translation(corners: np.ndarray, edges: tuple, rows: np.ndarray) -> np.ndarray | None:
    """(3,) float32 t where the faces `rows` of a scene whose `edges` are (v0, e1, e2) (each (F, 3)) now lie
    at `corners` (R, 3, 3) float32 (where a ray hierarchy was built of them) plus t, each corner within a
    few float32 ulps of the largest coordinate involved: a dragged object, whose hierarchy then serves
    moved by t (an instance's transform, viewer.rays.embree) instead of being built again. None where
    they moved otherwise (turned, scaled, reshaped) or `rows` is empty."""
    if len(rows) == 0 or len(corners) != len(rows):
        return None
    rows = np.ascontiguousarray(rows, np.int64)
    v0, e1, e2 = (np.ascontiguousarray(a, np.float64) for a in edges)
    shift = (v0[rows[0]] - corners[0, 0]).astype(np.float32)
    with cores_for(len(rows)):
        error, size = _off_shift(np.ascontiguousarray(corners, np.float32), v0, e1, e2, rows, shift.astype(np.float64))
    return shift if error <= 8 * np.finfo(np.float32).eps * size else None


@numba.njit(cache=True, nogil=True, parallel=True)
def _off_shift(corners, v0, e1, e2, rows, shift):
    """(the largest |corner now - corner then - shift|, the largest |coordinate| of either) over the `rows`'
    corners, in one pass on every core."""
    worst = np.zeros(rows.shape[0])
    size = np.zeros(rows.shape[0])
    for i in numba.prange(rows.shape[0]):
        f = rows[i]
        for k in range(3):
            a = v0[f, k]
            for j in range(3):
                now = a if j == 0 else (a + e1[f, k] if j == 1 else a + e2[f, k])
                then = np.float64(corners[i, j, k])
                worst[i] = max(worst[i], abs(now - then - shift[k]))
                size[i] = max(size[i], abs(now), abs(then))
    return worst.max(), size.max()

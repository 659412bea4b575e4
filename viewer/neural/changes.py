"""What an `Encoder` (viewer/neural/encoder.py) compares between two calls to find what an edit changed:
the sun, the colour columns of the voxels' albedo and emission, the voxels that kept their surface, a
lamp's patches by their identity, and which voxels' light from a lamp holds through a move.
"""

from __future__ import annotations

import weakref
from dataclasses import fields

import numpy as np

from viewer.rays.voxels import VoxelGrid


def sun_parts(sun) -> tuple[np.ndarray | None, np.ndarray]:
    if sun is None:
        return None, np.zeros(3)
    return np.asarray(sun.direction, np.float64), np.asarray(sun.irradiance, np.float64)


def same_direction(a, b) -> bool:
    if a is None or b is None:
        return a is None and b is None
    return bool(np.array_equal(a, b))


def same_sun(a, b) -> bool:
    return same_direction(a[0], b[0]) and np.array_equal(a[1], b[1])


def same_columns(a: np.ndarray | None, b: np.ndarray) -> np.ndarray:
    """(3,) whether each colour column of two (K, 3) arrays is equal."""
    if a is None or a.shape != b.shape:
        return np.zeros(3, bool)
    return np.array([np.array_equal(a[:, c], b[:, c]) for c in range(3)])


def proportional_channels(before, after) -> np.ndarray:
    """(3,) per colour channel: whether all the light of `after` (voxel emission (K, 3), sun irradiance
    (3,)) is that of `before` times one positive factor, or both are dark: then the scale-out leaves
    the pass's inputs as they were."""
    out = np.zeros(3, bool)
    if before[0] is None or before[0].shape != after[0].shape:
        return out
    for c in range(3):
        old = np.append(before[0][:, c], before[1][c])
        new = np.append(after[0][:, c], after[1][c])
        top_old, top_new = np.abs(old).max(), np.abs(new).max()
        if top_old == 0 or top_new == 0:
            out[c] = top_old == top_new
            continue
        factor = top_new / top_old
        out[c] = np.abs(new - factor * old).max() <= 1e-12 * top_new
    return out


_last_match: tuple = (None, None, None)
"""(weak references to the last two voxel lists matched, the answer): a move matches them for the seen
rays and again for the voxels' shadows."""


def same_voxels(old: VoxelGrid, new: VoxelGrid) -> np.ndarray:
    """(K_new,) the row of `old`'s voxel at the same grid cell as each of `new`'s with the same surface in
    it (its position and normal), -1 elsewhere (read-only; the last answer kept). A cell holds a voxel for
    each way its surfaces face, under one hash id; both lists are in hash id order, as voxelizing lays
    them out (sorted here where not)."""
    global _last_match
    kept_old, kept_new, answer = _last_match
    if kept_old is not None and kept_old() is old and kept_new() is new:
        return answer
    answer = _matched(old, new)
    answer.flags.writeable = False
    _last_match = (weakref.ref(old), weakref.ref(new), answer)
    return answer


def _matched(old: VoxelGrid, new: VoxelGrid) -> np.ndarray:
    old_id, new_id = old.hash_id, new.hash_id
    out = np.full(len(new_id), -1)
    order = None if np.all(old_id[1:] >= old_id[:-1]) else np.argsort(old_id, kind="stable")
    first = np.searchsorted(old_id, new_id, "left", sorter=order)
    runs = np.searchsorted(old_id, new_id, "right", sorter=order) - first
    for step in range(int(runs.max(initial=0))):
        open_ = np.flatnonzero((out < 0) & (runs > step))
        at = first[open_] + step
        if order is not None:
            at = order[at]
        same = (np.all(old.position[at] == new.position[open_], axis=1)
                & np.all(old.normal[at] == new.normal[open_], axis=1))
        out[open_[same]] = at[same]
    return out


def patch_keys(position, normal, area, target) -> list[bytes]:
    """A patch's identity across edits: its position, normal, area and the end of its visibility ray
    (equal patches, should two ever coincide, are told apart by their order)."""
    keys = [row.tobytes() for row in np.column_stack([position, normal, area, target])]
    if len(set(keys)) < len(keys):
        seen: dict[bytes, int] = {}
        for e, key in enumerate(keys):
            seen[key] = seen.get(key, -1) + 1
            keys[e] = key + bytes([seen[key] % 256]) * (seen[key] > 0)
    return keys


def kept_received(before: tuple | None, received: np.ndarray, lit: tuple) -> tuple[np.ndarray, np.ndarray] | None:
    """An emitter's light at the voxels (`received` (K,)) made with `before` and now to be made with `lit`
    (`Emitter.lit`: the voxels, their visibility rows, each patch's row, the patches' pieces): the voxels
    whose values must be summed again (those that lost their surface or whose rows changed), and the
    kept values at the others; None where every value must be summed again (other pieces, another
    voxel size, nothing before)."""
    if before is None or before[0].count == 0:
        return None
    (old_voxels, old_visible, old_rows, old_pieces), (voxels, visible, rows, pieces) = before, lit
    if old_voxels.voxel_size != voxels.voxel_size or not all(
            np.array_equal(getattr(old_pieces, f.name), getattr(pieces, f.name)) for f in fields(pieces)):
        return None
    match = same_voxels(old_voxels, voxels)
    at = np.maximum(match, 0)
    redo = (match < 0) | rows_changed(old_visible, old_rows, visible, rows, at)
    return np.flatnonzero(redo), received[at]


def rows_changed(before: np.ndarray, before_rows: np.ndarray, now: np.ndarray, rows: np.ndarray,
                 at: np.ndarray | None = None) -> np.ndarray:
    """(P,) bool: the points (columns of `now` (R, P)) where some patch's visibility differs, patch e
    reading row `before_rows[e]` of `before` then and row `rows[e]` of `now` now; `at` (P,): the column
    of `before` each point was (None: the same)."""
    out = np.zeros(now.shape[1], bool)
    for old, new in set(zip(np.asarray(before_rows).tolist(), np.asarray(rows).tolist())):
        out |= (before[old] if at is None else before[old, at]) != now[new]
    return out

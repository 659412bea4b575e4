"""Where rays land: the voxel of the surface a ray meets, from the face Embree names and the voxel listing
(viewer/rays/voxel_rays.py), for bundles of rays cast from compiled loops.
"""

from __future__ import annotations

import numba
import numpy as np

from viewer.rays import dda, embree
from viewer.rays.packets import LANES, closest8, packet
from viewer.rays.sides import NO_FACE, facing_face, first_face
from viewer.rays.listing import NEIGHBOUR_ORDER
from viewer.threads import cores_for

FAR = 1e37
"""The length of a ray that goes on until it meets something (Embree's own default)."""
STEP_BACK = 1e-4
"""The hit point is read this many voxels back along the ray before its cell is looked up, so that a
hit on a cell's boundary is the first cell's (the one the ray crossed first, as the DDA reads it), and
single precision (about 1e-6 voxels at the grid's far side) cannot move it across."""


@numba.njit(cache=True, nogil=True)
def landed(o, d, face, t, front, lo, h, n, first, triangle, voxel):
    """`voxel_of` each hit."""
    out = np.empty(face.shape[0], np.int64)
    for r in range(face.shape[0]):   # one thread: a few lookups a ray, beside Embree's traversal
        out[r] = voxel_of(o[r, 0], o[r, 1], o[r, 2], d[r, 0], d[r, 1], d[r, 2], face[r], t[r], front[r], lo, h, n,
                          first, triangle, voxel)
    return out


@numba.njit(cache=True, nogil=True, parallel=True)
def bundle(o, d, intersect, scene, faces, e1, e2, twin, v0, lo, h, n, first, triangle, voxel, out):
    """out[p, k]: the voxel that ray k of origin p meets first (d (P, D, 3), or (1, D, 3) shared), traced
    through Embree as it is made (viewer.rays.embree) and looked up at once, on every core."""
    step = 0 if d.shape[0] == 1 else 1
    for p in numba.prange(o.shape[0]):
        record, q = embree.record(), p * step
        for k in range(d.shape[1]):
            dx, dy, dz = d[q, k, 0], d[q, k, 1], d[q, k, 2]
            f, t, _, _, front = first_face(intersect, scene, record, faces, e1, e2, twin, v0, o[p, 0], o[p, 1],
                                           o[p, 2], dx, dy, dz, FAR)
            out[p, k] = voxel_of(o[p, 0], o[p, 1], o[p, 2], dx, dy, dz, f, t, front, lo, h, n, first, triangle, voxel)


UNKNOWN = -3
"""A kept ray's voxel before it is found (neither a voxel, dda.MISS nor dda.BACKFACE)."""


def bundle_kept(o, d, which, kept, box_lo, box_hi, old_face, old_t, old_hits, remap, intersect, scene, faces, e1, e2,
                twin, v0, lo, h, n, first, triangle, voxel, out, face, t, none, sources, backs, in_place):
    """`_bundle` for directions d[which[p]] from origin p (d (S, D, 3)), keeping each ray's face and t:
    with `kept`, a ray that does not pass through the box [box_lo, box_hi] before its old hit
    (`old_face`, `old_t`) keeps them, and its voxel is the one it landed on before (`old_hits` (P, D),
    empty: looked up again) under its new index (`remap`: each old voxel's, -1 where the voxel changed:
    looked up again); the others are traced. Also `sources`: the hits with `none` for a miss or a back
    face, and `backs` (P,): how many of each origin's rays met a back face. Returns (P,) how many rays of
    each origin were traced. `in_place`: `face`, `t` and `out` are `old_face`, `old_t` and `old_hits`, whose
    kept rays' faces and distances are then neither read nor written (a kept ray past the sphere test
    reads nothing but its old voxel).

    Three passes: every ray's old voxel under its new index, and whether its line passes within the
    sphere around the box (a dot product: most rays point elsewhere); then the rays near the box or whose
    voxel changed, listed and shared evenly among the threads, tested against the box itself and traced
    or looked up again; then each origin's tallies. In one pass over the origins, the rays to trace, which
    bunch up in the origins near the box, fell to one thread: the 885k rays of a moved box in val-00002
    (9.6k traced again) 5.1 -> 4.1 ms on two cores, the 68k-triangle scan's moved bunny (146k) 39 -> 35."""
    count = d.shape[1]
    known = old_hits.shape[0] == o.shape[0]
    centre, reach = 0.5 * (box_lo + box_hi), 0.0
    if kept:
        half = 0.5 * (box_hi - box_lo)
        reach = float(half[0] * half[0] + half[1] * half[1] + half[2] * half[2])
    near = np.empty((o.shape[0], count), np.bool_)
    across = np.ascontiguousarray(np.asarray(d, np.float64).transpose(0, 2, 1))   # each set's x, y, z rows
    listed = _kept_voxels(o, across, which, kept, centre, reach, old_hits, remap, known, old_face, old_t, out, face, t,
                          in_place, near, none, sources, backs)
    starts = np.zeros(o.shape[0] + 1, np.int64)
    starts[1:] = np.cumsum(listed)
    rays = _listed(near, starts)
    met, backed = np.zeros(rays.shape[0], np.bool_), np.zeros(rays.shape[0], np.int8)
    _again(o, d, which, kept, box_lo, box_hi, old_face, old_t, rays, intersect, scene, faces, e1, e2, twin, v0, lo, h,
           n, first, triangle, voxel, out, face, t, none, sources, met, backed)
    with cores_for(o.shape[0]):   # a few additions a listed ray: one thread but for the largest lattices
        return _tallies(starts, met, backed, backs)


@numba.njit(cache=True, nogil=True, parallel=True)
def _kept_voxels(o, d, which, kept, centre, reach, old_hits, remap, known, old_face, old_t, out, face, t, in_place,
                 near, none, sources, backs):
    """`bundle_kept`'s first pass, its directions d (S, 3, D) as each set's rows of x, y and z (so that the
    test along them vectorizes): out[p, k] the ray's old voxel under its new index (UNKNOWN where it
    changed or none is known), `sources` and `backs` of those, its old face and t copied unless `in_place`,
    and near[p, k] whether it is to be tested again: its line passes within the sphere around the box, or
    its voxel is UNKNOWN (the tests as bitwise ors, so that the loop holds no branch). Returns (P,) how
    many of each origin's rays are."""
    listed = np.zeros(o.shape[0], np.int64)
    everything = not kept
    for p in numba.prange(o.shape[0]):
        xs, ys, zs = d[which[p], 0], d[which[p], 1], d[which[p], 2]
        wx, wy, wz = centre[0] - o[p, 0], centre[1] - o[p, 1], centre[2] - o[p, 2]
        gap = wx * wx + wy * wy + wz * wz - reach   # <= 0: the origin is within the sphere
        hits, marked = out[p], near[p]
        if known:
            was_row = old_hits[p]
            for k in range(xs.shape[0]):
                was = was_row[k]
                moved_to = remap[max(was, 0)]
                hits[k] = was if was < 0 else (moved_to if moved_to >= 0 else UNKNOWN)
        else:
            hits[:] = UNKNOWN
        found = back = 0
        for k in range(xs.shape[0]):
            dx, dy, dz = xs[k], ys[k], zs[k]
            along = dx * wx + dy * wy + dz * wz
            hit = hits[k]
            marked[k] = (everything | (hit == UNKNOWN) | (gap <= 0.0)
                         | ((along > 0.0) & (along * along >= gap * (dx * dx + dy * dy + dz * dz))))
            sources[p, k] = none if hit < 0 else hit
            back += hit == dda.BACKFACE
        for k in range(xs.shape[0]):
            found += marked[k]
        if not in_place:
            face[p], t[p] = old_face[p], old_t[p]
        listed[p], backs[p] = found, back
    return listed


@numba.njit(cache=True, nogil=True, parallel=True)
def _listed(near, starts):
    """(N,) the flat indices (origin x D + ray) of the rays `near` marks, origin by origin."""
    out = np.empty(starts[-1], np.int64)
    for p in numba.prange(near.shape[0]):
        at = starts[p]
        if at == starts[p + 1]:
            continue
        for k in range(near.shape[1]):
            if near[p, k]:
                out[at] = p * near.shape[1] + k
                at += 1
    return out


RAYS_A_TASK = 256
"""Listed rays a thread takes at a time in `bundle_kept`'s second pass."""


@numba.njit(cache=True, nogil=True, parallel=True)
def _again(o, d, which, kept, box_lo, box_hi, old_face, old_t, rays, intersect, scene, faces, e1, e2, twin, v0, lo, h,
           n, first, triangle, voxel, out, face, t, none, sources, met, backed):
    """`bundle_kept`'s second pass over the listed `rays`, shared evenly among the threads: traced (met[i])
    where the ray meets the box before its old hit (or is not `kept`), else its voxel looked up again on
    its old face where it is UNKNOWN; its `sources` entry brought up to date, and backed[i] how its
    origin's count of back faces changes."""
    count = d.shape[1]
    inverse = np.empty_like(d)
    for s in range(d.shape[0]):
        for k in range(count):
            for axis in range(3):
                inverse[s, k, axis] = 1.0 / d[s, k, axis] if d[s, k, axis] != 0.0 else np.inf
    for task in numba.prange((rays.shape[0] + RAYS_A_TASK - 1) // RAYS_A_TASK):
        record = embree.record()
        for i in range(task * RAYS_A_TASK, min(rays.shape[0], (task + 1) * RAYS_A_TASK)):
            p, k = rays[i] // count, rays[i] % count
            ox, oy, oz = o[p, 0], o[p, 1], o[p, 2]
            q = which[p]
            dx, dy, dz = d[q, k, 0], d[q, k, 1], d[q, k, 2]
            before = out[p, k]
            again = not kept or meets_box_inverse(ox, oy, oz, inverse[q, k, 0], inverse[q, k, 1], inverse[q, k, 2],
                                                  dx, dy, dz, FAR if old_face[p, k] == NO_FACE else old_t[p, k],
                                                  box_lo, box_hi)
            if again:
                met[i] = True
                f, th, _, _, front = first_face(intersect, scene, record, faces, e1, e2, twin, v0, ox, oy, oz, dx, dy,
                                                dz, FAR)
                face[p, k], t[p, k] = f, th
                out[p, k] = voxel_of(ox, oy, oz, dx, dy, dz, f, th, front, lo, h, n, first, triangle, voxel)
            elif before == UNKNOWN:   # a kept ray whose voxel changed: its old face met from the same side
                f, th, front = old_face[p, k], old_t[p, k], False
                if f != NO_FACE:
                    f, front = facing_face(f, dx, dy, dz, e1, e2, twin)
                out[p, k] = voxel_of(ox, oy, oz, dx, dy, dz, f, th, front, lo, h, n, first, triangle, voxel)
            hit = out[p, k]
            sources[p, k] = none if hit < 0 else hit
            backed[i] = (hit == dda.BACKFACE) - (before == dda.BACKFACE)


@numba.njit(cache=True, nogil=True, parallel=True)
def _tallies(starts, met, backed, backs):
    """`bundle_kept`'s last pass: (P,) each origin's traced rays, and its back faces brought up to date, from
    its listed rays' (`starts`)."""
    traced = np.zeros(starts.shape[0] - 1, np.int64)
    for p in numba.prange(traced.shape[0]):
        for i in range(starts[p], starts[p + 1]):
            traced[p] += met[i]
            backs[p] += backed[i]
    return traced


@numba.njit(cache=True, nogil=True, parallel=True)
def tallied(hits, none, sources, backs):
    """`bundle_kept`'s `sources` and `backs` of (P, D) hits found otherwise."""
    for p in numba.prange(hits.shape[0]):
        back = 0
        for k in range(hits.shape[1]):
            hit = hits[p, k]
            sources[p, k] = none if hit < 0 else hit
            back += hit == dda.BACKFACE
        backs[p] = back


@numba.njit(cache=True, nogil=True, inline="always")
def meets_box_inverse(ox, oy, oz, ix, iy, iz, dx, dy, dz, far, lo, hi):
    """`meets_box` with the direction's inverse (ix, iy, iz) given: products where it divided."""
    near = 0.0
    for axis in range(3):
        start = ox if axis == 0 else (oy if axis == 1 else oz)
        step = dx if axis == 0 else (dy if axis == 1 else dz)
        inverse = ix if axis == 0 else (iy if axis == 1 else iz)
        if step == 0.0:
            if start < lo[axis] or start > hi[axis]:
                return False
        else:
            a, b = (lo[axis] - start) * inverse, (hi[axis] - start) * inverse
            near, far = max(near, min(a, b)), min(far, max(a, b))
    return near <= far


@numba.njit(cache=True, nogil=True, inline="always")
def meets_box(ox, oy, oz, dx, dy, dz, far, lo, hi):
    """Whether o + s d for s in [0, far] passes through the box [lo, hi] (a slab test)."""
    ix = 1.0 / dx if dx != 0.0 else np.inf
    iy = 1.0 / dy if dy != 0.0 else np.inf
    iz = 1.0 / dz if dz != 0.0 else np.inf
    return meets_box_inverse(ox, oy, oz, ix, iy, iz, dx, dy, dz, far, lo, hi)


PACKETS_A_TASK = 64
"""Packets of rays a thread takes at a time (`bundle_packed`)."""


@numba.njit(cache=True, nogil=True, parallel=True)
def bundle_packed(o, d, per_origin, packets, intersect8, scene, faces, e1, e2, twin, lo, h, n, first, triangle,
                  voxel, out, face, t):
    """`bundle_kept` with every ray traced, LANES at a time: `packets` (N, LANES) flat ray indices
    (origin x per_origin + ray, -1 for none), each once; d (R, 3) and out, face, t (R,) flat."""
    for block in numba.prange((packets.shape[0] + PACKETS_A_TASK - 1) // PACKETS_A_TASK):
        record = packet()
        for row in range(block * PACKETS_A_TASK, min(packets.shape[0], (block + 1) * PACKETS_A_TASK)):
            rays = packets[row]
            closest8(intersect8, scene, record, o, d, rays, per_origin, FAR, face, t)
            for lane in range(LANES):
                r = rays[lane]
                if r < 0:
                    continue
                q, dx, dy, dz = r // per_origin, d[r, 0], d[r, 1], d[r, 2]
                f, front = NO_FACE, False
                if face[r] >= 0:
                    f, front = facing_face(faces[face[r]], dx, dy, dz, e1, e2, twin)
                face[r] = f
                out[r] = voxel_of(o[q, 0], o[q, 1], o[q, 2], dx, dy, dz, f, t[r], front, lo, h, n, first, triangle,
                                  voxel)


@numba.njit(cache=True, nogil=True, inline="always")
def voxel_of(ox, oy, oz, dx, dy, dz, f, t, front, lo, h, n, first, triangle, voxel):
    """The voxel of a hit: the listing's entry for the hit's face in the cell a hair before the hit
    point, else in the cell of the point itself or a neighbour (a hit on the listing's edge); a face met
    from behind is BACKFACE, and one the listing lacks near the hit too (it cannot be lit)."""
    if f == NO_FACE:
        return dda.MISS
    if not front:
        return dda.BACKFACE
    if first.shape[0] == 0:   # `keyed_cells`: the facing of each face, and the voxel of each key
        return _keyed_voxel(ox, oy, oz, dx, dy, dz, t, lo, h, n, triangle[f], voxel)
    found = dda.BACKFACE
    back = STEP_BACK * h
    cx = cy = cz = 0
    for attempt in range(2):
        s = t - back if attempt == 0 else t
        cx = min(max(int(np.floor((ox + s * dx - lo[0]) / h)), 0), n - 1)
        cy = min(max(int(np.floor((oy + s * dy - lo[1]) / h)), 0), n - 1)
        cz = min(max(int(np.floor((oz + s * dz - lo[2]) / h)), 0), n - 1)
        found = _entry(cx, cy, cz, f, n, first, triangle, voxel)
        if found != dda.MISS:
            break
    if found == dda.MISS:
        for k in range(27):
            x, y, z = cx + k % 3 - 1, cy + (k // 3) % 3 - 1, cz + k // 9 - 1
            if 0 <= x < n and 0 <= y < n and 0 <= z < n:
                found = _entry(x, y, z, f, n, first, triangle, voxel)
                if found != dda.MISS:
                    break
    return dda.BACKFACE if found == dda.MISS else found


@numba.njit(cache=True, nogil=True, inline="always")
def _keyed_voxel(ox, oy, oz, dx, dy, dz, t, lo, h, n, facing, table):
    """The voxel of `facing` in the cell a hair before the hit point (`table`: flat cell x 6 + facing ->
    voxel, -1 for none), else in the nearest neighbouring cell that has one, else BACKFACE: the voxel
    `dda.Cells.of` gives the face's entry there."""
    s = t - STEP_BACK * h
    cx = dda.cell_of(ox + s * dx, lo[0], h, n)
    cy = dda.cell_of(oy + s * dy, lo[1], h, n)
    cz = dda.cell_of(oz + s * dz, lo[2], h, n)
    for k in range(NEIGHBOUR_ORDER.shape[0]):
        x, y, z = cx + NEIGHBOUR_ORDER[k, 0], cy + NEIGHBOUR_ORDER[k, 1], cz + NEIGHBOUR_ORDER[k, 2]
        if 0 <= x < n and 0 <= y < n and 0 <= z < n:
            found = table[(x + n * (y + n * z)) * 6 + facing]
            if found >= 0:
                return found
    return dda.BACKFACE


@numba.njit(cache=True, nogil=True)
def _entry(x, y, z, f, n, first, triangle, voxel):
    """The voxel that the listing of cell (x, y, z) gives face f, dda.MISS where it does not list f."""
    flat = x + n * (y + n * z)
    for e in range(first[flat], first[flat + 1]):
        if triangle[e] == f:
            return voxel[e]
    return dda.MISS

"""Closest hits of many rays against a scene's triangles: which face each ray meets first, where on it
(the barycentrics u, v of the point v0 + u (v1 - v0) + v (v2 - v0)), how far, and from which side.

Two backends answer alike. Embree (shipped by the `embreex` package) traverses a bounding-volume
hierarchy and costs about log(faces) a ray; the project's numba DDA (viewer/rays/dda.py) marches a fixed
grid of cells and tests every triangle listed in each cell it crosses, so on a detailed mesh, where one
cell of a 32^3 grid lists a couple of hundred of a bunny's triangles, each ray costs hundreds of triangle
tests. Embree is called from compiled loops (viewer/rays/embree.py), on every core and without Python's
lock, or through embreex's own binding where that cannot load. Measured on the final gather's rays on 2
cores (docs/PERFORMANCE.md, `python -m viewer.bench.rays`): 14.3 M rays a second in a Cornell box
(embreex's binding 5.9, the DDA 4.6), 6.0 M with a 68k-triangle scan (3.7 and 0.5). The DDA stays the
fallback where embreex is not installed, and the caster of the stages that need a cell's voxel rather
than a face.

A hit's side comes from the face's own normal against the ray's direction, and a two-sided sheet's
reversed faces give the near side (viewer/rays/sides.py).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numba
import numpy as np

from viewer.rays import dda, embree, moved_faces
from viewer.rays.sides import NO_FACE, NO_TWIN, barycentrics, sides

try:   # optional at run time: the DDA answers the same questions without it, slower on detailed meshes
    from embreex import rtcore_scene
    from embreex.mesh_construction import TriangleMesh
except ImportError:   # pragma: no cover - depends on the installation
    rtcore_scene = TriangleMesh = None

MOVED_SHARE = 0.5
"""A caster made from a previous one builds the moved faces apart while they are at most this share of
the faces (a lamp, an object); past it, one hierarchy of all the faces costs as much..."""
PARTED_FACES = 20_000
"""... and while the faces that stayed are at least this many: a second level costs every ray a sixth of
its speed, which a box room's hierarchy, built in a fraction of a millisecond, does not pay back (its
moved box's probes took 66 ms instead of 60-62 with parts). Moved faces at least this many are built
apart whatever their share (a scan in a room): the next move of the same faces by a translation (a
drag) keeps their hierarchy, which a million triangles took 100-200 ms to build."""
EMBREE_CHUNK = 1 << 14
"""Rays per call into embreex's binding (where viewer.rays.embree cannot load), which holds Python's lock
while it traces: about 5 ms at a time (Python's own switch interval), so that a frame on the render
thread waits no longer while the final gather is cast on the worker; the calls cost the same rays a
second as 4x larger ones."""


def embree_available() -> bool:
    """Whether the Embree backend can be used (the embreex package imports)."""
    return rtcore_scene is not None


@dataclass(frozen=True)
class Hits:
    """What each of R rays meets first."""

    face: np.ndarray
    """(R,) int64: the scene face, NO_FACE for none."""
    t: np.ndarray
    """(R,) float64: distance along the (unit) direction, inf for none."""
    u: np.ndarray
    """(R,) float64: barycentric weight of the face's second corner at the hit."""
    v: np.ndarray
    """(R,) float64: barycentric weight of its third corner."""
    front: np.ndarray
    """(R,) bool: the ray met the face's front (the side its counter-clockwise normal points to)."""


def distinct_rows(rows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(first, inverse) of a 2D array's distinct rows: the index of each one's first occurrence, and each
    row's number among them, as np.unique(rows, axis=0, return_index=True, return_inverse=True) gives
    them but in no set order. Rows are told apart by their dot product with irrational weights (one sort
    of numbers, where np.unique sorts the rows themselves: 0.03 s against 0.98 s for 280k normals), and
    the answer is checked row for row; rows that share a key without being equal go through np.unique."""
    rows = np.asarray(rows)
    if rows.ndim == 2 and len(rows) and rows.dtype.kind in "fiu":
        key = rows @ np.sqrt(np.array([2.0, 3.0, 5.0, 7.0, 11.0, 13.0, 17.0, 19.0, 23.0, 29.0])[:rows.shape[1]]) \
            if rows.shape[1] <= 10 else None
        if key is not None and np.all(np.isfinite(key)):
            _, first, which = np.unique(key, return_index=True, return_inverse=True)
            if np.array_equal(rows[first][which.ravel()], rows):
                return first, which.ravel()
    _, first, which = np.unique(rows, axis=0, return_index=True, return_inverse=True)
    return first, which.ravel()


def _hull_of(corners: np.ndarray) -> np.ndarray:
    """The corners of the convex hull of `corners` (all of them where the hull is flat or they are too few)."""
    from scipy.spatial import ConvexHull, QhullError

    try:
        return corners[ConvexHull(corners).vertices]
    except (QhullError, ValueError):
        return corners


@dataclass
class _Stayed:
    """The faces that stayed through a move, kept across a drag: their hierarchy, and their hull's corners
    once asked (a 68k-triangle scan's took 26 ms)."""

    faces: np.ndarray
    hierarchy: "embree.Hierarchy"
    hull: np.ndarray | None = None
    shift: np.ndarray | None = None
    """Where the hierarchy serves its faces moved since it was built: their translation (the moved faces')."""


def corners(scene, faces: np.ndarray) -> np.ndarray:
    """(K, 3, 3) float32 corners of the `faces`, as Embree takes them."""
    return np.ascontiguousarray(scene.vertices[scene.faces[faces]], np.float32)


def usable_faces(scene) -> np.ndarray:
    """The faces rays can meet: those of area above 1e-12 of the largest (as the DDA lists them)."""
    areas = scene.face_areas
    return np.nonzero(areas > 1e-12 * max(float(areas.max()), 1e-30))[0]


class TriangleCaster:
    """A scene's triangles, ready for rays: an Embree hierarchy, or the DDA's cells."""

    _faces: np.ndarray | None = None
    """The scene faces Embree holds (`usable_faces`), in the order it numbers them; None for the DDA, whose
    cells hold them all."""
    _hull: np.ndarray | None = None
    """`_hull_corners`, once asked."""
    _direct: "embree.Scene | None" = None
    """Embree called from compiled loops (viewer.rays.embree); None where only embreex's binding works."""
    _quick: bool | None = False
    twin: np.ndarray = NO_TWIN
    """(F,) each scene face's reversed twin, -1 for none (`Scene.twins`), or NO_TWIN where no face
    has one (and for the DDA, whose march settles a tie by the order its cells list the faces)."""
    _stayed: _Stayed | None = None
    """The faces that stayed, where this caster was made from a previous one with some faces moved: the
    next move of the same faces keeps them."""
    _went: _Stayed | None = None
    """... and the faces that moved, in the hierarchy built of them at the first move: a later move of the
    same faces by a translation (a drag) keeps it, moved (`moved_faces.translation`)."""

    def __init__(self, scene, cells: dda.Cells | None = None, backend: str | None = None,
                 previous: "TriangleCaster | None" = None, quick: bool | None = False):
        """`cells`: the scene's dda.Cells (any grid, Cells.blocking will do) when the caller has them, for
        the DDA backend; `backend`: "embree", "dda", or None for Embree where it is installed ("embreex":
        Embree through embreex's own binding, which holds Python's lock: for comparisons). `previous`:
        the caster of the same faces before some of them moved (a dragged lamp or object), whose
        hierarchy of the faces that stayed is kept where it has one (`_parted`). `quick`: Embree built
        quickly, its rays slower (`embree.Hierarchy`; None: the large hierarchies alone)."""
        self._quick = quick
        backend = backend or ("embree" if embree_available() else "dda")
        if backend in ("embree", "embreex") and not embree_available():
            raise ValueError("the embree backend needs the embreex package")
        if backend not in ("embree", "embreex", "dda"):
            raise ValueError(f"unknown ray-casting backend {backend!r}")
        self.backend = "embree" if backend == "embreex" else backend
        if backend == "dda":
            if cells is None:
                from viewer.rays.voxels import grid_frame
                cells = dda.Cells.blocking(scene, *grid_frame(scene, 32), 32)
            self._march(cells)
            return
        faces = usable_faces(scene)
        parts = self._parted(scene, faces, previous) if backend == "embree" else None
        if parts is not None:
            faces = np.concatenate([parts[0], parts[1]])
            # the moved faces alone (the stayed ones' hierarchy is kept), unless their own is kept too
            mesh = corners(scene, parts[1]) if parts[3] is None else parts[3].hierarchy.corners
        else:
            mesh = np.asarray(scene.triangles)[faces]
        self._embrace(mesh, faces, *scene.edges, backend == "embree", parts)
        # a move keeps a scene without two-sided sheets without (a face dragged exactly onto another's
        # corners, wound the other way, is not looked for): 24 ms of a million-triangle scan's move
        kept = (previous is not None and previous.backend == self.backend and previous.twin is NO_TWIN
                and len(previous.v0) == len(scene.faces))
        self.twin = NO_TWIN if kept else scene.twins

    def _parted(self, scene, faces: np.ndarray, previous: "TriangleCaster | None"):
        """(faces that stayed, faces that moved, `_Stayed` of the former, of the latter or None) where
        `previous` holds the same faces with at most MOVED_SHARE of them elsewhere now; the previous one's
        `_Stayed` where it held the same faces apart, else made here; its moved faces' where the same
        faces moved again by a translation (with that shift), else None: they are built again. None: one
        hierarchy of all."""
        v0, e1, e2 = scene.edges
        if (previous is None or previous._direct is None or not embree.available()
                or previous.v0.shape != v0.shape):
            return None
        moved = moved_faces.changed_rows((previous.v0, v0), (previous.e1, e1), (previous.e2, e2))[faces]
        count, stayed_count = int(moved.sum()), len(faces) - int(moved.sum())
        few_moved = count <= MOVED_SHARE * len(faces) and stayed_count >= PARTED_FACES
        if count == 0 or stayed_count == 0 or not (few_moved or count >= PARTED_FACES):
            return None
        stayed, went = faces[~moved], faces[moved]
        kept, gone = previous._stayed, previous._went
        if gone is not None and np.array_equal(gone.faces, went):
            shift = moved_faces.translation(gone.hierarchy.corners, (v0, e1, e2), went)
            gone = None if shift is None else _Stayed(went, gone.hierarchy, shift=shift)
        else:
            gone = None
        if kept is None or not np.array_equal(kept.faces, stayed):
            kept = _Stayed(stayed, embree.Hierarchy(corners(scene, stayed), self._quick))
        return stayed, went, kept, gone

    def _embrace(self, mesh, faces, v0, e1, e2, direct: bool = True, parts=None) -> None:
        self.mesh = np.ascontiguousarray(mesh, np.float32)
        """(faces, 3, 3) float32: the corners Embree holds in a hierarchy of this caster's own (the usable
        faces, or those that moved where the faces that stayed keep theirs)."""
        self._faces = np.ascontiguousarray(faces, np.int64)
        self.v0, self.e1, self.e2 = (np.ascontiguousarray(a, np.float64) for a in (v0, e1, e2))
        if direct and embree.available():   # called from compiled loops: all cores, without Python's lock
            if parts is None:
                self._direct = embree.Scene(self.mesh, quick=self._quick)
            else:
                self._stayed = parts[2]
                self._went = parts[3] or _Stayed(parts[1], embree.Hierarchy(self.mesh, self._quick))
                self._direct = embree.Scene(parts[2].hierarchy, self._went.hierarchy, shifts=[None, self._went.shift])
        else:
            self._embree = rtcore_scene.EmbreeScene()
            TriangleMesh(self._embree, self.mesh)

    @property
    def direct(self) -> "embree.Scene | None":
        """Embree for compiled loops to call (viewer.rays.embree), None where it is not used."""
        return self._direct

    @property
    def faces(self) -> np.ndarray | None:
        """The scene faces Embree holds, in the order of `mesh` (None for the DDA)."""
        return self._faces

    def nothing_ahead(self, points: np.ndarray, normals: np.ndarray, margin: float) -> np.ndarray:
        """(P,) bool: no face reaches more than `margin` in front of the plane through each point with its
        normal, so that every ray from the point into that half-space, started more than `margin` off
        the plane, meets nothing: the back of a room's wall, which looks out of the scene. Exact, from
        the support of the faces' convex hull along each distinct normal (a few dozen corners for a
        room, whatever stands in it), where casting the rays would cost microseconds each."""
        p = np.asarray(points, np.float64).reshape(-1, 3)
        if len(p) == 0:
            return np.zeros(0, bool)
        normals = np.asarray(normals, np.float64).reshape(-1, 3)
        first, which = distinct_rows(normals)
        normal = normals[first]
        support = np.empty(len(normal))
        corners = self._hull_corners()
        for start in range(0, len(normal), 4096):   # (normals x corners) a block at a time
            support[start:start + 4096] = (normal[start:start + 4096] @ corners.T).max(axis=1)
        offset = np.einsum("ij,ij->i", p, normal[which.ravel()])
        return support[which.ravel()] - offset <= margin

    def _hull_corners(self) -> np.ndarray:
        """The corners of the convex hull of the faces rays can meet (all their corners where the hull is
        flat). Qhull takes the corners as they are, shared ones repeated: sorting them out first took the
        272k-triangle scan 1.4 s instead of 0.2."""
        if self._hull is None:
            faces = slice(None) if self._faces is None else self._faces
            if self._stayed is None:
                self._hull = _hull_of(self._corners(faces))
            else:   # the hull of the faces that stayed (kept across a drag) and the moved faces' corners
                stayed = self._stayed
                if stayed.hull is None:
                    stayed.hull = _hull_of(self._corners(stayed.faces))
                self._hull = _hull_of(np.concatenate([stayed.hull, self._corners(self._faces[len(stayed.faces):])]))
        return self._hull

    def _corners(self, faces) -> np.ndarray:
        v0, e1, e2 = self.v0[faces], self.e1[faces], self.e2[faces]
        return np.concatenate([v0, v0 + e1, v0 + e2])

    @staticmethod
    def marching(cells: dda.Cells) -> "TriangleCaster":
        """The DDA's caster over `cells` alone (their triangles are the scene's)."""
        caster = TriangleCaster.__new__(TriangleCaster)
        caster.backend = "dda"
        caster._march(cells)
        return caster

    def _march(self, cells: dda.Cells) -> None:
        self.v0, self.e1, self.e2 = cells.v0, cells.e1, cells.e2
        by_face = replace(cells, voxel=cells.triangle)                     # a front hit names its face
        self._marched = (by_face.args(), replace(by_face, e1=cells.e2, e2=cells.e1).args())   # and a back one

    def blocked(self, origins: np.ndarray, directions: np.ndarray, lengths: np.ndarray) -> np.ndarray:
        """(R,) bool: whether the segment o + t d, 0 < t <= length, crosses a face from either side (Embree's
        occlusion query: the first hit found, not the closest)."""
        o = np.ascontiguousarray(origins, np.float64).reshape(-1, 3)
        d = np.ascontiguousarray(directions, np.float64).reshape(-1, 3)
        length = np.ascontiguousarray(np.broadcast_to(lengths, (len(o),)), np.float64)
        if self.backend == "dda":
            return _marched_blocked(o, d, length, self._marched[0])
        if self._direct is not None:
            return self._direct.occluded(o, d, length)
        out = np.empty(len(o), bool)
        o32, d32, far = o.astype(np.float32), d.astype(np.float32), length.astype(np.float32)
        for start in range(0, len(o), EMBREE_CHUNK):
            part = slice(start, start + EMBREE_CHUNK)
            out[part] = self._embree.run(o32[part], d32[part], dists=far[part], query="OCCLUDED") >= 0
        return out

    def closest_hits(self, origins: np.ndarray, directions: np.ndarray, t_max: float = np.inf) -> Hits:
        """The first face each ray o + t d, 0 < t <= t_max, meets; `directions` (R, 3) of unit length."""
        o = np.ascontiguousarray(origins, np.float64).reshape(-1, 3)
        d = np.ascontiguousarray(directions, np.float64).reshape(-1, 3)
        if self.backend == "dda":
            face, t, u, v, front = _marched_hits(o, d, float(t_max), *self._marched)
            return Hits(face, t, u, v, front)
        if self._direct is not None:
            primitive, t, u, v = self._direct.closest(o, d, min(float(t_max), 1e37))
            face = np.where(primitive >= 0, self._faces[np.maximum(primitive, 0)], NO_FACE)
            return Hits(*self._sides(o, d, face, t, u, v))
        face = np.empty(len(o), np.int64)
        t, u, v = np.empty(len(o)), np.empty(len(o)), np.empty(len(o))
        o32, d32 = o.astype(np.float32), d.astype(np.float32)
        far = np.float32(min(float(t_max), 1e37))
        for start in range(0, len(o), EMBREE_CHUNK):
            part = slice(start, start + EMBREE_CHUNK)
            found = self._embree.run(o32[part], d32[part], dists=far, output=1)
            prim = found["primID"].astype(np.int64)
            hit = prim >= 0
            face[part] = np.where(hit, self._faces[np.where(hit, prim, 0)], NO_FACE)
            t[part] = np.where(hit, found["tfar"], np.inf)
            u[part], v[part] = found["u"], found["v"]
        return Hits(*self._sides(o, d, face, t, u, v))

    def _sides(self, o, d, face, t, u, v) -> tuple:
        """(face, t, u, v, front) of Embree's hits: the face met and its side (`sides.facing_face`)."""
        face, u, v, front = sides(o, d, face, t, np.asarray(u, np.float64), np.asarray(v, np.float64), self.v0,
                                  self.e1, self.e2, self.twin)
        return face, t, u, v, front


def closest_hits(scene, origins: np.ndarray, directions: np.ndarray, t_max: float = np.inf,
                 backend: str | None = None) -> Hits:
    """The first face each ray meets (TriangleCaster once: build a caster to cast more than one set)."""
    return TriangleCaster(scene, backend=backend).closest_hits(origins, directions, t_max)


@numba.njit(cache=True, nogil=True, parallel=True)
def _marched_hits(o, d, t_max, by_face, flipped):
    """The DDA's closest hits: a back hit is marched again with the faces flipped, which names its face;
    the barycentrics are those of the hit point on that face's plane."""
    count = o.shape[0]
    face = np.full(count, NO_FACE, np.int64)
    t, u, v = np.full(count, np.inf), np.zeros(count), np.zeros(count)
    front = np.zeros(count, np.bool_)
    none = np.zeros(0, np.int64)
    v0, e1, e2 = by_face[6], by_face[7], by_face[8]
    for r in numba.prange(count):
        ox, oy, oz, dx, dy, dz = o[r, 0], o[r, 1], o[r, 2], d[r, 0], d[r, 1], d[r, 2]
        f, th = dda.march(ox, oy, oz, dx, dy, dz, t_max, by_face, none)
        ahead = f >= 0
        if f == dda.BACKFACE:
            f, th = dda.march(ox, oy, oz, dx, dy, dz, t_max, flipped, none)
        if f < 0:
            continue
        face[r], t[r], front[r] = f, th, ahead
        u[r], v[r] = barycentrics(ox + th * dx, oy + th * dy, oz + th * dz, f, v0, e1, e2)
    return face, t, u, v, front


@numba.njit(cache=True, nogil=True, parallel=True)
def _marched_blocked(o, d, length, cells):
    out = np.zeros(o.shape[0], np.bool_)
    none = np.zeros(0, np.int64)
    for r in numba.prange(o.shape[0]):
        hit, _ = dda.march(o[r, 0], o[r, 1], o[r, 2], d[r, 0], d[r, 1], d[r, 2], length[r], cells, none)
        out[r] = hit != dda.MISS
    return out

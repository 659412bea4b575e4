"""Embree's ray queries called from compiled loops, without Python's lock.

The `embreex` package ships Embree (libembree4) and a Python binding whose `run` holds Python's lock
while it traces, one ray at a time through its own bookkeeping: 5.3-5.9 M rays a second on one core of
this project's 2-core test machine, and every other thread of the process (the GI source's trace, the
renderer's final gather, the frames' Python) waits its turn. Here the same library is called from
numba's nopython loops: each ray goes into one RTCRayHit record that `rtcIntersect1` fills, the loop
releases the lock and runs on every core (6.3-6.6 M rays a second a core in a Cornell box, against
embreex's 5.3-5.9, both with Embree's robust traversal), and two threads that trace at once run side by
side (docs/PERFORMANCE.md, `python -m viewer.bench.rays`).

The scene is built as embreex builds it (one triangle mesh, robust traversal, which closes the cracks
between neighbouring triangles), so the hits are embreex's own, bit for bit: the same face, distance and
barycentrics (tests/rays/test_embree.py). A scene may also be made of parts, each with a hierarchy of its
own, so that a moved object is built again alone (`Scene`). Where the library cannot be found or loaded,
`available()` is False and viewer.rays.cast uses embreex's binding instead.

The record layouts (Embree 4's rtcore_ray.h, 16-byte aligned): RTCRay is org (3 floats), tnear, dir
(3), time, tfar, mask, id, flags, 48 bytes; RTCHit follows it with Ng (3), u, v, primID, geomID, instID.
"""

from __future__ import annotations

import ctypes
import glob
import os
import threading
import weakref

import numba
import numpy as np
from llvmlite import ir
from numba.core import types
from numba.extending import intrinsic

INVALID = 0xFFFFFFFF
"""RTC_INVALID_GEOMETRY_ID: geomID of a ray that met nothing."""
RECORD = 32
"""Floats of one RTCRayHit record (24 used), with room to align it to 16 bytes."""
BLOCK = 4096
"""Rays a thread takes at a time."""
RUN = 512
"""Items that `spread` keeps together."""
# Embree 4's enumerations (rtcore_common.h, rtcore_geometry.h, rtcore_scene.h)
GEOMETRY_TRIANGLE, GEOMETRY_INSTANCE, BUFFER_INDEX, BUFFER_VERTEX = 0, 121, 0, 1
FORMAT_UINT3, FORMAT_FLOAT3, FORMAT_FLOAT3X4_COLUMN_MAJOR = 0x5003, 0x9003, 0x9234
IDENTITY = np.array([1, 0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0], np.float32)
"""An instance's transform: the identity, columns of a 3x4 matrix."""
SCENE_ROBUST = 1 << 2
BUILD_QUALITY_LOW = 0
QUICK_FACES = 20_000
"""Above this many triangles a hierarchy built for speed of building (`Hierarchy`'s `quick=None`) takes
Embree's low build quality; at or below it, the default. The neural encoding's 885k seen rays of a 24^3
lattice: a 904-triangle generator room's 70 -> 47 ms at the default quality (0.3 -> 0.4 ms to build), a
68k-triangle scan's 58 -> 51 ms, built in 16 ms instead of 6 (a moved scan builds again, with fewer
rays)."""

_lock = threading.Lock()
_library = None   # (ctypes library, device, rtcIntersect1's address, rtcOccluded1's) once loaded
_failed: str | None = None


def _find_library() -> str | None:
    """libembree4 where the embreex wheel put it (embreex.libs beside the package on Linux and Windows,
    .dylibs inside it on macOS)."""
    try:
        import embreex
        import embreex.rtcore_scene  # noqa: F401 - loads Embree and the libraries it needs into the process
    except ImportError:
        return None
    package = os.path.dirname(embreex.__file__)
    for folder in (package + ".libs", os.path.join(package, ".dylibs"), package):
        found = sorted(glob.glob(os.path.join(folder, "*embree4*")))
        if found:
            return found[0]
    return None


def _load():
    global _library, _failed
    with _lock:
        if _library is not None or _failed is not None:
            return _library
        try:
            path = _find_library()
            if path is None:
                raise OSError("libembree4 is not installed beside embreex")
            lib = ctypes.CDLL(path)
            pointer = ctypes.c_void_p
            for name, result, arguments in (
                    ("rtcNewDevice", pointer, [ctypes.c_char_p]),
                    ("rtcGetDeviceError", ctypes.c_int, [pointer]),
                    ("rtcNewScene", pointer, [pointer]),
                    ("rtcSetSceneFlags", None, [pointer, ctypes.c_int]),
                    ("rtcNewGeometry", pointer, [pointer, ctypes.c_int]),
                    ("rtcSetSharedGeometryBuffer", None, [pointer, ctypes.c_int, ctypes.c_uint, ctypes.c_int,
                                                          pointer, ctypes.c_size_t, ctypes.c_size_t, ctypes.c_size_t]),
                    ("rtcCommitGeometry", None, [pointer]),
                    ("rtcAttachGeometry", ctypes.c_uint, [pointer, pointer]),
                    ("rtcReleaseGeometry", None, [pointer]),
                    ("rtcSetGeometryInstancedScene", None, [pointer, pointer]),
                    ("rtcSetGeometryTransform", None, [pointer, ctypes.c_uint, ctypes.c_int, pointer]),
                    ("rtcSetSceneBuildQuality", None, [pointer, ctypes.c_int]),
                    ("rtcSetGeometryBuildQuality", None, [pointer, ctypes.c_int]),
                    ("rtcCommitScene", None, [pointer]),
                    ("rtcReleaseScene", None, [pointer])):
                function = getattr(lib, name)
                function.restype, function.argtypes = result, arguments
            device = lib.rtcNewDevice(None)
            if not device:
                raise OSError("rtcNewDevice failed")
            address = ctypes.c_void_p
            _library = (lib, device, ctypes.cast(lib.rtcIntersect1, address).value,
                        ctypes.cast(lib.rtcOccluded1, address).value, ctypes.cast(lib.rtcIntersect8, address).value,
                        ctypes.cast(lib.rtcOccluded8, address).value)
        except (OSError, AttributeError) as exc:
            _failed = str(exc)
        return _library


def spread(count: int, run: int = RUN) -> np.ndarray:
    """A permutation of range(count): runs of `run` consecutive items, the runs in a fixed pseudo-random order.
    A parallel loop gives each thread one contiguous share of its range; where the items' cost clusters (a
    scanned mesh's samples, numbered tile by tile, whose rays traverse its dense hierarchy, beside the
    walls' cheap ones) one thread finishes first and the other goes on alone. Looped over in this order, the
    shares cost alike and neighbours stay together for the caches: the final gather of a 68k-triangle scan
    on 2 cores went from 8.7 to 10.2 M rays a second (`python -m viewer.bench.rays`)."""
    runs = (count + run - 1) // run
    order = np.random.default_rng(0).permutation(runs)
    items = (order[:, None] * run + np.arange(run)).ravel()
    return items[items < count]


def available() -> bool:
    """Whether Embree can be called here (else viewer.rays.cast uses embreex's own binding)."""
    return _load() is not None


class Hierarchy:
    """Triangles in one Embree hierarchy of their own (one robust triangle mesh, as embreex builds it): a
    `Scene` queries one alone, or several side by side."""

    def __init__(self, triangles: np.ndarray, quick: bool | None = False):
        """`triangles` (F, 3, 3): each face's corners; face i is primitive i. `quick`: built with Embree's
        low build quality (a Morton build: a 272k-triangle scan in 20 ms instead of 48, a 68k one in 5
        instead of 10), whose rays run slower: 5-14% on a scan, 1.3-1.6x in rooms of a hundred to a
        thousand large triangles; None: quick above QUICK_FACES triangles. Either build meets the same
        faces at the same distances, except where coplanar faces tie: which one a ray gets follows the
        hierarchy."""
        library = _load()
        if library is None:
            raise OSError(f"Embree cannot be called directly: {_failed}")
        lib, device = library[0], library[1]
        faces = len(triangles)
        self.count = faces
        self.quick = faces > QUICK_FACES if quick is None else bool(quick)
        """Whether it was built with the low build quality."""
        # Embree reads vertices 16 bytes at a time: one more vertex than the faces use keeps the last read
        # inside the buffer. Both buffers stay referenced here, as long as the scene that shares them.
        self._vertices = np.zeros((3 * faces + 1, 3), np.float32)
        self._vertices[:-1] = np.asarray(triangles, np.float32).reshape(-1, 3)
        self._indices = np.arange(3 * faces, dtype=np.uint32).reshape(-1, 3)
        scene = lib.rtcNewScene(device)
        lib.rtcSetSceneFlags(scene, SCENE_ROBUST)
        geometry = lib.rtcNewGeometry(device, GEOMETRY_TRIANGLE)
        if self.quick:
            lib.rtcSetSceneBuildQuality(scene, BUILD_QUALITY_LOW)
            lib.rtcSetGeometryBuildQuality(geometry, BUILD_QUALITY_LOW)
        lib.rtcSetSharedGeometryBuffer(geometry, BUFFER_VERTEX, 0, FORMAT_FLOAT3, self._vertices.ctypes.data, 0,
                                       12, 3 * faces)
        lib.rtcSetSharedGeometryBuffer(geometry, BUFFER_INDEX, 0, FORMAT_UINT3, self._indices.ctypes.data, 0,
                                       12, faces)
        lib.rtcCommitGeometry(geometry)
        lib.rtcAttachGeometry(scene, geometry)
        lib.rtcReleaseGeometry(geometry)
        self.address = _committed(self, lib, device, scene)

    @property
    def corners(self) -> np.ndarray:
        """(F, 3, 3) float32: the corners it was built of."""
        return self._vertices[:-1].reshape(-1, 3, 3)


class Scene:
    """Triangles in Embree, queried from compiled loops: one `Hierarchy`, or several, each an instance
    (with the identity transform) in a scene of their own. Parts let a moved object or lamp be built
    alone while the rest keeps its hierarchy: on a 68k-triangle scan, a lamp's two triangles and the
    scene over both parts took 0.2 ms to build where the whole scan took 10-11 ms; the rays meet the same
    faces at the same distances (every one of a million random rays), at 14.3 M rays a second instead of
    17.1 on two cores (a second level to traverse)."""

    def __init__(self, *parts, quick: bool | None = False, shifts=None):
        """Each part (F_i, 3, 3) triangles or a `Hierarchy` (`quick`: see there); the parts' faces are
        numbered one after the other (primitive i of part k is face offset_k + i). `shifts`: one (3,)
        translation or None a part, where a part's hierarchy serves its triangles moved (a dragged
        object's, kept across the drag: a million-triangle scan's took 100 ms to build again)."""
        library = _load()
        if library is None:
            raise OSError(f"Embree cannot be called directly: {_failed}")
        lib, device, intersect, occluded, intersect8, occluded8 = library
        self.parts = [part if isinstance(part, Hierarchy) else Hierarchy(part, quick) for part in parts]
        offsets = np.cumsum([0] + [part.count for part in self.parts])[:-1]
        shifts = [None] * len(self.parts) if shifts is None else list(shifts)
        if len(self.parts) == 1 and shifts[0] is None:
            address = self.parts[0].address
        else:
            scene = lib.rtcNewScene(device)
            lib.rtcSetSceneFlags(scene, SCENE_ROBUST)
            for part, shift in zip(self.parts, shifts):
                transform = IDENTITY.copy()   # Embree copies it
                if shift is not None:
                    transform[9:] = shift
                geometry = lib.rtcNewGeometry(device, GEOMETRY_INSTANCE)
                lib.rtcSetGeometryInstancedScene(geometry, part.address)
                lib.rtcSetGeometryTransform(geometry, 0, FORMAT_FLOAT3X4_COLUMN_MAJOR, transform.ctypes.data)
                lib.rtcCommitGeometry(geometry)
                lib.rtcAttachGeometry(scene, geometry)
                lib.rtcReleaseGeometry(geometry)
            address = _committed(self, lib, device, scene)
        self.scene = np.array([address, *offsets], np.int64)
        """What compiled loops pass to `closest` and `occluded` as the scene: its address, then each
        part's first face (instance i's primitives are numbered from `scene[1 + i]`)."""
        self._intersect, self._occluded = intersect, occluded
        self.handle = (intersect, self.scene)
        """(rtcIntersect1's address, `scene`): what a compiled loop passes to `closest`."""
        self.occlusion = (occluded, self.scene)
        """(rtcOccluded1's address, `scene`): what a compiled loop passes to `occluded`."""
        self.packets = (intersect8, self.scene)
        """(rtcIntersect8's address, `scene`): what a compiled loop passes to `closest8`."""
        self.occlusion8 = (occluded8, self.scene)
        """(rtcOccluded8's address, `scene`): what a compiled loop passes to `occluded8`."""

    def closest(self, origins: np.ndarray, directions: np.ndarray, far: float):
        """(primitive, t, u, v) of the first face each ray o + t d, 0 <= t <= far, meets: primitive -1 (and t
        inf) for none. `origins`, `directions` (R, 3) float64, rounded to Embree's floats."""
        count = len(origins)
        primitive, t = np.empty(count, np.int64), np.empty(count)
        u, v = np.empty(count), np.empty(count)
        _closest(self._intersect, self.scene, origins, directions, np.float32(min(far, 3.0e38)), primitive, t, u, v)
        return primitive, t, u, v

    def occluded(self, origins: np.ndarray, directions: np.ndarray, lengths: np.ndarray) -> np.ndarray:
        """(R,) bool: whether each segment o + t d, 0 <= t <= length, meets a face (the first found)."""
        out = np.empty(len(origins), np.bool_)
        _occluded(self._occluded, self.scene, origins, directions, lengths, out)
        return out


def _committed(owner, lib, device, scene) -> int:
    """Commit `scene`, released with `owner`; OSError where Embree reports an error."""
    lib.rtcCommitScene(scene)
    error = lib.rtcGetDeviceError(device)
    if error:
        lib.rtcReleaseScene(scene)
        raise OSError(f"Embree could not build the scene (error {error})")
    weakref.finalize(owner, lib.rtcReleaseScene, scene)
    return scene


@intrinsic
def _call(typingctx, function, scene, record, arguments):
    """function(scene, record, arguments) for an Embree query's address and three pointers, all passed as
    integers: a call the compiled loop makes without Python (and which numba can cache, where a ctypes
    function object would be baked into the code as a constant)."""
    if not all(isinstance(a, types.Integer) for a in (function, scene, record, arguments)):
        return None

    def codegen(context, builder, signature, args):
        word = ir.IntType(64)
        kind = ir.FunctionType(ir.VoidType(), [word, word, word])
        values = [builder.zext(a, word) if a.type.width < 64 else a for a in args]
        builder.call(builder.inttoptr(values[0], kind.as_pointer()), values[1:])
        return context.get_dummy_value()

    return types.void(function, scene, record, arguments), codegen


@numba.njit(cache=True, nogil=True, inline="always")
def record():
    """A thread's RTCRayHit record for `closest`: (floats, the same memory as uint32, the first 16-byte
    aligned offset into them, its address)."""
    ray = np.empty(RECORD, np.float32)
    at = (16 - ray.ctypes.data % 16) % 16 // 4
    return ray, ray.view(np.uint32), at, ray.ctypes.data + 4 * at


@numba.njit(cache=True, nogil=True, inline="always")
def _ray(ray, bits, at, ox, oy, oz, dx, dy, dz, far):
    ray[at], ray[at + 1], ray[at + 2], ray[at + 3] = ox, oy, oz, 0.0        # origin, tnear
    ray[at + 4], ray[at + 5], ray[at + 6], ray[at + 7] = dx, dy, dz, 0.0    # direction, time
    ray[at + 8] = far                                                       # tfar
    bits[at + 9], bits[at + 10], bits[at + 11] = INVALID, 0, 0              # mask (every geometry), id, flags


@numba.njit(cache=True, nogil=True, inline="always")
def closest(intersect, scene, record, ox, oy, oz, dx, dy, dz, far):
    """(primitive, t, u, v) of the first face the ray meets within `far` (primitive -1 for none), through
    a `record`: for compiled loops that make their rays as they go (viewer.rays.sides.first_face).
    `intersect`, `scene`: a `Scene`'s `handle`."""
    ray, bits, at, address = record
    _ray(ray, bits, at, ox, oy, oz, dx, dy, dz, far)
    bits[at + 18], bits[at + 19] = INVALID, INVALID   # hit.geomID, hit.instID[0]
    _call(intersect, scene[0], address, 0)
    if bits[at + 18] == INVALID:
        return -1, np.inf, 0.0, 0.0
    instance = bits[at + 19]
    first = 0 if instance == INVALID else scene[1 + instance]
    return (first + np.int64(bits[at + 17]), np.float64(ray[at + 8]), np.float64(ray[at + 15]),
            np.float64(ray[at + 16]))


@numba.njit(cache=True, nogil=True, inline="always")
def occluded(occluded_query, scene, record, ox, oy, oz, dx, dy, dz, length):
    """Whether the segment o + t d, 0 <= t <= length, meets a face (the first found), through a `record`:
    for compiled loops that make their segments as they go (viewer.probes.weights)."""
    ray, bits, at, address = record
    _ray(ray, bits, at, ox, oy, oz, dx, dy, dz, np.float32(length))
    _call(occluded_query, scene[0], address, 0)
    return ray[at + 8] < 0.0   # Embree sets tfar to -inf when the segment is blocked


@numba.njit(cache=True, nogil=True, parallel=True)
def _closest(intersect, scene, o, d, far, primitive, t, u, v):
    count = o.shape[0]
    for block in numba.prange((count + BLOCK - 1) // BLOCK):
        ray = record()
        for i in range(block * BLOCK, min(count, (block + 1) * BLOCK)):
            primitive[i], t[i], u[i], v[i] = closest(intersect, scene, ray, o[i, 0], o[i, 1], o[i, 2], d[i, 0],
                                                     d[i, 1], d[i, 2], far)


@numba.njit(cache=True, nogil=True, parallel=True)
def _occluded(query, scene, o, d, length, out):
    count = o.shape[0]
    for block in numba.prange((count + BLOCK - 1) // BLOCK):
        ray = record()
        for i in range(block * BLOCK, min(count, (block + 1) * BLOCK)):
            out[i] = occluded(query, scene, ray, o[i, 0], o[i, 1], o[i, 2], d[i, 0], d[i, 1], d[i, 2], length[i])

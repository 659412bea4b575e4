"""Embree's eight-ray packet queries (rtcIntersect8, rtcOccluded8) called from compiled loops, as
viewer/rays/embree.py calls its one-ray ones: rays from nearby origins in nearly the same direction,
which Embree traverses together (the seen rays of a probe lattice, shadow segments from neighbouring
points to one end), with the hits and answers of the rays traced one at a time.
"""

from __future__ import annotations

import numba
import numpy as np
from llvmlite import ir
from numba.core import types
from numba.extending import intrinsic

from viewer.rays.embree import INVALID


@intrinsic
def _call4(typingctx, function, valid, scene, record, arguments):
    """function(valid, scene, record, arguments): `_call` for a packet query (rtcIntersect8)."""
    if not all(isinstance(a, types.Integer) for a in (function, valid, scene, record, arguments)):
        return None

    def codegen(context, builder, signature, args):
        word = ir.IntType(64)
        kind = ir.FunctionType(ir.VoidType(), [word, word, word, word])
        values = [builder.zext(a, word) if a.type.width < 64 else a for a in args]
        builder.call(builder.inttoptr(values[0], kind.as_pointer()), values[1:])
        return context.get_dummy_value()

    return types.void(function, valid, scene, record, arguments), codegen


LANES = 8
"""Rays of a packet (`closest8`): RTCRayHit8 holds each field for 8 rays in a row (rtcore_ray.h), its
ray's fields at 0-11 x 8 and its hit's at 12-19 x 8 (Ng, u, v, primID, geomID, instID), 32-byte aligned."""


@numba.njit(cache=True, nogil=True, inline="always")
def packet():
    """A thread's RTCRayHit8 record and its valid mask: (floats, the same memory as uint32, the first
    32-byte aligned offset into them, its address, the mask, its aligned offset, its address)."""
    ray = np.empty(20 * LANES + 16, np.float32)
    at = (32 - ray.ctypes.data % 32) % 32 // 4
    valid = np.empty(LANES + 8, np.int32)
    first = (32 - valid.ctypes.data % 32) % 32 // 4
    return ray, ray.view(np.uint32), at, ray.ctypes.data + 4 * at, valid, first, valid.ctypes.data + 4 * first


@numba.njit(cache=True, nogil=True, inline="always")
def closest8(intersect8, scene, record, o, d, rays, per_origin, far, primitive, t):
    """`closest` for up to LANES rays in one packet: ray r = rays[l] (-1: no ray in lane l) starts at
    o[r // per_origin] along d[r] (flat (R, 3)), within `far`; primitive[r] and t[r] as `closest` gives
    them. Parallel rays from nearby origins share the hierarchy's traversal: 442,000 seen rays of a
    validation room 20.8 -> 15.8 ms on two cores, every one meeting the same face at the same t."""
    ray, bits, at, address, valid, first, valid_address = record
    w = LANES
    for lane in range(w):
        r = rays[lane]
        valid[first + lane] = 0 if r < 0 else -1
        if r < 0:
            continue
        q = r // per_origin
        ray[at + lane], ray[at + w + lane], ray[at + 2 * w + lane] = o[q, 0], o[q, 1], o[q, 2]
        ray[at + 4 * w + lane], ray[at + 5 * w + lane], ray[at + 6 * w + lane] = d[r, 0], d[r, 1], d[r, 2]
        ray[at + 3 * w + lane], ray[at + 7 * w + lane], ray[at + 8 * w + lane] = 0.0, 0.0, far   # tnear, time, tfar
        bits[at + 9 * w + lane], bits[at + 10 * w + lane], bits[at + 11 * w + lane] = INVALID, 0, 0   # mask, id, flags
        bits[at + 18 * w + lane], bits[at + 19 * w + lane] = INVALID, INVALID   # hit.geomID, hit.instID[0]
    _call4(intersect8, valid_address, scene[0], address, 0)
    for lane in range(w):
        r = rays[lane]
        if r < 0:
            continue
        if bits[at + 18 * w + lane] == INVALID:
            primitive[r], t[r] = -1, np.inf
        else:
            instance = bits[at + 19 * w + lane]
            offset = 0 if instance == INVALID else scene[1 + instance]
            primitive[r], t[r] = offset + np.int64(bits[at + 17 * w + lane]), np.float64(ray[at + 8 * w + lane])


@numba.njit(cache=True, nogil=True, inline="always")
def occluded8(occluded8_query, scene, record, o, d, length, lanes, blocked):
    """`occluded` for up to LANES segments in one packet: lane l (where lanes[l]) from o[l] along unit
    d[l] (each (LANES, 3)) for length[l]; blocked[l] whether it meets a face, through a `packet` record
    (RTCRay8 is RTCRayHit8's first twelve fields)."""
    ray, bits, at, address, valid, first, valid_address = record
    w = LANES
    for lane in range(w):
        valid[first + lane] = -1 if lanes[lane] else 0
        if not lanes[lane]:
            continue
        ray[at + lane], ray[at + w + lane], ray[at + 2 * w + lane] = o[lane, 0], o[lane, 1], o[lane, 2]
        ray[at + 4 * w + lane], ray[at + 5 * w + lane], ray[at + 6 * w + lane] = d[lane, 0], d[lane, 1], d[lane, 2]
        ray[at + 3 * w + lane], ray[at + 7 * w + lane] = 0.0, 0.0   # tnear, time
        ray[at + 8 * w + lane] = np.float32(length[lane])           # tfar
        bits[at + 9 * w + lane], bits[at + 10 * w + lane], bits[at + 11 * w + lane] = INVALID, 0, 0
    _call4(occluded8_query, valid_address, scene[0], address, 0)
    for lane in range(w):
        blocked[lane] = lanes[lane] and ray[at + 8 * w + lane] < 0.0   # Embree sets tfar to -inf there

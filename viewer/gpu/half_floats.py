"""Half floats read back from a texture, widened to float32 in one compiled pass: numpy widens float16 in
software, 7.7 ns a value on this project's 2-core machine, where the lightmap's read-back after every
lamp drag widens a million texels' three channels."""

from __future__ import annotations

import numba
import numpy as np


def widened(halves: np.ndarray, channels: int) -> np.ndarray:
    """(N, channels) float32: the first `channels` of the (N, C) float16 `halves`, exactly as numpy's
    `astype(np.float32)` gives them (zeros, subnormals, infinities and NaNs included)."""
    bits = np.ascontiguousarray(halves).view(np.uint16).reshape(len(halves), -1)
    out = np.empty((len(bits), channels), np.uint32)
    _widen(bits, out)
    return out.view(np.float32)


@numba.njit(cache=True, nogil=True, parallel=True)
def _widen(bits, out):
    for i in numba.prange(bits.shape[0]):
        for c in range(out.shape[1]):
            h = np.uint32(bits[i, c])
            sign = (h & np.uint32(0x8000)) << np.uint32(16)
            exponent = (h >> np.uint32(10)) & np.uint32(0x1F)
            mantissa = h & np.uint32(0x3FF)
            if exponent == 0x1F:          # infinity or NaN
                out[i, c] = sign | np.uint32(0x7F800000) | (mantissa << np.uint32(13))
            elif exponent != 0:           # normal
                out[i, c] = sign | ((exponent + np.uint32(112)) << np.uint32(23)) | (mantissa << np.uint32(13))
            elif mantissa == 0:           # zero
                out[i, c] = sign
            else:                         # subnormal: normalize the mantissa
                shift = np.uint32(0)
                while (mantissa & np.uint32(0x400)) == 0:
                    mantissa <<= np.uint32(1)
                    shift += np.uint32(1)
                out[i, c] = (sign | ((np.uint32(113) - shift) << np.uint32(23))
                             | ((mantissa & np.uint32(0x3FF)) << np.uint32(13)))

"""What the exported network is fed: the encoded inputs, the same through asinh, and its seen filter's
two products, which compiled code here computes faster than onnxruntime does inside the graph.

ProbeNet (viewer/training/models.py) filters the seen light and the unshadowed gather, each times the
probes' open share, with one learned 3x3x3 kernel per SH coefficient (the edges repeated). onnxruntime's
CPU convolution has no depthwise path in 3D: on the Cornell box's three colour passes the two filters
took 13.5 ms of the network's 40 (one thread, a 2-core AMD EPYC machine). The export moves them out of
the graph (`viewer.training.export.split_filters`), which then takes their products as inputs, and
writes the kernels on the model's card; a graph that filters itself is fed as before.
"""

from __future__ import annotations

import numba
import numpy as np

from viewer.neural import encoding

FILTERED = {"seen_filtered": encoding.SEEN, "bounce_filtered": encoding.BOUNCE}
"""The graph inputs of a split network, and the encoding's channels each filters (times the open share)."""


def feed(names: list[str], inputs: np.ndarray, kernels: np.ndarray | None) -> dict[str, np.ndarray]:
    """The session's inputs by `names` for encoded `inputs` (passes, CHANNELS, M, M, M): `inputs`, the
    asinh `compressed` ones, and the FILTERED ones by `kernels` (9, 27) (the card's)."""
    out = {names[0]: inputs}
    for name in names[1:]:
        if name in FILTERED:
            if kernels is None:
                raise ValueError(f"the network takes {name} but its card has no filter kernels")
            out[name] = filtered(inputs, FILTERED[name], kernels)
        else:
            out[name] = encoding.compressed(inputs)
    return out


def filtered(inputs: np.ndarray, channels: slice, kernels: np.ndarray) -> np.ndarray:
    """(passes, 9, M, M, M) float32: `inputs`' 9 `channels` times the open share, each convolved with its
    3x3x3 kernel (`kernels` (9, 27): the Conv3d weight (9, 1, 3, 3, 3) flattened), the lattice's faces repeated beyond it: what
    `ProbeNet.seen_filter` (a grouped Conv3d, replicate padding) gives."""
    inputs = np.asarray(inputs, np.float32)
    weights = np.ascontiguousarray(np.asarray(kernels, np.float32).reshape(-1, 3, 3, 3))
    if weights.shape[0] != channels.stop - channels.start:
        raise ValueError(f"{weights.shape[0]} filter kernels for {channels.stop - channels.start} channels")
    out = np.empty((inputs.shape[0], weights.shape[0], *inputs.shape[2:]), np.float32)
    _depthwise(inputs, channels.start, encoding.OPEN, weights, out)
    return out


@numba.njit(cache=True, nogil=True, parallel=True, fastmath=True)
def _depthwise(inputs, first, opened, weights, out):
    """out[b, c] = weights[c] (3x3x3) convolved with inputs[b, first + c] x inputs[b, opened], edges
    repeated: each (pass, channel) padded into a block of its own, then three taps a row at a time (the
    rows' loops vectorize: 1.0 ms for the Cornell box's three passes on two cores, where one tap at a
    time and a clamped index per padded cell took 2.5)."""
    passes, count, m = out.shape[0], out.shape[1], out.shape[2]
    for job in numba.prange(passes * count):
        b, c = job // count, job % count
        padded = np.empty((m + 2, m + 2, m + 2), np.float32)
        source, share = inputs[b, first + c], inputs[b, opened]
        for z in range(m):
            for y in range(m):
                row, values, weight = padded[z + 1, y + 1], source[z, y], share[z, y]
                for x in range(m):
                    row[x + 1] = values[x] * weight[x]
                row[0], row[m + 1] = row[1], row[m]
            padded[z + 1, 0] = padded[z + 1, 1]
            padded[z + 1, m + 1] = padded[z + 1, m]
        padded[0] = padded[1]
        padded[m + 1] = padded[m]
        target = out[b, c]
        for z in range(m):
            for y in range(m):
                row = target[z, y]
                for x in range(m):
                    row[x] = 0.0
                for i in range(3):
                    for j in range(3):
                        taps = padded[z + i, y + j]
                        w0, w1, w2 = weights[c, i, j, 0], weights[c, i, j, 1], weights[c, i, j, 2]
                        for x in range(m):
                            row[x] += w0 * taps[x] + w1 * taps[x + 1] + w2 * taps[x + 2]

"""The network's last step, outside its graph: from the head's corrections to the probes' SH.

ProbeNet (viewer/training/models.py) ends in arithmetic per probe: the seen light's filtered products
divided by the open shares around the probe, the unshadowed gather's detail added where the rays let it
through, the learned gains, the head's correction of the reflected light scaled by the local light, and
the direct light added to it. onnxruntime runs each of these as its own pass over the whole lattice:
2.1 ms of the network's 7.2 on a 24^3 lattice's three colour passes (two threads, an Intel Xeon). The
export cuts the graph after its head (`viewer.training.onnx_graph.split_tail`) and writes the two gains
on the card; `Tail.probes` does the rest in one compiled pass over the probes, in 0.6 ms: the same sums
to float32 round-off (the shipped network's output within 1e-7 of its whole graph's;
tests/neural/test_network_tail.py).
"""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

import numba
import numpy as np

from viewer.neural import encoding
from viewer.neural.network_feed import FILTERED, feed, filtered_products

_OPEN, _SEEN, _BOUNCE, _DIRECT = encoding.OPEN, encoding.SEEN.start, encoding.BOUNCE.start, encoding.DIRECT.start
HEAD = "head"
"""The output of a graph cut after its head (`viewer.training.onnx_graph.split_tail`): the head's 19 channels,
which `Tail.probes` turns into the network's output."""
REFLECTED_FLOOR = 0.01
"""The reflected light's correction is relative to the bounce: times |bounce DC| + this. Reflected light
is proportional to the albedo, and so is the bounce; scaled by the direct light instead, the correction
gave rooms with walls of albedo 0.01-0.04 five to seven times their true indirect light."""
DETAIL_FLOOR, DETAIL_MAX = 1e-4, 4.0
"""The detail gain's guards (`viewer.training.models.detail_gain`): the smallest unshadowed light (in the
encoding's units, where the room's mean direct DC is 1) it divides by, and the largest gain it gives."""


@dataclass(frozen=True)
class Tail:
    """The learned gains of the reflected light's two inputs: the unshadowed bounce's and the filtered
    seen light's."""

    bounce_gain: float
    seen_gain: float

    @classmethod
    def of(cls, card: dict) -> "Tail | None":
        """The tail a model's card carries (None: its graph ends with its own)."""
        gains = card.get("tail")
        return None if gains is None else cls(float(gains["bounce_gain"]), float(gains["seen_gain"]))

    def to_dict(self) -> dict:
        return {"bounce_gain": self.bounce_gain, "seen_gain": self.seen_gain}

    def probes(self, inputs: np.ndarray, seen_filtered: np.ndarray, bounce_filtered: np.ndarray,
               head: np.ndarray) -> np.ndarray:
        """(passes, 19, M, M, M) float32, what the whole graph gives: 9 SH of all the light, 9 of the
        reflected light and the validity logit, from the encoded `inputs` (passes, CHANNELS, M, M, M), the
        seen filter's two products (passes, 9, M, M, M: `network_feed.feed`) and the head's output (passes,
        19, M, M, M)."""
        inputs = np.ascontiguousarray(inputs, np.float32)
        out = np.empty(head.shape, np.float32)
        _tail(inputs, np.ascontiguousarray(seen_filtered, np.float32),
              np.ascontiguousarray(bounce_filtered, np.float32), np.ascontiguousarray(head, np.float32),
              np.float32(self.bounce_gain), np.float32(self.seen_gain), out)
        return out


def fed_names(graph_inputs: list[str], tail: Tail | None) -> list[str]:
    """What `network_feed.feed` makes for a graph taking `graph_inputs`: those, or where a `tail` finishes
    the graph, the encoded inputs, their asinh and the seen filter's products, which the tail reads."""
    return ["inputs", "compressed", *FILTERED] if tail is not None else list(graph_inputs)


def run_graph(session, fed: dict[str, np.ndarray], tail: Tail | None) -> np.ndarray:
    """The network's output (passes, 19, M, M, M) from onnxruntime's `session` on `fed` (`fed_names`), its
    graph finished by `tail` where it ends at its head."""
    out = _graph(session, fed)
    return out if tail is None else _finished(tail, fed, out)


def run_overlapped(session, inputs: np.ndarray, kernels: np.ndarray, walls, previous: dict | None,
                   tail: Tail) -> tuple[dict[str, np.ndarray], np.ndarray]:
    """`feed` and `run_graph` for a graph that ends at its head, the seen filter's products (which only the
    tail reads) made on a thread of their own while onnxruntime runs the head, which leaves part of the
    second core idle; `walls` (`network_feed.WallTaps`, None, or what makes them: a new geometry's, 1.2 ms
    on a 24^3 lattice) are made there too. Returns the feed and the output."""
    fed = feed(["inputs", "compressed"], inputs, kernels, None, previous)

    def products() -> dict[str, np.ndarray]:
        taps = walls() if callable(walls) else walls
        return filtered_products(inputs, kernels, taps)

    made = _FILTERS.submit(products)
    head = _graph(session, fed)
    fed.update(made.result())
    return fed, _finished(tail, fed, head)


def _graph(session, fed: dict[str, np.ndarray]) -> np.ndarray:
    """The graph's output on the inputs of `fed` it takes."""
    return session.run(None, {i.name: fed[i.name] for i in session.get_inputs()})[0]


def _finished(tail: Tail, fed: dict[str, np.ndarray], head: np.ndarray) -> np.ndarray:
    return tail.probes(fed["inputs"], fed["seen_filtered"], fed["bounce_filtered"], head)


_FILTERS = ThreadPoolExecutor(max_workers=1, thread_name_prefix="seen-filter")
"""The thread the seen filter's products are made on beside the network's head (`run_overlapped`)."""


@numba.njit(cache=True, nogil=True, parallel=True)
def _tail(inputs, seen_filtered, bounce_filtered, head, bounce_gain, seen_gain, out):
    """ProbeNet.forward after its head, a slab of one pass a task (the names are the model's):
        weight = the open shares' 3x3x3 mean, edges repeated, at least 1/27
        seen, smooth = the filtered products / weight
        seen += clip(seen DC / max(smooth DC, DETAIL_FLOOR), 0, DETAIL_MAX) x (bounce - smooth)
        reflected = bounce_gain x bounce + seen_gain x seen + head's correction x magnitude
        magnitude = (|bounce DC| + |the seen DC's 3x3x3 mean within the lattice|) / 2 + REFLECTED_FLOOR
        all the light = direct + reflected.
    The two 3x3x3 means are summed an axis at a time over the slab, and every loop over a row of probes
    holds no branch, so that it vectorizes: 0.6 ms for a 24^3 lattice's three passes on two cores (about
    what reading its 14 MB takes), where 27 taps a probe took 1.0."""
    passes, m = inputs.shape[0], inputs.shape[2]
    sh = seen_filtered.shape[1]
    floor, cells = np.float32(1.0 / 27.0), np.float32(27.0)
    half, base = np.float32(0.5), np.float32(REFLECTED_FLOOR)
    low, high, zero = np.float32(DETAIL_FLOOR), np.float32(DETAIL_MAX), np.float32(0.0)
    for job in numba.prange(passes * m):
        task = np.int64(job)   # the loop's index is unsigned: mixed with signed ones numba makes floats
        b, i = task // m, task % m
        shares, seen_dc = np.zeros((m, m), np.float32), np.zeros((m, m), np.float32)
        counted = 0
        # along the first axis: the open shares with the lattice's edges repeated, the seen DC within it
        for di in range(-1, 2):
            a = min(max(i + di, 0), m - 1)
            shares += inputs[b, _OPEN, a]
            if 0 <= i + di < m:
                seen_dc += inputs[b, _SEEN, i + di]
                counted += 1
        shares, seen_dc = _box_rows(shares, True), _box_rows(seen_dc, False)
        shares, seen_dc = _box_rows(shares.T.copy(), True).T, _box_rows(seen_dc.T.copy(), False).T
        weight, magnitude, gain = np.empty(m, np.float32), np.empty(m, np.float32), np.empty(m, np.float32)
        for j in range(m):
            count_j = np.float32(counted * (3 - (j == 0) - (j == m - 1)))
            for k in range(m):
                count = count_j * np.float32(3 - (k == 0) - (k == m - 1))
                w = max(shares[j, k] / cells, floor)
                weight[k] = w
                magnitude[k] = half * (abs(inputs[b, _BOUNCE, i, j, k]) + abs(seen_dc[j, k] / count)) + base
                smooth_dc = bounce_filtered[b, 0, i, j, k] / w
                g = (seen_filtered[b, 0, i, j, k] / w) / max(smooth_dc, low)
                gain[k] = min(max(g, zero), high)
            for s in range(sh):
                bounce, direct = inputs[b, _BOUNCE + s, i, j], inputs[b, _DIRECT + s, i, j]
                seen, smooth = seen_filtered[b, s, i, j], bounce_filtered[b, s, i, j]
                correction, reflected, total = head[b, sh + s, i, j], out[b, sh + s, i, j], out[b, s, i, j]
                for k in range(m):
                    w = weight[k]
                    detail = seen[k] / w + gain[k] * (bounce[k] - smooth[k] / w)
                    light = bounce_gain * bounce[k] + seen_gain * detail + correction[k] * magnitude[k]
                    reflected[k] = light
                    total[k] = direct[k] + light
            out[b, 2 * sh, i, j] = head[b, 2 * sh, i, j]


@numba.njit(cache=True, nogil=True, inline="always")
def _box_rows(plane, repeat):
    """(m, m) the sums of three neighbours along each row of `plane`: the row's ends repeated (`repeat`)
    or left out."""
    m = plane.shape[1]
    out = np.empty_like(plane)
    for j in range(plane.shape[0]):
        row, sums = plane[j], out[j]
        for k in range(1, m - 1):
            sums[k] = row[k - 1] + row[k] + row[k + 1]
        if m == 1:
            sums[0] = 3 * row[0] if repeat else row[0]
        else:
            sums[0] = (2 * row[0] if repeat else row[0]) + row[1]
            sums[m - 1] = row[m - 2] + (2 * row[m - 1] if repeat else row[m - 1])
    return out

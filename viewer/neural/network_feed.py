"""What the exported network is fed: the encoded inputs, the same through asinh, and its seen filter's
two products, which compiled code here computes faster than onnxruntime does inside the graph.

ProbeNet (viewer/training/models.py) filters the seen light and the unshadowed gather, each times the
probes' open share, with one learned 3x3x3 kernel per SH coefficient (the edges repeated). onnxruntime's
CPU convolution has no depthwise path in 3D: on the Cornell box's three colour passes the two filters
took 13.5 ms of the network's 40 (one thread, a 2-core AMD EPYC machine). The export moves them out of
the graph (`viewer.training.onnx_graph.split_filters`), which then takes their products as inputs, and
writes the kernels on the model's card; a graph that filters itself is fed as before. Outside the graph
the filter also stops at walls (`WallTaps`), as training's does.
"""

from __future__ import annotations

import weakref

import numba
import numpy as np

from viewer.neural import encoding

FILTERED = {"seen_filtered": encoding.SEEN, "bounce_filtered": encoding.BOUNCE}
"""The graph inputs of a split network, and the encoding's channels each filters (times the open share)."""


def feed(names: list[str], inputs: np.ndarray, kernels: np.ndarray | None,
         walls: "WallTaps | None" = None, previous: dict | None = None) -> dict[str, np.ndarray]:
    """The session's inputs by `names` for encoded `inputs` (passes, CHANNELS, M, M, M): `inputs`, the
    asinh `compressed` ones, and the FILTERED ones by `kernels` (9, 27) (the card's), stopped at the
    `walls` of the lattice where given (`WallTaps`). `previous`: an earlier feed of the same names,
    whose compressed rows are reused where the inputs are the same (`encoding.compressed`)."""
    wanted = [name for name in names[1:] if name in FILTERED]
    if wanted and kernels is None:
        raise ValueError(f"the network takes {wanted[0]} but its card has no filter kernels")
    products = filtered_products(inputs, kernels, walls, wanted) if wanted else {}
    out = {names[0]: inputs}
    for name in names[1:]:
        out[name] = products[name] if name in products else encoding.compressed(
            inputs, None if previous is None else (previous[names[0]], previous[name]))
    return out


def filtered(inputs: np.ndarray, channels: slice, kernels: np.ndarray, walls: "WallTaps | None" = None) -> np.ndarray:
    """(passes, 9, M, M, M) float32: `inputs`' 9 `channels` times the open share, each convolved with its
    3x3x3 kernel (`kernels` (9, 27): the Conv3d weight (9, 1, 3, 3, 3) flattened), the lattice's faces
    repeated beyond it: what `ProbeNet.seen_filter` (a grouped Conv3d, replicate padding) gives. With
    `walls`, a tap across a surface takes the probe's own light as a tap beyond the faces does, and the
    probe's sum is scaled so that the graph's division by the plain average of the open shares around it
    divides by the average of those the taps took (`WallTaps`)."""
    return _filtered(inputs, [channels], kernels, walls)[0]


def filtered_products(inputs: np.ndarray, kernels: np.ndarray, walls: "WallTaps | None" = None,
                      names: list[str] | None = None) -> dict[str, np.ndarray]:
    """`filtered` of the FILTERED `names` (default all), in one pass for all of them: the walled probes'
    taps' light read into one block for both products (`_walled`): val-00001's two products 3.1 -> 2.5 ms
    on two cores, the same sums."""
    names = list(FILTERED) if names is None else names
    return dict(zip(names, _filtered(inputs, [FILTERED[name] for name in names], kernels, walls)))


def _filtered(inputs: np.ndarray, parts: list[slice], kernels: np.ndarray, walls: "WallTaps | None"):
    """(len(parts), passes, 9, M, M, M) float32: `filtered` of each of `parts`."""
    inputs = np.ascontiguousarray(inputs, np.float32)
    weights = np.ascontiguousarray(np.asarray(kernels, np.float32).reshape(-1, 3, 3, 3))
    for channels in parts:
        if weights.shape[0] != channels.stop - channels.start:
            raise ValueError(f"{weights.shape[0]} filter kernels for {channels.stop - channels.start} channels")
    firsts = np.array([channels.start for channels in parts], np.int64)
    out = np.empty((len(parts), inputs.shape[0], weights.shape[0], *inputs.shape[2:]), np.float32)
    _depthwise(inputs, firsts, encoding.OPEN, weights, out)
    if walls is not None and len(walls.rows) and walls.side == inputs.shape[2]:
        _walled(inputs, firsts, encoding.OPEN, weights.reshape(weights.shape[0], 27), walls.rows, walls.cells,
                walls.local, walls.scale, out)
    return out


class WallTaps:
    """Where the network's 3x3x3 seen filter must stop at a surface: the probes of a cubic lattice some of
    whose 27 taps cross a closed link (`SeenRays.links`: the segment between two neighbours meets a
    face), and the probe each of their taps takes instead, as `SeenRays.filtered` takes them (the link
    along the last axis from the probe, then along the second from there, then along the first: a tap
    across a wall takes the probe's own light, one beyond the lattice's faces repeats it). With plain
    taps a thin wall's dark side averaged in the lit side's light: the doorway's dark room got 1.36x its
    true light where the seen light itself gave 1.04x. Training filters the same way
    (`viewer.training.models.walled_filter`).

    Made once per geometry (links and open shares are the geometry's): 1692 of the Cornell box's 13,824
    probes, in 1.0 ms on two cores; each filter of the network's seen light then takes 0.6 ms more."""

    def __init__(self, links: np.ndarray, opened: np.ndarray):
        m = links.shape[1]
        self.side = m
        links = np.ascontiguousarray(links, np.bool_)
        opened = np.ascontiguousarray(opened, np.float32).reshape(-1)
        near = np.flatnonzero(_near_closed(links))   # the others take the plain taps
        walled, differs, plain_weight, walled_weight = _walled_taps(links, opened, near)
        self.rows = near[differs]
        """(S,) the probes (flat, x slowest) some of whose taps differ from the plain filter's."""
        self.scale = (np.maximum(plain_weight[differs], 1.0)
                      / np.maximum(walled_weight[differs], 1.0)).astype(np.float32)
        """(S,) the graph's open-share average over each probe's plain taps (at least 1/27), over the one
        its taps take."""
        self.cells, self.local = _taken(np.ascontiguousarray(walled[differs]), m ** 3)
        """(T,) the probes their taps take, each once, in order: `_walled` reads their light into one block
        first; and (S, 27) each tap's place among them. Marked in an array of the lattice's probes, not
        sorted: 0.05 ms where numpy's `unique` took 0.7 of the 1.1 these taps took (val-00001's 1,690
        walled probes)."""

    @property
    def sources(self) -> np.ndarray:
        """(S, 27) the probe each of their taps takes, in the kernel's flat order."""
        return self.cells[self.local]


@numba.njit(cache=True, nogil=True)
def _taken(sources, probes):
    """`np.unique(sources, return_inverse=True)` of (S, 27) probe indices below `probes`: the distinct ones
    in order (T,) int32, and each entry's place among them (S, 27) int32."""
    place = np.full(probes, -1, np.int32)
    flat = sources.reshape(-1)
    for q in flat:
        place[q] = 0
    cells = np.empty(probes, np.int32)
    count = 0
    for q in range(probes):
        if place[q] == 0:
            place[q], cells[count] = count, q
            count += 1
    local = np.empty(flat.shape[0], np.int32)
    for i in range(flat.shape[0]):
        local[i] = place[flat[i]]
    return cells[:count].copy(), local.reshape(sources.shape)


_last_walls: tuple = (None, None)


def wall_taps(seen) -> "WallTaps | None":
    """The `WallTaps` of `seen` (`SeenRays`; None, or one without links: no walls to stop at), kept for
    the last seen rays asked about: their geometry's."""
    global _last_walls
    if seen is None or seen.links is None:
        return None
    kept, taps = _last_walls   # read once: another thread's field may replace it meanwhile
    if kept is None or kept() is not seen:
        taps = WallTaps(seen.links, seen.open)
        _last_walls = (weakref.ref(seen), taps)
    return taps


def encoding_walls(enc: encoding.Encoding) -> "WallTaps | None":
    """The `WallTaps` of an `encoding.encode` result (its seen rays' links and open shares), for callers
    that run the network on one without an `Encoder`'s seen rays; None where nothing was seen."""
    if enc.links is None:
        return None
    return WallTaps(enc.links, enc.inputs[0, encoding.OPEN])


def tap_sources(links: np.ndarray) -> np.ndarray:
    """(27, M^3) int64: the probe each tap of each probe takes, with closed `links` (3, M, M, M) taken as
    the lattice's faces are: from the probe along the last axis, then along the second from there, then
    along the first, as `SeenRays.filtered` steps (where no link is closed: the faces repeated)."""
    walled, _, _, _ = _walled_taps(np.ascontiguousarray(links, np.bool_), None)
    return np.ascontiguousarray(walled.T, np.int64)


def _walled_taps(links: np.ndarray, opened: np.ndarray | None, probes: np.ndarray | None = None):
    """(N, 27) int32: the probe each tap of each of `probes` (N,) (None: every probe, flat) takes, walled;
    (N,) bool: whether any of a probe's taps differs from the plain filter's; and (N,) twice: the sums of
    `opened` (1 where None) over each probe's plain taps and over its walled ones."""
    m = links.shape[1]
    probes = np.arange(m ** 3) if probes is None else np.asarray(probes, np.int64)
    walled, differs = np.empty((len(probes), 27), np.int32), np.empty(len(probes), np.bool_)
    sums = np.empty((2, len(probes)), np.float32)
    _taps(links, probes, walled, differs, np.ones(m ** 3, np.float32) if opened is None else opened, sums)
    return walled, differs, sums[0], sums[1]


@numba.njit(cache=True, nogil=True)
def _near_closed(links):
    """(M^3,) bool: whether a closed link lies among those a probe's 27 taps may cross (the links from the
    3x3x3 cells around it); the others' taps are the plain filter's. The cells with a closed link, grown by
    one along each axis in turn. (A 24^3 lattice's walled taps were all worked out in 1.0 ms, where most
    probes have no wall near them: 0.3 ms now.)"""
    m = links.shape[1]
    grown = np.empty((m, m, m), np.bool_)
    for i in range(m):
        for j in range(m):
            for k in range(m):
                grown[i, j, k] = not (links[0, i, j, k] and links[1, i, j, k] and links[2, i, j, k])
    for axis in range(3):
        before = grown.copy()
        for i in range(m):
            for j in range(m):
                for k in range(m):
                    if before[i, j, k]:
                        for step in (-1, 1):
                            a, b, c = i + step * (axis == 0), j + step * (axis == 1), k + step * (axis == 2)
                            if 0 <= a < m and 0 <= b < m and 0 <= c < m:
                                grown[a, b, c] = True
    return grown.reshape(-1)


@numba.njit(cache=True, nogil=True, parallel=True)
def _taps(links, probes, walled, differs, opened, sums):
    """The walled taps of `probes`, where they differ from the plain ones and the open shares' sums over
    both, in one pass (1.7 -> 1.0 ms for every probe of a 24^3 lattice, where the plain taps were written
    out and compared after)."""
    m = links.shape[1]
    for n in numba.prange(probes.shape[0]):
        p = probes[n]
        i, j, k = p // (m * m), (p // m) % m, p % m
        plain_sum = walled_sum = 0.0
        other = False
        for t in range(27):
            di, dj, dk = t // 9 - 1, (t // 3) % 3 - 1, t % 3 - 1
            ip, jp, kp = min(max(i + di, 0), m - 1), min(max(j + dj, 0), m - 1), min(max(k + dk, 0), m - 1)
            kw = kp if kp != k and links[2, i, j, min(k, kp)] else k
            jw = jp if jp != j and links[1, i, min(j, jp), kw] else j
            iw = ip if ip != i and links[0, min(i, ip), jw, kw] else i
            q, q0 = (iw * m + jw) * m + kw, (ip * m + jp) * m + kp
            walled[n, t] = q
            other |= q != q0
            plain_sum += opened[q0]
            walled_sum += opened[q]
        sums[0, n], sums[1, n] = plain_sum, walled_sum
        differs[n] = other


@numba.njit(cache=True, nogil=True, parallel=True, fastmath=True)
def _depthwise(inputs, firsts, opened, weights, out):
    """out[f, b, c] = weights[c] (3x3x3) convolved with inputs[b, firsts[f] + c] x inputs[b, opened], edges
    repeated: each (part, pass, channel) padded into a block of its own, laid out flat, so that each row of
    three taps of a whole slab of the output is one long loop over the block (its rows' two padding cells
    summed too, and dropped), which vectorizes: rows of the lattice's own 24 left a third of each loop to
    its scalar end, and a loop a tap read and wrote the slab three times as often (val-00001's two
    products: 1.80 -> 1.60 ms on one core)."""
    parts, passes, count, m = out.shape[0], out.shape[1], out.shape[2], out.shape[3]
    s = m + 2
    plane = s * s
    for job in numba.prange(parts * passes * count):
        f, b, c = job // (passes * count), (job // count) % passes, job % count
        padded = np.empty((m + 2) * plane + 2, np.float32)   # two more: the last row's padding taps
        source, share = inputs[b, firsts[f] + c], inputs[b, opened]
        for z in range(m):
            for y in range(m):
                at = (z + 1) * plane + (y + 1) * s
                values, weight = source[z, y], share[z, y]
                for x in range(m):
                    padded[at + x + 1] = values[x] * weight[x]
                padded[at], padded[at + m + 1] = padded[at + 1], padded[at + m]
            at = (z + 1) * plane
            padded[at:at + s] = padded[at + s:at + 2 * s]
            padded[at + (m + 1) * s:at + plane] = padded[at + m * s:at + (m + 1) * s]
        padded[:plane] = padded[plane:2 * plane]
        padded[(m + 1) * plane:(m + 2) * plane] = padded[m * plane:(m + 1) * plane]
        padded[(m + 2) * plane:] = 0.0
        target, kernel = out[f, b, c], weights[c]
        n = m * s
        slab = np.empty(n, np.float32)
        for z in range(m):
            slab[:] = 0.0
            for i in range(3):
                for j in range(3):   # a row of three taps in one loop: a third of the slab's reads and writes
                    w0, w1, w2 = kernel[i, j, 0], kernel[i, j, 1], kernel[i, j, 2]
                    at = (z + i) * plane + j * s
                    t0, t1, t2 = padded[at:at + n], padded[at + 1:at + 1 + n], padded[at + 2:at + 2 + n]
                    for e in range(n):
                        slab[e] += w0 * t0[e] + w1 * t1[e] + w2 * t2[e]
            for y in range(m):
                target[z, y, :] = slab[y * s:y * s + m]


WALLED_ROWS = 32
"""Walled probes a task of `_walled` takes."""
WALLED_CELLS = 256
"""Taken probes a task of `_walled` reads into its block."""


@numba.njit(cache=True, nogil=True, parallel=True, fastmath=True)
def _walled(inputs, firsts, opened, weights, rows, cells, local, scale, out):
    """`_depthwise`'s sums made again at the probes `rows` (S,) over their taps (`WallTaps`: the probes
    `cells` (T,) they take, each tap's place among them `local` (S, 27)), times their `scale` (S,). The
    taken probes' light, every part's channels side by side and their open share last, is read into one
    block first, a run of probes a task, so that each tap reads one row of it; each tap's weights are laid
    out the same way, so that a tap is one loop along the row that vectorizes. val-00001's 1,690 walled
    probes: 0.95 -> 0.63 ms for the two products on two cores, where a task read one channel of every
    probe and each tap's sums were taken a part and a channel at a time (float32 sums, as `_depthwise`'s).
    (Adding to the plain sums only the taps that differ, 8.5 of the 27 on the Cornell box, was not faster
    and left the dark side of a wall a rounding error above zero.)"""
    parts, passes, count = out.shape[0], out.shape[1], out.shape[2]
    width = parts * count
    flat = inputs.reshape(passes, inputs.shape[1], inputs.shape[2] * inputs.shape[3] * inputs.shape[4])
    channel = np.empty(width + 1, np.int64)   # the input channel of each place in a row
    for k in range(width):
        channel[k] = firsts[k // count] + k % count
    channel[width] = opened
    light = np.empty((passes, cells.shape[0], width + 1), np.float32)
    runs = (cells.shape[0] + WALLED_CELLS - 1) // WALLED_CELLS
    for job in numba.prange(passes * runs):
        b, run = job // runs, job % runs
        for i in range(run * WALLED_CELLS, min(cells.shape[0], (run + 1) * WALLED_CELLS)):
            q, row = cells[i], light[b, i]
            for k in range(width + 1):
                row[k] = flat[b, channel[k], q]
    wide = np.empty((27, width), np.float32)   # each tap's weight of each place in a row
    for t in range(27):
        for k in range(width):
            wide[t, k] = weights[k % count, t]
    target = out.reshape(parts, passes, count, flat.shape[2])
    blocks = (rows.shape[0] + WALLED_ROWS - 1) // WALLED_ROWS
    for job in numba.prange(passes * blocks):
        b, block = job // blocks, job % blocks
        totals = np.empty(width, np.float32)
        for s in range(block * WALLED_ROWS, min(rows.shape[0], (block + 1) * WALLED_ROWS)):
            totals[:] = 0.0
            for t in range(27):
                values, weight = light[b, local[s, t]], wide[t]
                taken = values[width]
                for k in range(width):
                    totals[k] += weight[k] * values[k] * taken
            for k in range(width):
                target[k // count, b, k % count, rows[s]] = totals[k] * scale[s]

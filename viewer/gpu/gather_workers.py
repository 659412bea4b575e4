"""The final gather's rays cast in worker processes, on machines of 4 cores and more.

In-process, a gather's rays are made, traced and landed in one compiled loop on every core, Embree
called without Python's lock (viewer/rays/embree.py). The workers date from when Embree was reached
through embreex's binding, which holds the lock, so that rays cast on a thread took turns with every
other thread of the process: a new scene's gather rays and the GI source's own probe rays shared one
core. On a 16-core machine they settled a new Cornell box 1.3-1.9x sooner then (docs/PERFORMANCE.md);
each worker's loops run on one thread.

A gather hands its arrays (the scene's triangles, the samples' ray frames, the lightmap's layout) to the
workers once, in one block of shared memory; each task names a run of samples and which of their rays
to cast, and returns the lightmap pixel each ray lands on, the same numbers the in-process cast gives
(the same rays, the same Embree; tests/gpu/test_final_gather.py). The pool starts on first use (or
`warm`, which the viewer calls when it opens: a worker takes a second or two to import numba and
Embree) and lives as long as the process.
"""

from __future__ import annotations

import atexit
import multiprocessing
import os
import threading
from concurrent.futures import ProcessPoolExecutor
from multiprocessing import shared_memory

import numpy as np

from viewer.gpu.gather_cast import cast_rays

MAX_WORKERS = 4
"""Worker processes at most (each holds numpy, numba and Embree: about 150 MB)."""
ENV = "GI_VIEWER_RAY_WORKERS"
"""An environment variable that sets the number of worker processes (0: cast in-process)."""

_lock = threading.Lock()
_pool: ProcessPoolExecutor | None = None
_broken = False
_warmed = False


MIN_CORES = 4
"""Cores a machine needs for the workers: on 2 the GI source's rays and the compiled loops of the
viewer's own threads already keep both busy, and a new Cornell box settled 10% later with a worker
(3.35 s against 3.05 s, docs/PERFORMANCE.md)."""


def worker_count() -> int:
    """Worker processes to use: none below MIN_CORES cores, else one fewer than the cores (the viewer's
    own threads keep one), at most MAX_WORKERS; the environment's GI_VIEWER_RAY_WORKERS where it is set."""
    if ENV in os.environ:
        try:
            return max(0, int(os.environ[ENV]))
        except ValueError:
            return 0
    cores = os.cpu_count() or 1
    return 0 if cores < MIN_CORES else min(MAX_WORKERS, cores - 1)


def pool() -> ProcessPoolExecutor | None:
    """The worker pool, started on first use; None where there are none to use (or they failed)."""
    global _pool
    with _lock:
        if _pool is None and not _broken and worker_count() > 0:
            _pool = ProcessPoolExecutor(worker_count(), mp_context=multiprocessing.get_context("spawn"),
                                        initializer=_one_thread)
            atexit.register(_pool.shutdown, wait=False, cancel_futures=True)
        return _pool


def warm() -> None:
    """Start the workers and have each import what a task needs (numba's compiled functions, Embree), so
    that the first gather does not wait for them (once; later calls do nothing)."""
    global _warmed
    executor = pool()
    if executor is not None and not _warmed:
        _warmed = True
        for _ in range(worker_count()):
            executor.submit(_warm)


def shutdown() -> None:
    """Stop the workers (a later gather starts them again if it has any to use)."""
    global _pool, _warmed
    with _lock:
        if _pool is not None:
            _pool.shutdown(wait=True, cancel_futures=True)
        _pool, _warmed = None, False


def broke() -> None:
    """A task failed for a reason of the pool's (a worker killed): cast in-process from now on."""
    global _broken, _pool
    with _lock:
        _broken = True
        if _pool is not None:
            _pool.shutdown(wait=False, cancel_futures=True)
            _pool = None


class SharedArrays:
    """Named arrays in one block of shared memory: made by the caster's process, read by the workers
    (`attach`) without a copy."""

    def __init__(self, arrays: dict[str, np.ndarray]):
        arrays = {name: np.ascontiguousarray(a) for name, a in arrays.items()}
        self.spec, offset = {}, 0
        for name, a in arrays.items():
            self.spec[name] = (offset, a.shape, a.dtype.str)
            offset += (a.nbytes + 63) // 64 * 64
        self.block = shared_memory.SharedMemory(create=True, size=max(offset, 1))
        for name, view in views(self.block, self.spec).items():
            view[...] = arrays[name]

    @property
    def handle(self) -> tuple[str, dict]:
        return self.block.name, self.spec

    def release(self) -> None:
        self.block.close()
        self.block.unlink()


def views(block: shared_memory.SharedMemory, spec: dict) -> dict[str, np.ndarray]:
    """The arrays a block holds, by name (`SharedArrays.spec`), without a copy."""
    return {name: np.ndarray(shape, np.dtype(dtype), buffer=block.buf, offset=offset)
            for name, (offset, shape, dtype) in spec.items()}


def pooled_cast(frame, lift: float, layout: tuple):
    """A function (samples, rays, hits) that casts those rays of those samples in the worker processes,
    with what they need shared once (None where the rays are cast here: no workers, or the DDA's cells),
    and the shared block to release after."""
    caster, face_tile, tile_origin, tile_n, width = layout
    executor = pool() if caster.backend == "embree" else None
    if executor is None:
        return None, None
    shared = SharedArrays(dict(
        triangles=caster.mesh, faces=caster.faces, v0=caster.v0, e1=caster.e1, e2=caster.e2, points=frame.points,
        normals=frame.normals, tangents=frame.tangents, bitangents=frame.bitangents, shift=frame.shift,
        face_tile=np.asarray(face_tile, np.int64), tile_origin=np.asarray(tile_origin, np.int64),
        tile_n=np.asarray(tile_n, np.int64)))
    scalars = (frame.rows, 2 * frame.rows, float(lift), int(width))

    def cast(samples: np.ndarray, rays: np.ndarray, hits: np.ndarray) -> None:
        per = max(TASK_RAYS // max(len(rays), 1), 1)
        runs = [samples[first:first + per] for first in range(0, len(samples), per)]
        tasks = [executor.submit(cast_task, shared.handle, scalars, run, rays) for run in runs]
        for run, task in zip(runs, tasks):
            hits[run[:, None], rays] = task.result()

    return cast, shared


TASK_RAYS = 1 << 18
"""Rays a worker casts in one task (about 60 ms of Embree): enough tasks to keep the workers even."""


# ---- in the workers ---------------------------------------------------------------------------------
_attached: dict[str, tuple] = {}
"""The gather a worker last attached to: {block name: (block, arrays, caster)}."""


def _one_thread() -> None:
    """A worker's compiled loops (Embree's rays among them) run on one thread: the pool has a worker a core."""
    import numba

    numba.set_num_threads(1)


def _warm() -> None:
    """Load the compiled ray functions (from numba's cache, a second or so) and Embree in a new worker."""
    from viewer.gpu.gather_cast import pixels_of, rays_of
    from viewer.rays import cast  # noqa: F401 (Embree)

    one = np.zeros((1, 3))
    rays_of(one, one, one, one, 1, 2, np.zeros((1, 2)), 0.0, np.zeros((1, 2), np.int64))
    empty = np.zeros(0, np.int64)
    pixels_of(empty, np.zeros(0), np.zeros(0), np.zeros(0, bool), empty, np.zeros((0, 2), np.int64), empty, 1)


def _attach(name: str, spec: dict) -> tuple[dict, object]:
    """The arrays of a gather's block and the Embree caster of its triangles, made once per gather."""
    if name not in _attached:
        from viewer.rays.cast import TriangleCaster

        for old, _ in list(_attached.items()):
            _attached.pop(old)[0].close()
        block = shared_memory.SharedMemory(name=name)
        arrays = views(block, spec)
        caster = TriangleCaster.of_triangles(*(arrays[key] for key in ("triangles", "faces", "v0", "e1", "e2")))
        _attached[name] = (block, arrays, caster)
    return _attached[name][1], _attached[name][2]


def cast_task(handle: tuple[str, dict], scalars: tuple, samples: np.ndarray, rays: np.ndarray) -> np.ndarray:
    """(len(samples), len(rays)) int32: the lightmap pixel that each of `rays` of each of `samples` lands
    on (viewer.gpu.final_gather's `_cast`, in a worker)."""
    arrays, caster = _attach(*handle)
    rows, columns, lift, width = scalars
    frame = (arrays["points"], arrays["normals"], arrays["tangents"], arrays["bitangents"], rows, columns,
             arrays["shift"], lift)
    todo = np.column_stack([np.repeat(samples, len(rays)), np.tile(rays, len(samples))]).astype(np.int64)
    out = np.empty(len(todo), np.int32)
    cast_rays(frame, todo, caster, arrays["face_tile"], arrays["tile_origin"], arrays["tile_n"], width, out)
    return out.reshape(len(samples), len(rays))

"""gi-viewer: real-time diffuse global illumination from voxels and SH light probes."""

import os
import sys

# numba's parallel loops (viewer.rays.dda, viewer.physical.relight) run on OpenMP threads, which by default spin while
# they wait for work. When the render loop or llvmpipe keeps the other core busy, the spinning threads
# take its time: a relight measured 190 ms instead of 57 ms under load (docs/PERFORMANCE.md). Waiting
# passively costs nothing on an idle machine. Set before any import loads the OpenMP runtime.
os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")


def _one_blas_thread() -> None:
    """numpy's matrix products on one thread, in every part of the viewer. OpenBLAS's threads spin for
    about a tenth of a second after each product they share, and the products here are small: the spinning
    thread only takes the other core from the compiled passes, onnxruntime and Embree that follow. Measured
    on 2 cores: the physical solver's new scene in a generator room 360 -> 317 ms and its moved box 224 ->
    193 ms on one BLAS thread (the Cornell box alike within a few ms), and the network's new scene right
    after a solver's 145 ms instead of 105. The variable is read when numpy loads OpenBLAS; where numpy
    was imported before the viewer, its threads are limited where they are. A user's own
    OPENBLAS_NUM_THREADS is kept."""
    if "OPENBLAS_NUM_THREADS" in os.environ:
        return
    os.environ["OPENBLAS_NUM_THREADS"] = "1"
    if "numpy" in sys.modules:
        from threadpoolctl import threadpool_limits

        threadpool_limits(limits=1, user_api="blas")


_one_blas_thread()


def _keep_freed_blocks() -> bool:
    """Have glibc's malloc serve blocks up to 32 MB (its largest mmap threshold on 64 bits) from its heap
    and keep what is freed there (up to 256 MB at its top) for the next ones, instead of mapping each
    block afresh and handing it back when freed: every colour edit makes a dozen arrays of megabytes (the
    network's inputs, their asinh, the filtered light), and the system zeroes each new mapping a page at
    a time as it is first written (840 page faults an albedo edit of a 68k-triangle scan, 2-3 ms of its
    32). viewer.memory.trim_free_memory still hands the free heap back. False where malloc is not glibc's."""
    import ctypes
    import ctypes.util

    mmap_threshold, trim_threshold = -3, -1   # malloc.h's M_MMAP_THRESHOLD, M_TRIM_THRESHOLD
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")
        return bool(libc.mallopt(mmap_threshold, 32 << 20)) and bool(libc.mallopt(trim_threshold, 256 << 20))
    except (OSError, AttributeError):   # not glibc
        return False


_keep_freed_blocks()

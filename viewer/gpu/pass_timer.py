"""Milliseconds per render pass: a GL_TIME_ELAPSED query (GPU) and the wall clock (CPU) around each pass.

    timer = PassTimer(ctx)
    renderer.timer = timer            # the renderer wraps each of its passes in timer("name")
    renderer.draw(...); renderer.present(...)
    timer.frame()                     # {"indirect": (gpu_ms, cpu_ms), "surface": ..., "present": ...}

With `finish` (the default) every pass ends with glFinish, so its CPU time is the time until its
pixels exist. On a software rasterizer (llvmpipe) that is the cost of the pass, and the GPU figure is
that same wall clock: its timer queries do not measure the work (viewer.gpu.context.is_software). The
glFinish serializes the frame, so benchmarks time whole frames separately (without a timer) and use the
per-pass numbers for where the time goes.
"""

from __future__ import annotations

import time
from contextlib import contextmanager

import moderngl

from viewer.gpu.context import is_software


class PassTimer:
    def __init__(self, ctx: moderngl.Context, finish: bool = True):
        self.ctx = ctx
        self.finish = finish
        self.software = is_software(ctx)
        self._queries: dict[str, moderngl.Query] = {}
        self._cpu: dict[str, float] = {}
        self._order: list[str] = []

    @contextmanager
    def __call__(self, name: str):
        query = self._queries.get(name)
        if query is None:
            query = self._queries[name] = self.ctx.query(time=True)
        if name not in self._order:
            self._order.append(name)
        start = time.perf_counter()
        with query:
            yield
        if self.finish:
            self.ctx.finish()
        self._cpu[name] = 1e3 * (time.perf_counter() - start)

    def frame(self) -> dict[str, tuple[float, float]]:
        """(GPU ms, CPU ms) of each pass timed since the last call, in the order they first ran."""
        out = {name: (self._cpu[name] if self.software and self.finish else self._queries[name].elapsed / 1e6,
                      self._cpu[name]) for name in self._order if name in self._cpu}
        self._cpu.clear()
        return out

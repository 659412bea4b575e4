"""Frame times: CPU milliseconds per frame (wall clock of the frame's work on the render thread) and
GPU milliseconds (a GL_TIME_ELAPSED query around the frame's GL commands), kept for a few seconds and
drawn as a two-line graph.

A timer query's result is read a few frames after it was issued, when the GPU has long finished it,
so reading it never stalls the frame (a ring of queries, one per frame in flight).

On a software rasterizer (Mesa llvmpipe) the "GPU" is the CPU's cores, and its timer queries do not
measure the frame's work: a query can come back as -1 (read as 4295 ms), and a query around a
frame's blit reads 1 ns while the copy runs later, when the next command waits for it. There the
frame's GL work is timed on the wall clock up to a glFinish at the end of the frame's GL commands
(which llvmpipe would wait for at the buffer swap anyway), and a result that cannot be a duration
(-1, or over a minute) is never recorded on either path.
"""

from __future__ import annotations

import math
import time
from collections import deque
from contextlib import contextmanager

import moderngl
import numpy as np
from imgui_bundle import imgui

from viewer.gpu.context import is_software

QUERIES_IN_FLIGHT = 3
FAILED_QUERY_NS = (1 << 32) - 1
"""What a failed timer query reads (-1 as a 32-bit unsigned number: 4295 ms)."""
IMPLAUSIBLE_MS = 60_000.0
"""No frame takes a minute: a longer result is not a duration either."""
CPU_COLOUR = (1.0, 0.62, 0.2, 1.0)
GPU_COLOUR = (0.35, 0.8, 1.0, 1.0)


class FrameTimes:
    def __init__(self, ctx: moderngl.Context, history: int = 240, software: bool | None = None):
        self.ctx = ctx
        self.software = is_software(ctx) if software is None else software
        """Time the GL work on the wall clock to a glFinish instead of with timer queries."""
        self.cpu_ms: deque[float] = deque(maxlen=history)
        self.gpu_ms: deque[float] = deque(maxlen=history)
        self.redrawn: deque[bool] = deque(maxlen=history)
        self.all_cpu_ms: list[float] = []   # every frame (for the summary printed at exit)
        self.all_gpu_ms: list[float] = []
        self.all_redrawn: list[bool] = []
        self._queries = [ctx.query(time=True) for _ in range(QUERIES_IN_FLIGHT)]
        self._issued = [False] * QUERIES_IN_FLIGHT
        self._frame = 0
        self._started = 0.0
        self._skip_gpu = 0

    def begin(self) -> None:
        self._started = time.perf_counter()

    def end(self, redrawn: bool) -> None:
        """Close the frame's CPU time, and collect the oldest GPU time that is due."""
        cpu = 1e3 * (time.perf_counter() - self._started)
        self.cpu_ms.append(cpu)
        self.redrawn.append(redrawn)
        self.all_cpu_ms.append(cpu)
        self.all_redrawn.append(redrawn)
        self._frame += 1

    @contextmanager
    def gpu(self):
        """Time the GL commands issued inside the block (one block per frame)."""
        if self.software:
            started = time.perf_counter()
            yield
            self.ctx.finish()
            self._record(1e9 * (time.perf_counter() - started))   # seconds to nanoseconds
            return
        slot = self._frame % QUERIES_IN_FLIGHT
        query = self._queries[slot]
        if self._issued[slot]:  # issued QUERIES_IN_FLIGHT frames ago: finished by now
            self._record(query.elapsed)
        with query:
            yield
        self._issued[slot] = True

    def _record(self, nanoseconds: float) -> None:
        gpu = nanoseconds / 1e6
        if nanoseconds == FAILED_QUERY_NS or not 0.0 <= gpu < IMPLAUSIBLE_MS:
            gpu = math.nan   # a failed query: shown as a gap, left out of the summary
        self.gpu_ms.append(gpu)
        if self._skip_gpu > 0:
            self._skip_gpu -= 1
        else:
            self.all_gpu_ms.append(gpu)

    def restart_summary(self) -> None:
        """Forget the frames so far for `summary` (e.g. once the indirect light has settled)."""
        self.all_cpu_ms, self.all_gpu_ms, self.all_redrawn = [], [], []
        self._skip_gpu = 0 if self.software else sum(self._issued)   # results in flight: forgotten frames

    def summary(self, redrawn_only: bool = False) -> dict[str, float]:
        """Medians and 90th percentiles of CPU and GPU ms (of frames that redrew the scene, if asked)."""
        cpu = np.asarray(self.all_cpu_ms)
        gpu = np.asarray(self.all_gpu_ms)
        if redrawn_only:
            mask = np.asarray(self.all_redrawn, bool)
            cpu = cpu[mask]
            gpu = gpu[mask[:len(gpu)]]
        out = {"frames": float(len(cpu))}
        for name, values in (("cpu", cpu), ("gpu", gpu[np.isfinite(gpu)])):
            if len(values):
                out[f"{name}_median_ms"] = float(np.median(values))
                out[f"{name}_p90_ms"] = float(np.percentile(values, 90))
        return out

    def release(self) -> None:
        for query in self._queries:
            release = getattr(query, "release", None)   # moderngl 5 queries have none: the context owns them
            if release is not None:
                release()


def _u32(rgba) -> int:
    return imgui.get_color_u32(imgui.ImVec4(*rgba))


def draw_frame_graph(times: FrameTimes, height: float = 80.0) -> None:
    """CPU (orange) and GPU (blue) ms of recent frames on a log scale (idle frames take a few ms, scene
    redraws on a software GL hundreds), with guides at powers of ten, in the current window."""
    cpu, gpu = list(times.cpu_ms), list(times.gpu_ms)
    last_cpu = cpu[-1] if cpu else math.nan
    last_gpu = gpu[-1] if gpu else math.nan
    imgui.text_colored(imgui.ImVec4(*CPU_COLOUR), f"CPU {last_cpu:6.1f} ms")
    imgui.same_line()
    imgui.text_colored(imgui.ImVec4(*GPU_COLOUR), f"GPU {last_gpu:6.1f} ms")
    redraws = [c for c, r in zip(cpu, times.redrawn) if r]
    if redraws:
        imgui.same_line()
        imgui.text_disabled(f"redraw {np.median(redraws):.0f} ms")
        imgui.set_item_tooltip("Median CPU ms of the recent frames that drew the scene (the others only "
                               "present the last image and draw the panels)")
    width = imgui.get_content_region_avail().x
    origin = imgui.get_cursor_screen_pos()
    draw = imgui.get_window_draw_list()
    low = 1.0
    top = 10.0 ** max(2, math.ceil(math.log10(max([1.0, *cpu, *(g for g in gpu if math.isfinite(g))]))))
    x0, y0, y1 = origin.x, origin.y, origin.y + height

    def y_of(ms: float) -> float:
        return y1 - height * math.log(min(max(ms, low), top) / low) / math.log(top / low)

    draw.add_rect_filled(imgui.ImVec2(x0, y0), imgui.ImVec2(x0 + width, y1), _u32((0.05, 0.05, 0.07, 0.9)))
    guide = 10.0
    while guide < top:
        y = y_of(guide)
        draw.add_line(imgui.ImVec2(x0, y), imgui.ImVec2(x0 + width, y), _u32((0.4, 0.4, 0.4, 0.6)))
        draw.add_text(imgui.ImVec2(x0 + 2, y - 14), _u32((0.6, 0.6, 0.6, 1.0)), f"{guide:g} ms")
        guide *= 10.0
    capacity = times.cpu_ms.maxlen or 1
    step = width / (capacity - 1)
    for values, colour in ((cpu, CPU_COLOUR), (gpu, GPU_COLOUR)):
        if len(values) < 2:
            continue
        start = x0 + width - step * (len(values) - 1)
        points = [imgui.ImVec2(start + i * step, y_of(v)) for i, v in enumerate(values) if math.isfinite(v)]
        if len(points) >= 2:
            draw.add_polyline(points, col=_u32(colour), thickness=1.5, flags=0)
    imgui.dummy(imgui.ImVec2(width, height))

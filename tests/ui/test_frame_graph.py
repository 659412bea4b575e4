"""The frame graph's GPU figure (viewer/ui/frame_graph.py): the frame's GL work, never idle time or a
failed query."""

from __future__ import annotations

import math

import numpy as np

from viewer.gpu.context import is_software
from viewer.ui.frame_graph import FrameTimes


def test_on_a_software_gl_the_gpu_time_is_the_frames_work_not_the_time_between_frames(gl_context, monkeypatch):
    """llvmpipe here: each frame clears a 512x512 target inside the timed block, and the GL work is timed
    to the glFinish that closes the block. On a simulated clock the work takes 3 ms (it ends at the
    finish) and the test idles 80 ms between frames: the GPU figure is the 3 ms, never the idle time, on
    any machine and under any load."""
    from viewer.ui import frame_graph

    assert is_software(gl_context)
    clock = [100.0]
    monkeypatch.setattr(frame_graph.time, "perf_counter", lambda: clock[0])
    times = FrameTimes(gl_context)
    target = gl_context.simple_framebuffer((512, 512))
    finish = gl_context.finish

    def finishing():
        finish()
        clock[0] += 0.003                     # the frame's GL work, as the clock sees it

    monkeypatch.setattr(times, "ctx", _Finishing(gl_context, finishing))
    try:
        for _ in range(6):
            times.begin()
            with times.gpu():
                target.use()
                for _ in range(4):
                    target.clear(0.2, 0.3, 0.4, 1.0)
            times.end(redrawn=True)
            clock[0] += 0.080                 # idle until the next frame
        np.testing.assert_allclose(np.asarray(times.gpu_ms), 3.0, rtol=1e-9)
        np.testing.assert_allclose(np.asarray(times.cpu_ms), 3.0, rtol=1e-9)
    finally:
        target.release()
        times.release()


class _Finishing:
    """The GL context with its glFinish replaced (moderngl's Context takes no new attributes)."""

    def __init__(self, ctx, finish):
        self._ctx, self.finish = ctx, finish

    def __getattr__(self, name):
        return getattr(self._ctx, name)


def test_a_failed_timer_query_is_left_out(gl_context):
    """A timer query that comes back as -1 reads 4294967295 ns (4295 ms): it is shown as a gap and left
    out of the summary, instead of being the frame's GPU time."""
    times = FrameTimes(gl_context, software=False)
    try:
        for nanoseconds in (2e6, 4294967295, 3e6, 7e13):
            times._record(nanoseconds)
        assert math.isnan(times.gpu_ms[1]) and math.isnan(times.gpu_ms[3])
        times.all_cpu_ms = [1.0] * 4
        times.all_redrawn = [True] * 4
        assert times.summary()["gpu_median_ms"] == 2.5
    finally:
        times.release()

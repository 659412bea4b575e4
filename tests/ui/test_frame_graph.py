"""The frame graph's GPU figure (viewer/ui/frame_graph.py): the frame's GL work, never idle time or a
failed query."""

from __future__ import annotations

import math
import time

import numpy as np

from viewer.gpu.context import is_software
from viewer.ui.frame_graph import FrameTimes


def test_on_a_software_gl_the_gpu_time_is_the_frames_work_not_the_time_between_frames(gl_context):
    """llvmpipe here: each frame clears and fills a 512x512 target inside the timed block, then the
    test idles 80 ms before the next frame. The GPU figure is the block's work (a few ms), positive,
    and never includes the idle time."""
    assert is_software(gl_context)
    times = FrameTimes(gl_context)
    target = gl_context.simple_framebuffer((512, 512))
    try:
        for _ in range(6):
            times.begin()
            with times.gpu():
                target.use()
                for _ in range(4):
                    target.clear(0.2, 0.3, 0.4, 1.0)
            times.end(redrawn=True)
            time.sleep(0.08)
        gpu = np.asarray(times.gpu_ms)
        assert len(gpu) == 6 and np.all(gpu > 0.0) and np.all(gpu < 40.0), gpu
    finally:
        target.release()
        times.release()


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

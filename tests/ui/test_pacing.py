"""The window's frame pacing (viewer/ui/pacing.py): full rate while the user interacts, frames that leave
the cores to the work while it runs unattended, and an idle loop that input wakes."""

import threading
import time

import pytest

from viewer import wake
from viewer.ui.pacing import Pacing, Rests


def test_while_the_user_interacts_frames_come_at_the_active_rate_whatever_runs():
    pacing = Pacing(active_fps=60.0)
    for busy in (False, True):
        rest, idle = pacing.rest(0.004, busy=busy, user_active=True, since_input=0.0)
        assert rest == pytest.approx(1 / 60 - 0.004) and not idle


def test_unattended_work_gets_four_fifths_of_the_time_and_frames_come_ten_times_a_second_at_least():
    pacing = Pacing(active_fps=60.0, busy_share=0.2, busy_fps=10.0)
    frame = 0.015                                      # a llvmpipe frame of the panel and the still image
    rest, idle = pacing.rest(frame, busy=True, user_active=False, since_input=5.0)
    assert not idle and frame / (frame + rest) == pytest.approx(0.2)
    for frame in (0.03, 0.15):                         # a preview drawn, a frame that compiled shaders
        rest, _ = pacing.rest(frame, busy=True, user_active=False, since_input=5.0)
        assert frame + max(rest, 0.0) == pytest.approx(max(frame, 0.1))   # the result shows within 0.1 s
    fast = 0.002                                       # a GPU's frame: the active rate is the cap
    rest, _ = pacing.rest(fast, busy=True, user_active=False, since_input=5.0)
    assert rest == pytest.approx(1 / 60 - fast)


def test_right_after_an_edit_the_loop_keeps_the_active_rate():
    """A colour edit's relight takes tens of milliseconds: its picture must not wait for a long rest."""
    pacing = Pacing(active_fps=60.0, linger=0.25)
    rest, _ = pacing.rest(0.030, busy=True, user_active=False, since_input=0.1)
    assert rest < 0


def test_when_nothing_runs_the_loop_goes_idle_after_a_while():
    pacing = Pacing(idle_fps=4.0, idle_after=1.0)
    rest, idle = pacing.rest(0.01, busy=False, user_active=False, since_input=0.5)
    assert not idle and rest == pytest.approx(1 / 60 - 0.01)
    rest, idle = pacing.rest(0.01, busy=False, user_active=False, since_input=2.0)
    assert idle and rest == pytest.approx(0.25 - 0.01)


def test_a_result_handed_over_ends_the_rest_and_an_idle_rest_waits_on_the_windows_events():
    """A rest is taken before the next frame and ends when a worker hands a result over (viewer.wake):
    new probes are drawn at once, not a quarter of a second later. An idle rest waits on the window's
    events (input ends it), and a result posts one."""
    waits, posted = [], []
    rests = Rests(Pacing(active_fps=0.1, idle_fps=0.1), waits.append, lambda: posted.append(True))   # 10 s rests
    try:
        rests.plan(0.0, busy=False, user_active=False, since_input=60.0)    # idle: a 10 s rest
        rests.take()
        assert len(waits) == 1 and 9.0 < waits[0] <= 10.0
        rests.plan(0.0, busy=True, user_active=False, since_input=60.0)     # work runs: not idle, 10 s
        threading.Timer(0.05, wake.notify).start()
        started = time.perf_counter()
        rests.take()
        assert time.perf_counter() - started < 5.0 and posted     # ended by the result, not the clock
        rests.plan(0.0, busy=True, user_active=False, since_input=60.0)
        wake.notify()                                             # a result during the frame ...
        started = time.perf_counter()
        rests.take()                                              # ... and the next one starts at once
        assert time.perf_counter() - started < 5.0
    finally:
        rests.close()
    posted.clear()
    wake.notify()
    assert not posted                                             # closed: no longer listening

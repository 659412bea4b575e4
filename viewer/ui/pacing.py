"""How long the window's loop rests after each frame: llvmpipe and the solvers share the same few cores.

- While the user moves the camera or a slider: up to `active_fps` frames a second.
- While work runs that the picture waits for (a new scene's solve, a load) and the user does nothing:
  the frames only show progress, so they take at most `busy_share` of the time and leave the rest of
  the cores to the work, yet come at least `busy_fps` times a second, so that the result shows soon
  after it lands. A new Cornell box's GI was ready 3.2-3.9 s after the window opened at 60 frames a
  second (its geometry traced in 2.3-2.8 s of it); 2.5-2.6 s with this pacing (1.5-1.7 s), and 2.2-2.4 s
  at a fixed 10 frames a second (llvmpipe, 1280x720, three runs each: `python -m viewer view cornell
  --bench 5` under Xvfb).
- When nothing moves and nothing is computed: `idle_fps`, and input wakes the loop at once.

A rest ends early when work on another thread hands a result over (viewer.wake: new probes, a loaded
scene, the lightmap's weights): the frame that shows it starts at once (`Rests`).
"""

from __future__ import annotations

import threading
import time
from dataclasses import dataclass
from typing import Callable

from viewer import wake


@dataclass(frozen=True)
class Pacing:
    active_fps: float = 60.0
    """Frame rate while the user interacts or right after."""
    idle_fps: float = 4.0
    """Frame rate when nothing moves and nothing is computed."""
    idle_after: float = 1.0
    """Seconds after the last input before the loop goes idle."""
    linger: float = 0.25
    """Seconds after the last input during which the loop keeps `active_fps` whatever is computed: a
    colour edit's relight (tens of milliseconds) shows at once."""
    busy_share: float = 0.2
    """While work runs and the user does nothing, the share of the time frames may take..."""
    busy_fps: float = 10.0
    """... but at least this many frames a second, so that the work's result (the GI, a loaded scene)
    shows within a tenth of a second of its end, however long a frame took (a first frame that
    compiles shaders)."""

    def rest(self, frame: float, busy: bool, user_active: bool, since_input: float) -> tuple[float, bool]:
        """(seconds to rest after a frame that took `frame` seconds, whether the loop is idle: input may
        end the rest early). `busy`: work runs that the picture waits for, or the frame drew the scene;
        `user_active`: the camera or a slider moves; `since_input`: seconds since the last input."""
        idle = not busy and since_input >= self.idle_after
        rest = 1.0 / (self.idle_fps if idle else self.active_fps) - frame
        if busy and not user_active and since_input >= self.linger:
            rest = max(rest, min(frame * (1.0 - self.busy_share) / self.busy_share, 1.0 / self.busy_fps - frame))
        return rest, idle


class Rests:
    """The rest between the loop's frames: planned at the end of a frame (`plan`), taken at the start of the
    next one (`take`), once the picture was swapped in: taken at the end of the frame, it held back every
    picture by its length (up to 1/60 s while the user edits, a quarter of a second when idle). It ends
    early when a result lands (viewer.wake), and an idle one also on input where `wait_events` is given
    (glfw's wait_events_timeout; `post_empty_event` then ends it on a result)."""

    def __init__(self, pacing: Pacing, wait_events: Callable[[float], None] | None = None,
                 post_empty_event: Callable[[], None] | None = None):
        self.pacing = pacing
        self._wait_events, self._post_empty_event = wait_events, post_empty_event
        self._until: tuple[float, bool] | None = None    # (when the rest ends, idle)
        self._woken = threading.Event()
        self._stop = wake.listen(self._wake)

    def plan(self, frame: float, busy: bool, user_active: bool, since_input: float) -> None:
        """After a frame: `Pacing.rest`'s arguments."""
        rest, idle = self.pacing.rest(frame, busy, user_active, since_input)
        self._until = (time.perf_counter() + rest, idle) if rest > 0 else None

    def skip(self) -> None:
        """No rest before the next frame."""
        self._until = None

    def take(self) -> float:
        """Before a frame: the rest planned, or less. Returns the seconds it rested."""
        started = time.perf_counter()
        if self._until is not None:
            until, idle = self._until
            left = until - time.perf_counter()
            if left > 0 and idle and self._wait_events is not None:
                self._wait_events(left)   # returns at once on input, a drop, or a result
            elif left > 0:
                self._woken.wait(left)
        self._until = None
        self._woken.clear()
        return time.perf_counter() - started

    def _wake(self) -> None:   # from a worker thread
        self._woken.set()
        if self._post_empty_event is not None:
            try:
                self._post_empty_event()
            except Exception:  # noqa: BLE001 - the window is gone: nothing to wake
                pass

    def close(self) -> None:
        self._stop()

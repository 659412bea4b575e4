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
"""

from __future__ import annotations

from dataclasses import dataclass


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

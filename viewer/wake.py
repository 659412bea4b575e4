"""Wakes the window's frame loop when work on another thread hands a result over: new probes from the GI
source's worker, a loaded scene, the lightmap's weights and final-gather rays. Between frames the loop
rests (viewer/ui/pacing.py: up to 1/60 s while the user edits, a tenth of a second while work runs, a
quarter when idle); a result that lands during a rest is shown by a frame that starts at once instead of
when the rest ends.

    from viewer import wake
    stop = wake.listen(event.set)   # the loop: called from any thread
    wake.notify()                   # a worker: a result is ready
    stop()

Listeners must be quick and safe to call from any thread (setting a threading.Event, glfw's
post_empty_event).
"""

from __future__ import annotations

import threading
from typing import Callable

_listeners: list[Callable[[], None]] = []
_lock = threading.Lock()


def listen(callback: Callable[[], None]) -> Callable[[], None]:
    """Call `callback` on every `notify` until the function returned is called."""
    with _lock:
        _listeners.append(callback)

    def stop() -> None:
        with _lock:
            if callback in _listeners:
                _listeners.remove(callback)
    return stop


def notify() -> None:
    """A result is ready for the next frame (from any thread)."""
    with _lock:
        listeners = list(_listeners)
    for callback in listeners:
        callback()

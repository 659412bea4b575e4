"""Work that must not stall the window: loading a scene file, and the numpy GI solver.

Everything here runs off the render thread and hands plain data (a Scene, a ProbeGrid) back through
`poll()`, which the render loop calls once a frame; GL objects are only ever made on the render thread.

The CPU solver runs in a separate process rather than a thread: a solve takes seconds to a minute and
holds the GIL in its Python loops, and a stale solve (the user moved the light again) can then be
stopped at once instead of being waited for.
"""

from __future__ import annotations

import multiprocessing
import threading
import time
import traceback
from typing import Any, Callable

from viewer import wake

SOLVER_STAGES = ("voxelize", "geometry", "relight")
"""The stages of the physical kernel's solve (viewer.physical.gi.PhysicalGI), in order (its Timings keys); an edit
that needs no tracing runs only the last."""


class BackgroundTask:
    """A function run once on a daemon thread; `done`, then `result` or `error` (one readable line)."""

    def __init__(self, label: str, function: Callable[..., Any], *args):
        self.label = label
        self.started = time.perf_counter()
        self.finished: float | None = None
        self.result: Any = None
        self.error: str | None = None
        self._thread = threading.Thread(target=self._run, args=(function, args), daemon=True,
                                        name=f"viewer: {label}")
        self._thread.start()

    def _run(self, function, args) -> None:
        try:
            self.result = function(*args)
        except Exception as exc:  # reported in the window; the app keeps running
            self.error = str(exc) if isinstance(exc, ValueError) else f"{type(exc).__name__}: {exc}"
            if not isinstance(exc, ValueError):
                traceback.print_exc()
        finally:
            self.finished = time.perf_counter()
            wake.notify()

    @property
    def done(self) -> bool:
        return self.finished is not None

    def wait(self, seconds: float) -> None:
        """Until the work is done or `seconds` have passed (Python's lock let go meanwhile)."""
        self._thread.join(max(seconds, 0.0))

    @property
    def elapsed(self) -> float:
        return (self.finished or time.perf_counter()) - self.started


# ---- the numpy solver in a process ------------------------------------------------------------------

def _solver_worker(connection) -> None:
    """Child process: import the solver once, then solve each (scene, settings) that arrives, sending
    ("stage", name) as each stage of gi.solve finishes and ("done", grid, seconds) at the end."""
    import signal

    signal.signal(signal.SIGINT, signal.SIG_IGN)   # Ctrl+C is for the viewer, which then stops us
    from viewer.physical import gi

    class ReportingStages(dict):
        def __setitem__(self, name, seconds):
            if name not in self:
                connection.send(("stage", name))
            super().__setitem__(name, seconds)

    solvers: dict = {}   # settings -> gi.PhysicalGI: an edit re-runs only what it changes

    connection.send(("ready",))
    while True:
        job = connection.recv()
        if job is None:
            return
        generation, scene, settings = job
        timings = gi.Timings(ReportingStages())
        try:
            if settings.kernel == "physical":
                solver = solvers.get(settings) or gi.PhysicalGI(settings)
                solvers.clear()
                solvers[settings] = solver
                solver.update(scene, timings)
                grid = solver.probe_grid(include_emitted=False, timings=timings)
            else:
                grid = gi.solve(scene, settings, include_emitted=False, timings=timings)
            connection.send(("done", generation, grid, dict(timings.stages)))
        except Exception as exc:
            connection.send(("error", generation, f"{type(exc).__name__}: {exc}"))


class SolverProcess:
    """The CPU solver with "latest request wins": a new request stops a solve that is under way.

    `request` only records what to solve; the solve starts `debounce` seconds after the last request
    (a slider being dragged asks every frame), on a worker process that was started ahead of time.
    """

    def __init__(self, debounce: float = 0.3):
        self.debounce = debounce
        self._context = multiprocessing.get_context("spawn")  # no fork of a process holding a GL context
        self._process = None
        self._connection = None
        self._ready = False
        self._pending = None            # (scene, settings, requested_at)
        self._generation = 0            # of the latest request: older results are dropped
        self.running_since: float | None = None
        self.stages_done: list[str] = []
        self.last_seconds: dict[str, float] = {}
        self.error: str | None = None
        self._start_worker()

    def _start_worker(self) -> None:
        parent, child = self._context.Pipe()
        self._process = self._context.Process(target=_solver_worker, args=(child,), daemon=True,
                                              name="viewer CPU solver")
        self._process.start()
        child.close()
        self._connection, self._ready, self.running_since = parent, False, None

    def _stop_worker(self) -> None:
        if self._process is not None:
            self._process.terminate()
            self._process.join(timeout=2.0)
            self._connection.close()
        self._process = None

    # ---- requests ---------------------------------------------------------------------------------------
    def request(self, scene, settings) -> None:
        """Solve this scene next; a solve of an older request is stopped."""
        if self.running_since is not None:
            self._stop_worker()
            self._start_worker()
        self._pending = (scene, settings, time.perf_counter())
        self._generation += 1
        self.error = None

    def cancel(self) -> None:
        self._pending = None
        self._generation += 1
        if self.running_since is not None:
            self._stop_worker()
            self._start_worker()

    @property
    def busy(self) -> bool:
        return self._pending is not None or self.running_since is not None

    @property
    def progress(self) -> float:
        return len(self.stages_done) / len(SOLVER_STAGES)

    @property
    def stage(self) -> str:
        """The stage under way (or 'waiting')."""
        if self.running_since is None:
            return "waiting"
        left = [s for s in SOLVER_STAGES if s not in self.stages_done]
        return left[0] if left else "finishing"

    @property
    def elapsed(self) -> float:
        return time.perf_counter() - self.running_since if self.running_since is not None else 0.0

    def poll(self):
        """Called once a frame: starts a due request, and returns a finished ProbeGrid (else None)."""
        grid = None
        try:
            while self._connection.poll():
                message = self._connection.recv()
                if message[0] == "ready":
                    self._ready = True
                elif message[0] == "stage":
                    self.stages_done.append(message[1])
                elif message[0] == "done":
                    self.running_since = None
                    if message[1] == self._generation:
                        grid, self.last_seconds = message[2], message[3]
                elif message[0] == "error":
                    self.running_since = None
                    if message[1] == self._generation:
                        self.error = message[2]
        except (EOFError, OSError):  # the worker died: say so, and start another
            self.error = "the CPU solver process stopped unexpectedly"
            self._stop_worker()
            self._start_worker()
            return None
        if (self._pending is not None and self._ready and self.running_since is None
                and time.perf_counter() - self._pending[2] >= self.debounce):
            scene, settings, _ = self._pending
            self._pending = None
            self._connection.send((self._generation, scene, settings))
            self.running_since, self.stages_done = time.perf_counter(), []
        return grid

    def close(self) -> None:
        try:
            if self._process is not None and self._process.is_alive() and self.running_since is None:
                self._connection.send(None)
                self._process.join(timeout=1.0)
        except OSError:
            pass
        self._stop_worker()

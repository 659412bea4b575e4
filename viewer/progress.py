"""Lines that tell the user what a long step is doing, on stderr: before a step that takes seconds (a GI
solve, the lightmap's final gather, a bake), and once when the compiled ray kernels are being built for
this machine (the first run only: numba caches them, next to the package or in the user's cache folder).

    from viewer.progress import say, step
    say("tracing ...")
    with step("capture: solving the GI (compute)"):
        ...

The lines go to a terminal: where stderr is a file or a pipe (a script, a test) they are left out, so that
what a command prints there stays its result. `GI_VIEWER_PROGRESS=1` prints them anywhere, `=0` nowhere.

Work counted in steps (the dataset's rooms, the benchmark's measurements) shows a bar instead (`bar`, on
tqdm): rate and time left, redrawn in place on a terminal, a plain line now and then in a log.
Cheap to import: numba is imported only by `announce_compiles`, tqdm only by `bar`.
"""

from __future__ import annotations

import os
import sys
import threading
import time
from contextlib import contextmanager

PREFIX = "viewer: "
HEARTBEAT = 8.0
"""While one kernel compiles, a line every this many seconds."""
SLOW_SECONDS = 2.0
"""A step that took longer than this says how long it took when it ends."""
LOG_SECONDS = 60.0
"""Where a bar goes to a file or a pipe (a log of a long run), it writes a line at most this often."""


def enabled() -> bool:
    """Whether progress lines are printed: GI_VIEWER_PROGRESS=1 or 0 when set, else whether stderr is a
    terminal."""
    chosen = os.environ.get("GI_VIEWER_PROGRESS", "").strip()
    if chosen in ("0", "1"):
        return chosen == "1"
    try:
        return sys.stderr.isatty()
    except (AttributeError, ValueError):
        return False


def say(message: str) -> None:
    """One progress line on stderr, flushed at once (the user reads it while the step runs), where
    `enabled`."""
    if not enabled():
        return
    print(f"{PREFIX}{message}", file=sys.stderr, flush=True)


@contextmanager
def step(message: str):
    """Say `message` and " ..." before the work; after it, when it took over SLOW_SECONDS, say how long."""
    say(f"{message} ...")
    start = time.perf_counter()
    yield
    seconds = time.perf_counter() - start
    if seconds > SLOW_SECONDS:
        say(f"{message}: done in {seconds:.1f} s")


_announced: set[str] = set()
_listening = False


def compile_message(module: str, kernel: str = "") -> str | None:
    """The line for the first compilation of a kernel of `module` in this process (None: already said,
    or not one of ours): the first says what is happening, the next ones name their kernel, so that a
    minute of compiling is never a minute of silence."""
    name = f"{module}.{kernel}" if kernel else module
    if not module.startswith("viewer.") or name in _announced:
        return None
    first = not _announced
    _announced.add(name)
    if first:
        return (f"compiling the ray kernels for this machine, the first run only (numba caches them): {name}")
    return f"compiling {name}"


def announce_compiles() -> None:
    """From now on, say a line when numba compiles (rather than loads from its cache) a kernel of a module
    of the viewer for the first time in this process: the first run of a command can otherwise sit silent
    for a minute."""
    global _listening
    if _listening:
        return
    from numba.core import event

    compiling: list[tuple[str, float]] = []   # the kernels being compiled, innermost last, and since when
    said = [time.perf_counter()]

    def heartbeat():   # one kernel can take most of a minute: say it is still going every HEARTBEAT seconds
        while True:
            time.sleep(1.0)
            if compiling and time.perf_counter() - said[0] >= HEARTBEAT:
                name, start = compiling[-1]
                say(f"still compiling {name} ({time.perf_counter() - start:.0f} s)")
                said[0] = time.perf_counter()

    class Announce(event.Listener):
        def on_start(self, ev):
            dispatcher = (ev.data or {}).get("dispatcher")
            function = getattr(dispatcher, "py_func", None)
            module = getattr(function, "__module__", None) or ""
            compiling.append((f"{module}.{getattr(function, '__name__', '')}", time.perf_counter()))
            message = compile_message(module, getattr(function, "__name__", ""))
            if message:
                say(message)
                said[0] = time.perf_counter()

        def on_end(self, ev):
            if compiling:
                compiling.pop()

    event.register("numba:compile", Announce())
    if enabled():
        threading.Thread(target=heartbeat, name="compile-heartbeat", daemon=True).start()
    _listening = True


def bar(total: int, unit: str, description: str = "", done: int = 0, stream=None):
    """A tqdm progress bar over `total` steps of `unit` (`done` of them finished before this run), on
    stderr or `stream`: on a terminal it is redrawn in place; in a file or a pipe it is a line at most
    every LOG_SECONDS (and at the end), each on a line of its own, so a log of an hours-long run stays
    readable. Lines that must stay (a result, a failure) go through the bar's `write`."""
    from tqdm import tqdm

    stream = sys.stderr if stream is None else stream
    try:
        terminal = stream.isatty()
    except (AttributeError, ValueError):
        terminal = False
    target = stream if terminal else _LogLines(stream)

    class Bar(tqdm):
        def write(self, line: str) -> None:
            if terminal:   # above the bar, which tqdm redraws (its own `write` goes to stdout unless told)
                tqdm.write(line, file=target)
            else:
                target.write(line + "\n")

    return Bar(total=total, initial=done, unit=unit, desc=description or None, dynamic_ncols=terminal,
               file=target, mininterval=0.5 if terminal else LOG_SECONDS, ascii=not terminal, smoothing=0.05)


class _LogLines:
    """A stream for a bar that is not on a terminal: tqdm redraws with a carriage return, which a log would
    keep as one ever-growing line; here each redraw is a line of its own, and blank ones are dropped."""

    def __init__(self, stream):
        self.stream = stream

    def write(self, text: str) -> None:
        for line in text.replace("\r", "\n").split("\n"):
            if line.strip():
                self.stream.write(line.rstrip() + "\n")

    def flush(self) -> None:
        self.stream.flush()


def plural(count: int, word: str) -> str:
    """`1 bounce`, `3 bounces`."""
    return f"{count} {word}" + ("" if count == 1 else "s")

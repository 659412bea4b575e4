"""Driving the viewer's real window (for the window tests and the soak, viewer/bench/soak.py): an Xvfb
server, real X11 input through the XTEST extension, a real XDND drag-and-drop source, and the viewer run
as a subprocess whose `viewer: ...` stderr lines can be waited for.

Everything talks to libX11 / libXtst through ctypes (python-xlib is not installed). The XDND source
follows the protocol (https://www.freedesktop.org/wiki/Specifications/XDND/, version 5): it owns the
XdndSelection, sends XdndEnter / XdndPosition to the target window, waits for XdndStatus, sends
XdndDrop, answers the target's SelectionRequest for text/uri-list with the file URIs, and waits for
XdndFinished. That is the same exchange a file manager has with the window, so the viewer's glfw drop
callback is reached the way a user's drop reaches it.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import os
import re
import shutil
import subprocess
import sys
import threading
import time
from pathlib import Path
from urllib.parse import quote

REPO = Path(__file__).resolve().parent.parent.parent

# ---- libX11 through ctypes ------------------------------------------------------------------------

c_ulong, c_long, c_int, c_void_p = ctypes.c_ulong, ctypes.c_long, ctypes.c_int, ctypes.c_void_p
CLIENT_MESSAGE, SELECTION_REQUEST, SELECTION_NOTIFY = 33, 30, 31
PROP_MODE_REPLACE = 0


class XClientMessageEvent(ctypes.Structure):
    _fields_ = [("type", c_int), ("serial", c_ulong), ("send_event", c_int), ("display", c_void_p),
                ("window", c_ulong), ("message_type", c_ulong), ("format", c_int), ("l", c_long * 5)]


class XSelectionRequestEvent(ctypes.Structure):
    _fields_ = [("type", c_int), ("serial", c_ulong), ("send_event", c_int), ("display", c_void_p),
                ("owner", c_ulong), ("requestor", c_ulong), ("selection", c_ulong), ("target", c_ulong),
                ("property", c_ulong), ("time", c_ulong)]


class XSelectionEvent(ctypes.Structure):
    _fields_ = [("type", c_int), ("serial", c_ulong), ("send_event", c_int), ("display", c_void_p),
                ("requestor", c_ulong), ("selection", c_ulong), ("target", c_ulong), ("property", c_ulong),
                ("time", c_ulong)]


class XEvent(ctypes.Union):
    _fields_ = [("type", c_int), ("xclient", XClientMessageEvent), ("xselectionrequest", XSelectionRequestEvent),
                ("xselection", XSelectionEvent), ("pad", c_long * 24)]


def _load_library(name: str, package: str):
    try:
        return ctypes.cdll.LoadLibrary(ctypes.util.find_library(name) or f"lib{name}.so.6")
    except OSError:
        raise RuntimeError(f"lib{name} not found: the window tests drive X11 through it "
                           f"(apt-get install {package})") from None


def _load_x11():
    x11 = _load_library("X11", "libx11-6")
    signatures = {
        "XOpenDisplay": (c_void_p, [ctypes.c_char_p]),
        "XCloseDisplay": (c_int, [c_void_p]),
        "XDefaultRootWindow": (c_ulong, [c_void_p]),
        "XDefaultScreen": (c_int, [c_void_p]),
        "XInternAtom": (c_ulong, [c_void_p, ctypes.c_char_p, c_int]),
        "XCreateSimpleWindow": (c_ulong, [c_void_p, c_ulong, c_int, c_int, ctypes.c_uint, ctypes.c_uint,
                                          ctypes.c_uint, c_ulong, c_ulong]),
        "XDestroyWindow": (c_int, [c_void_p, c_ulong]),
        "XSetSelectionOwner": (c_int, [c_void_p, c_ulong, c_ulong, c_ulong]),
        "XSendEvent": (c_int, [c_void_p, c_ulong, c_int, c_long, ctypes.POINTER(XEvent)]),
        "XChangeProperty": (c_int, [c_void_p, c_ulong, c_ulong, c_ulong, c_int, c_int, ctypes.c_char_p, c_int]),
        "XPending": (c_int, [c_void_p]),
        "XNextEvent": (c_int, [c_void_p, ctypes.POINTER(XEvent)]),
        "XFlush": (c_int, [c_void_p]),
        "XSync": (c_int, [c_void_p, c_int]),
        "XTranslateCoordinates": (c_int, [c_void_p, c_ulong, c_ulong, c_int, c_int, ctypes.POINTER(c_int),
                                          ctypes.POINTER(c_int), ctypes.POINTER(c_ulong)]),
        "XStringToKeysym": (c_ulong, [ctypes.c_char_p]),
        "XKeysymToKeycode": (ctypes.c_ubyte, [c_void_p, c_ulong]),
    }
    for name, (restype, argtypes) in signatures.items():
        function = getattr(x11, name)
        function.restype, function.argtypes = restype, argtypes
    xtst = _load_library("Xtst", "libxtst6")
    for name, argtypes in {"XTestFakeKeyEvent": [c_void_p, ctypes.c_uint, c_int, c_ulong],
                           "XTestFakeButtonEvent": [c_void_p, ctypes.c_uint, c_int, c_ulong],
                           "XTestFakeMotionEvent": [c_void_p, c_int, c_int, c_int, c_ulong]}.items():
        function = getattr(xtst, name)
        function.restype, function.argtypes = c_int, argtypes
    return x11, xtst


class X11:
    """A connection to an X server, for input (XTEST) and drag and drop (XDND) into other clients."""

    def __init__(self, display: str):
        self.x11, self.xtst = _load_x11()
        self.display = self.x11.XOpenDisplay(display.encode())
        if not self.display:
            raise RuntimeError(f"cannot open X display {display}")
        self.root = self.x11.XDefaultRootWindow(self.display)

    def atom(self, name: str) -> int:
        return self.x11.XInternAtom(self.display, name.encode(), 0)

    def close(self) -> None:
        if self.display:
            self.x11.XCloseDisplay(self.display)
            self.display = None

    def origin(self, window: int) -> tuple[int, int]:
        """The window's top-left corner in root (screen) coordinates."""
        x, y, child = c_int(), c_int(), c_ulong()
        self.x11.XTranslateCoordinates(self.display, window, self.root, 0, 0, ctypes.byref(x), ctypes.byref(y),
                                       ctypes.byref(child))
        return x.value, y.value

    # ---- input (XTEST: as if from the keyboard and mouse) ---------------------------------------------
    def move(self, x: int, y: int) -> None:
        self.xtst.XTestFakeMotionEvent(self.display, -1, int(x), int(y), 0)
        self.x11.XFlush(self.display)

    def button(self, button: int, down: bool) -> None:
        self.xtst.XTestFakeButtonEvent(self.display, button, int(down), 0)
        self.x11.XFlush(self.display)

    def key(self, name: str, down: bool | None = None) -> None:
        """Press and release a key by keysym name ('s', 'F1', 'Escape', 'Shift_L'), or only one of them."""
        code = self.x11.XKeysymToKeycode(self.display, self.x11.XStringToKeysym(name.encode()))
        if not code:
            raise ValueError(f"no keycode for keysym {name!r}")
        for state in ((True, False) if down is None else (down,)):
            self.xtst.XTestFakeKeyEvent(self.display, code, int(state), 0)
            self.x11.XFlush(self.display)
            time.sleep(0.05)

    def drag(self, start: tuple[int, int], end: tuple[int, int], button: int = 1, steps: int = 12,
             pause: float = 0.05) -> None:
        self.move(*start)
        time.sleep(pause)
        self.button(button, True)
        for i in range(1, steps + 1):
            time.sleep(pause)
            self.move(start[0] + (end[0] - start[0]) * i // steps, start[1] + (end[1] - start[1]) * i // steps)
        time.sleep(pause)
        self.button(button, False)

    # ---- XDND source ----------------------------------------------------------------------------------
    def _client_message(self, target: int, message_type: str, data: list[int]) -> None:
        event = XEvent()
        event.xclient.type = CLIENT_MESSAGE
        event.xclient.window = target
        event.xclient.message_type = self.atom(message_type)
        event.xclient.format = 32
        for i, value in enumerate(data):
            event.xclient.l[i] = value
        self.x11.XSendEvent(self.display, target, 0, 0, ctypes.byref(event))
        self.x11.XFlush(self.display)

    def _next_event(self, deadline: float) -> XEvent | None:
        event = XEvent()
        while time.monotonic() < deadline:
            if self.x11.XPending(self.display):
                self.x11.XNextEvent(self.display, ctypes.byref(event))
                return event
            time.sleep(0.01)
        return None

    def drop(self, target: int, paths: list[str | Path], at: tuple[int, int] | None = None,
             timeout: float = 300.0) -> dict:
        """Drag `paths` onto window `target` and drop them at root position `at` (default: 100, 100 inside
        the window). Returns what happened: accepted (XdndStatus), requested (the target asked for the
        data), finished (XdndFinished)."""
        uri_list = "".join(f"file://{quote(str(Path(p).resolve()))}\r\n" for p in paths).encode()
        source = self.x11.XCreateSimpleWindow(self.display, self.root, 0, 0, 1, 1, 0, 0, 0)
        uri_type, selection = self.atom("text/uri-list"), self.atom("XdndSelection")
        self.x11.XSetSelectionOwner(self.display, selection, source, 0)
        if at is None:
            x, y = self.origin(target)
            at = (x + 100, y + 100)
        self.move(*at)
        result = {"accepted": False, "requested": False, "finished": False}
        deadline = time.monotonic() + timeout
        try:
            self._client_message(target, "XdndEnter", [source, 5 << 24, uri_type, 0, 0])
            self._client_message(target, "XdndPosition", [source, 0, (at[0] << 16) | at[1], 0,
                                                          self.atom("XdndActionCopy")])
            dropped = False
            while time.monotonic() < deadline and not result["finished"]:
                event = self._next_event(deadline)
                if event is None:
                    break
                if event.type == CLIENT_MESSAGE and event.xclient.message_type == self.atom("XdndStatus"):
                    result["accepted"] = bool(event.xclient.l[1] & 1)
                    if not dropped:
                        if not result["accepted"]:
                            self._client_message(target, "XdndLeave", [source, 0, 0, 0, 0])
                            break
                        self._client_message(target, "XdndDrop", [source, 0, 0, 0, 0])
                        dropped = True
                elif event.type == SELECTION_REQUEST:
                    request = event.xselectionrequest
                    self._answer(request, uri_list if request.target == uri_type else None)
                    result["requested"] = True
                elif event.type == CLIENT_MESSAGE and event.xclient.message_type == self.atom("XdndFinished"):
                    result["finished"] = True
        finally:
            self.x11.XDestroyWindow(self.display, source)
            self.x11.XFlush(self.display)
        return result

    def _answer(self, request: XSelectionRequestEvent, data: bytes | None) -> None:
        """Put the data on the requestor's property and tell it so (property None: refused)."""
        reply = XEvent()
        reply.xselection.type = SELECTION_NOTIFY
        reply.xselection.requestor = request.requestor
        reply.xselection.selection = request.selection
        reply.xselection.target = request.target
        reply.xselection.time = request.time
        reply.xselection.property = request.property if data is not None else 0
        if data is not None:
            self.x11.XChangeProperty(self.display, request.requestor, request.property, request.target, 8,
                                     PROP_MODE_REPLACE, data, len(data))
        self.x11.XSendEvent(self.display, request.requestor, 0, 0, ctypes.byref(reply))
        self.x11.XFlush(self.display)


# ---- Xvfb ------------------------------------------------------------------------------------------

def xvfb_available() -> bool:
    return shutil.which("Xvfb") is not None


def start_xvfb(size: str = "1600x1000x24") -> tuple[subprocess.Popen, str]:
    """An Xvfb server on a free display number; returns (process, ':N')."""
    for number in range(90, 190):
        if Path(f"/tmp/.X{number}-lock").exists() or Path(f"/tmp/.X11-unix/X{number}").exists():
            continue
        process = subprocess.Popen(["Xvfb", f":{number}", "-screen", "0", size, "-nolisten", "tcp"],
                                   stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
        deadline = time.monotonic() + 10.0
        while time.monotonic() < deadline and process.poll() is None:
            if Path(f"/tmp/.X11-unix/X{number}").exists():
                return process, f":{number}"
            time.sleep(0.05)
        process.kill()
        process.wait()
    raise RuntimeError("no free X display number for Xvfb")


# ---- the viewer as a subprocess --------------------------------------------------------------------

class Viewer:
    """`python -m viewer.app ARGS` on a display, with its stderr lines collected as they come."""

    def __init__(self, display: str, args: list[str], cwd: Path, timeout: float = 600.0):
        env = dict(os.environ, DISPLAY=display, PYTHONPATH=str(REPO))
        env.pop("WAYLAND_DISPLAY", None)
        self.process = subprocess.Popen([sys.executable, "-m", "viewer.app", *args], cwd=cwd, env=env,
                                        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        self.lines: list[str] = []
        self._changed = threading.Condition()
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()
        self.timeout = timeout
        self.window = None

    def _read(self) -> None:
        for line in self.process.stderr:
            with self._changed:
                self.lines.append(line.rstrip("\n"))
                self._changed.notify_all()
        with self._changed:
            self._changed.notify_all()

    @property
    def log(self) -> str:
        return "\n".join(self.lines)

    def wait_for(self, pattern: str, timeout: float | None = None, start: int = 0) -> re.Match:
        """The first stderr line (from line `start` on) matching the regular expression."""
        deadline = time.monotonic() + (timeout or self.timeout)
        regex = re.compile(pattern)
        with self._changed:
            while True:
                for line in self.lines[start:]:
                    match = regex.search(line)
                    if match:
                        return match
                if self.process.poll() is not None and not self._reader.is_alive():
                    raise AssertionError(f"viewer exited ({self.process.returncode}) without {pattern!r}:\n{self.log}")
                left = deadline - time.monotonic()
                if left <= 0:
                    raise AssertionError(f"no {pattern!r} from the viewer in time:\n{self.log}")
                self._changed.wait(min(left, 0.5))

    def ready(self) -> int:
        """Wait for the first frame; returns the X11 window id."""
        self.window = int(self.wait_for(r"ready: window (0x[0-9a-f]+)").group(1), 16)
        return self.window

    def wait_exit(self, timeout: float | None = None) -> int:
        try:
            code = self.process.wait(timeout=timeout or self.timeout)
        except subprocess.TimeoutExpired:
            self.process.kill()
            raise AssertionError(f"viewer did not exit in time:\n{self.log}") from None
        self._reader.join(timeout=5.0)
        return code

    def kill(self) -> None:
        if self.process.poll() is None:
            self.process.kill()
            self.process.wait()

"""Window input: every event goes to imgui first; what imgui does not want moves the camera or is a
hotkey.

Mouse: left drag orbits, shift + left drag or middle drag pans, the wheel zooms, right drag looks
around and, while the right button is held, W A S D / Q E fly (so S alone stays free for screenshots).
"""

from __future__ import annotations

import time
from typing import Callable

from viewer.ui.camera_controller import OrbitCamera
from viewer.ui.imgui_input import ImguiInput


class Controls:
    def __init__(self, wnd, imgui_input: ImguiInput, camera: Callable[[], OrbitCamera],
                 hotkeys: dict[int, Callable], linger: float = 0.25):
        self.wnd = wnd
        self.imgui = imgui_input
        self.camera = camera
        """The camera to move (a function: the session replaces it when a scene is opened)."""
        self.hotkeys = hotkeys
        """Key code -> function(modifiers), called on a press that imgui does not want."""
        self.linger = linger
        """Seconds after camera input during which the view counts as moving (preview resolution)."""
        self.gesture: str | None = None     # "orbit", "pan" or "look" while a button is held
        self._button = None
        self.last_input = time.perf_counter()
        self._moving_until = 0.0

    @property
    def moving(self) -> bool:
        """The user is moving the camera (or just did)."""
        return self.gesture is not None or time.perf_counter() < self._moving_until

    def touch(self, moved: bool = True) -> None:
        self.last_input = time.perf_counter()
        if moved:
            self._moving_until = self.last_input + self.linger

    # ---- keyboard -----------------------------------------------------------------------------------
    def key(self, key, action, modifiers) -> None:
        keys = self.wnd.keys
        self.imgui.key(key, action != keys.ACTION_RELEASE, modifiers.shift, modifiers.ctrl, modifiers.alt)
        self.touch(moved=False)
        if action == keys.ACTION_PRESS and not self.imgui.wants_keyboard and key in self.hotkeys:
            if not (self.gesture == "look" and key in (keys.W, keys.A, keys.S, keys.D, keys.Q, keys.E)):
                self.hotkeys[key](modifiers)

    def character(self, char: str) -> None:
        self.imgui.character(char)

    def fly(self, seconds: float) -> None:
        """Move the camera by the fly keys held down (only while the right button looks around)."""
        if self.gesture != "look":
            return
        keys, pressed = self.wnd.keys, self.wnd.is_key_pressed
        forward = pressed(keys.W) - pressed(keys.S)
        right = pressed(keys.D) - pressed(keys.A)
        up = pressed(keys.E) - pressed(keys.Q)
        if forward or right or up:
            self.camera().fly(forward, right, up, min(seconds, 0.1), fast=self.wnd.modifiers.shift)
            self.touch()

    # ---- mouse --------------------------------------------------------------------------------------
    def mouse_position(self, x: int, y: int) -> None:
        self.imgui.mouse_position(x, y)
        self.touch(moved=False)

    def mouse_press(self, x: int, y: int, button: int) -> None:
        self.imgui.mouse_button(x, y, button, True)
        self.touch(moved=False)
        if self.imgui.wants_mouse or self.gesture is not None:
            return
        mouse = self.wnd.mouse
        if button == mouse.left:
            self.gesture = "pan" if self.wnd.modifiers.shift else "orbit"
        elif button == mouse.middle:
            self.gesture = "pan"
        elif button == mouse.right:
            self.gesture = "look"
        self._button = button

    def mouse_drag(self, x: int, y: int, dx: int, dy: int) -> None:
        self.imgui.mouse_position(x, y)
        camera = self.camera()
        if self.gesture == "orbit":
            camera.orbit(dx, dy)
        elif self.gesture == "pan":
            camera.pan(dx, dy, self.wnd.size[1])
        elif self.gesture == "look":
            camera.look(dx, dy)
        self.touch(moved=self.gesture is not None)

    def mouse_release(self, x: int, y: int, button: int) -> None:
        self.imgui.mouse_button(x, y, button, False)
        if self.gesture is not None and button == self._button:
            self.gesture = None
            self.touch()

    def scroll(self, x_offset: float, y_offset: float) -> None:
        self.imgui.scroll(x_offset, y_offset)
        if not self.imgui.wants_mouse:
            self.camera().zoom(y_offset)
            self.touch()
        else:
            self.touch(moved=False)

"""Window events (moderngl-window's glfw backend) -> imgui's input queue.

imgui >= 1.87 takes input as events (`io.add_mouse_pos_event`, `add_key_event`, ...); this is the
platform half of an imgui backend, the GL half being `viewer.ui.imgui_renderer`. Key codes are GLFW's,
which is what moderngl-window's glfw window passes on.
"""

from __future__ import annotations

import glfw
from imgui_bundle import imgui


def _key_map() -> dict[int, int]:
    """GLFW key code -> imgui.Key."""
    k = imgui.Key
    table = {getattr(glfw, f"KEY_{c}"): getattr(k, c.lower()) for c in "ABCDEFGHIJKLMNOPQRSTUVWXYZ"}
    table.update({getattr(glfw, f"KEY_{d}"): getattr(k, f"_{d}", None) for d in range(10)})
    table.update({getattr(glfw, f"KEY_F{n}"): getattr(k, f"f{n}") for n in range(1, 13)})
    table.update({getattr(glfw, f"KEY_KP_{d}"): getattr(k, f"keypad{d}") for d in range(10)})
    names = {
        "TAB": "tab", "LEFT": "left_arrow", "RIGHT": "right_arrow", "UP": "up_arrow", "DOWN": "down_arrow",
        "PAGE_UP": "page_up", "PAGE_DOWN": "page_down", "HOME": "home", "END": "end", "INSERT": "insert",
        "DELETE": "delete", "BACKSPACE": "backspace", "SPACE": "space", "ENTER": "enter", "ESCAPE": "escape",
        "APOSTROPHE": "apostrophe", "COMMA": "comma", "MINUS": "minus", "PERIOD": "period", "SLASH": "slash",
        "SEMICOLON": "semicolon", "EQUAL": "equal", "LEFT_BRACKET": "left_bracket", "BACKSLASH": "backslash",
        "RIGHT_BRACKET": "right_bracket", "GRAVE_ACCENT": "grave_accent", "KP_ENTER": "keypad_enter",
        "KP_DECIMAL": "keypad_decimal", "KP_ADD": "keypad_add", "KP_SUBTRACT": "keypad_subtract",
        "LEFT_SHIFT": "left_shift", "RIGHT_SHIFT": "right_shift", "LEFT_CONTROL": "left_ctrl",
        "RIGHT_CONTROL": "right_ctrl", "LEFT_ALT": "left_alt", "RIGHT_ALT": "right_alt",
        "LEFT_SUPER": "left_super", "RIGHT_SUPER": "right_super",
    }
    table.update({getattr(glfw, f"KEY_{g}"): getattr(k, i) for g, i in names.items()})
    return {code: key for code, key in table.items() if key is not None}


KEYS = _key_map()
MOUSE_BUTTONS = {1: 0, 2: 1, 3: 2}
"""moderngl-window's buttons (1 left, 2 right, 3 middle) -> imgui's (0 left, 1 right, 2 middle)."""


class ImguiInput:
    """Forwards events to imgui and says whether imgui wants them (then the 3D view should not act)."""

    def __init__(self, size: tuple[int, int], buffer_size: tuple[int, int]):
        self.io = imgui.get_io()
        self.resize(size, buffer_size)

    def resize(self, size: tuple[int, int], buffer_size: tuple[int, int]) -> None:
        self.io.display_size = (float(size[0]), float(size[1]))
        scale = (buffer_size[0] / max(size[0], 1), buffer_size[1] / max(size[1], 1))
        self.io.display_framebuffer_scale = scale

    @property
    def wants_mouse(self) -> bool:
        return bool(self.io.want_capture_mouse)

    @property
    def wants_keyboard(self) -> bool:
        return bool(self.io.want_capture_keyboard)

    def mouse_position(self, x: float, y: float) -> None:
        self.io.add_mouse_pos_event(float(x), float(y))

    def mouse_button(self, x: float, y: float, button: int, down: bool) -> None:
        self.io.add_mouse_pos_event(float(x), float(y))
        if button in MOUSE_BUTTONS:
            self.io.add_mouse_button_event(MOUSE_BUTTONS[button], down)

    def scroll(self, x_offset: float, y_offset: float) -> None:
        self.io.add_mouse_wheel_event(float(x_offset), float(y_offset))

    def key(self, code: int, down: bool, shift: bool, ctrl: bool, alt: bool) -> None:
        self.io.add_key_event(imgui.Key.mod_shift, shift)
        self.io.add_key_event(imgui.Key.mod_ctrl, ctrl)
        self.io.add_key_event(imgui.Key.mod_alt, alt)
        if code in KEYS:
            self.io.add_key_event(KEYS[code], down)

    def character(self, char: str) -> None:
        self.io.add_input_character(ord(char))

"""What the panel's sections share: their note colour and the "(?)" tooltip."""

from __future__ import annotations

from imgui_bundle import imgui

NOTE_COLOUR = imgui.ImVec4(0.75, 0.75, 0.75, 1.0)


def tooltip(text: str) -> None:
    """A "(?)" after the last item, with `text` on hover."""
    imgui.same_line()
    imgui.text_disabled("(?)")
    imgui.set_item_tooltip(text)

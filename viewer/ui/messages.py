"""What the window's panels and the headless session share without imgui: the messages shown to the user
and the width of the settings panel (the scene is drawn left of it)."""

from __future__ import annotations

import time
from dataclasses import dataclass, field

PANEL_WIDTH = 360


@dataclass
class Message:
    text: str
    error: bool = False
    warning: bool = False
    """A warning stays until dismissed, as an error does (a note fades)."""
    at: float = field(default_factory=time.perf_counter)

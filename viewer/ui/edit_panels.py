"""The settings panel's scene-edit sections: the light, the objects, the materials. Each edits the
SceneEdits it is given and says whether it changed anything (viewer.ui.panels lays them out)."""

from __future__ import annotations

import numpy as np
from imgui_bundle import imgui

from viewer.ui.panel_style import NOTE_COLOUR, tooltip as _tooltip
from viewer.ui.scene_edits import SceneEdits


def _to_srgb(linear) -> list[float]:
    """Linear colour -> sRGB-encoded, as colour pickers show colours (IEC 61966-2-1)."""
    x = np.clip(np.asarray(linear, np.float64), 0.0, 1.0)
    return list(np.where(x <= 0.0031308, 12.92 * x, 1.055 * x ** (1 / 2.4) - 0.055))


def _to_linear(srgb) -> np.ndarray:
    x = np.clip(np.asarray(srgb, np.float64), 0.0, 1.0)
    return np.where(x <= 0.04045, x / 12.92, ((x + 0.055) / 1.055) ** 2.4)


def colour_edit(label: str, linear) -> tuple[bool, np.ndarray]:
    """A colour picker that shows a linear colour as it looks on screen (sRGB) and returns it linear."""
    changed, picked = imgui.color_edit3(label, _to_srgb(linear))
    return changed, _to_linear(picked) if changed else np.asarray(linear, np.float64)


def light_section(edits: SceneEdits, scene_size: float) -> bool:
    light = edits.light
    changed = False
    if light.group is None and light.direction is None:
        imgui.text_colored(NOTE_COLOUR, "This scene has no emitter and no sun.")
        return False
    if light.group is not None:
        imgui.text(f"Emitter: {light.group}")
        moved, offset = imgui.drag_float3("position", list(light.centre + light.offset), 0.005 * scene_size)
        if moved:
            edits.set_light(offset=np.asarray(offset) - light.centre)
        resized, size = imgui.slider_float("size", light.size, 0.1, 4.0, "%.2f x",
                                           imgui.SliderFlags_.logarithmic)
        if resized:
            edits.set_light(size=size)
        changed |= moved or resized
    else:
        imgui.text("Sun")
        turned, direction = imgui.drag_float3("direction", list(light.direction), 0.01, -1.0, 1.0)
        if turned:
            edits.set_light(direction=direction)
        changed |= turned
    recoloured, colour = colour_edit("colour", light.colour)
    if recoloured:
        edits.set_light(colour=colour)
    top = max(100.0, 10.0 ** np.ceil(np.log10(max(edits.initial_intensity, 1e-3) * 5.0)))
    brighter, intensity = imgui.slider_float("intensity", light.intensity, 0.01, top, "%.2f",
                                             imgui.SliderFlags_.logarithmic)
    if brighter:
        edits.set_light(intensity=intensity)
    return changed or recoloured or brighter


def objects_section(edits: SceneEdits, scene_size: float) -> bool:
    """Move an object (a material group): pick it, drag its position; whether it moved."""
    groups = edits.material_groups
    if not groups:
        imgui.text_colored(NOTE_COLOUR, "This scene has nothing to move but its light.")
        return False
    if edits.selected not in groups:
        edits.selected = groups[0]
    picked, index = imgui.combo("object", groups.index(edits.selected), groups)
    if picked:
        edits.selected = groups[index]
    group = edits.selected
    centre = edits.centre_of(group)
    moved, position = imgui.drag_float3("position##object", list(centre + edits.offset_of(group)),
                                        0.005 * scene_size)
    if moved:
        edits.set_offset(group, np.asarray(position) - centre)
    _tooltip("Drag to move the object; the light follows it as soon as it rests")
    back = bool(np.any(edits.offset_of(group) != 0.0)) and imgui.button("Put it back")
    if back:
        edits.set_offset(group, np.zeros(3))
    return moved or back


def materials_section(edits: SceneEdits) -> bool:
    """Albedo per group (shown sRGB-encoded; the scene keeps linear reflectance)."""
    changed = False
    for group in edits.material_groups:
        edited, rgb = colour_edit(group, edits.albedo_of(group))
        if edited:
            edits.set_albedo(group, rgb)
            changed = True
    return changed

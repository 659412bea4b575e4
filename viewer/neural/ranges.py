"""What the procedural rooms are drawn from: `Ranges`, and the named presets the datasets use.

`Ranges()` is the first dataset's ("v1", what models/probenet.onnx was trained on and what the
out-of-distribution study of viewer.bench.stability measures distances from); `PRESETS["v2"]` is the
wide one (v2): any albedo from near black to near white, one to three lights of any size, colour
and intensity on any surface (objects included), sun through windows more often, thin partitions,
more objects and elongated rooms. A dataset records the preset's name and every field it drew from.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

OBJECT_KINDS = ("box", "sphere", "cylinder", "cone", "wedge", "tilted-box")
LIGHT_SURFACES = ("ceiling", "back", "left-wall", "right-wall", "floor", "object")


@dataclass(frozen=True)
class Ranges:
    """Everything `random_scene` draws, as ranges (lo, hi) and probabilities."""

    room_scale: tuple[float, float] = (0.75, 1.3)
    """Half extent of the room along x, y and z (drawn independently; `cornell` is 1, 1, 1)."""
    albedo: tuple[float, float] = (0.05, 0.9)
    """Bounds of every albedo component, walls and objects alike."""
    grey_level: tuple[float, float] = (0.35, 0.9)
    """Brightness of a white or grey surface (before its slight tint)."""
    grey_tint: float = 0.06
    """Largest departure of a grey's channels from its brightness (warm / cool whites)."""
    saturated_wall_probability: float = 0.25
    """Chance that a wall (each of the five alone) gets a saturated colour instead of a white or grey."""
    saturated_object_probability: float = 0.6
    """Chance that an object gets a saturated colour instead of a white or grey."""
    saturation: tuple[float, float] = (0.5, 0.95)
    """HSV saturation of a saturated colour."""
    value: tuple[float, float] = (0.35, 0.9)
    """HSV value of a saturated colour."""
    objects: tuple[int, int] = (0, 4)
    """Fewest and most objects in a room (inclusive; fewer when they do not fit)."""
    object_kinds: tuple[str, ...] = OBJECT_KINDS
    """Shapes to draw from: box, sphere, cylinder, cone, wedge, tilted-box; and "slab", never trained on
    (an upright panel 0.02-0.04 thick)."""
    object_half_width: tuple[float, float] = (0.1, 0.4)
    """Horizontal half extent (or radius) of an object."""
    object_half_height: tuple[float, float] = (0.1, 0.6)
    """Vertical half extent of a box, cylinder, cone or wedge."""
    tilt_degrees: tuple[float, float] = (10.0, 35.0)
    """Tilt of a tilted box about a horizontal axis (it rests on an edge)."""
    stack_probability: float = 0.3
    """Chance that an object is put on top of an upright box or cylinder already in the room."""
    hang_probability: float = 0.0
    """Chance that an object floats just under the ceiling lights instead of standing on the floor
    (never in training: the out-of-distribution study's)."""
    placement_tries: int = 50
    """Rejection-sampling tries per object before it is left out (no object overlaps another)."""
    lights: tuple[int, int] = (1, 2)
    """Fewest and most area lights (inclusive)."""
    light_half_extent: tuple[float, float] = (0.05, 0.6)
    """Half extent of a rectangular light along each of its two axes."""
    light_power: tuple[float, float] = (0.3, 3.0)
    """Total power of the area lights, in units of `CORNELL_POWER` (drawn log-uniformly)."""
    wall_light_probability: float = 0.2
    """Chance that a light hangs on the back or a side wall (facing into the room) instead of under
    the ceiling (facing down)."""
    floor_light_probability: float = 0.0
    """Chance that a light lies on the floor facing up (never in training: the out-of-distribution
    study's; objects may stand on it)."""
    colour_temperature: tuple[float, float] = (2700.0, 9000.0)
    """Colour temperature (K) of a light: the Planck spectrum at 610, 550 and 465 nm."""
    light_tint_probability: float = 0.15
    """Chance that a light is tinted by a saturated colour on top of its temperature."""
    window_probability: float = 0.2
    """Chance that the room has a window (ceiling, back or a side wall) with the sun shining through."""
    window_half_extent: tuple[float, float] = (0.15, 0.4)
    """Half extent of the window along each of its two axes."""
    sun_power: tuple[float, float] = (0.3, 3.0)
    """Power of the sunlight through the window, in units of `CORNELL_POWER` (log-uniform)."""
    sun_temperature: tuple[float, float] = (4500.0, 7000.0)
    """Colour temperature (K) of the sun."""
    sun_zenith_degrees: tuple[float, float] = (0.0, 50.0)
    """Angle of the sun from the window's axis (ceiling: from straight up)."""
    light_surfaces: tuple[str, ...] = ()
    """v2: surfaces a light is drawn on, each equally likely ("ceiling", "back", "left-wall",
    "right-wall", "floor", "object": an object that glows all over). Empty: the v1 rule above
    (`wall_light_probability`, `floor_light_probability`)."""
    wall_lights_up: bool = True
    """Whether a light on the back or a side wall stays in the wall's upper half (v1), or may hang
    anywhere on it."""
    light_share: tuple[float, float] = (0.3, 1.0)
    """Each light's share of the total power is drawn from this range, then the shares are normalized
    (so with (0.05, 1) one lamp can be twenty times another)."""
    partitions: tuple[int, int] = (0, 0)
    """Fewest and most thin partitions: upright panels standing on the floor, at right angles to the
    back or a side wall, a gap `OBJECT_GAP` from it (so the two halves of the room share some light)."""
    partition_thickness: tuple[float, float] = (0.02, 0.05)
    """Full thickness of a partition."""
    partition_length: tuple[float, float] = (0.3, 0.7)
    """Length of a partition along the floor, as a share of the room's extent in that direction."""
    partition_height: tuple[float, float] = (0.5, 1.0)
    """Height of a partition as a share of the clear height (floor to just under the ceiling lights)."""

    def as_dict(self) -> dict:
        """JSON-able: every field (tuples as lists)."""
        return asdict(self)


V2 = Ranges(
    room_scale=(0.6, 1.8),
    albedo=(0.01, 0.95),
    grey_level=(0.01, 0.95),
    saturated_wall_probability=0.3,
    value=(0.05, 0.95),
    objects=(0, 6),
    object_half_width=(0.08, 0.45),
    object_half_height=(0.05, 0.7),
    lights=(1, 3),
    light_half_extent=(0.03, 0.6),
    light_power=(0.1, 10.0),
    light_share=(0.05, 1.0),
    light_surfaces=LIGHT_SURFACES,
    wall_lights_up=False,
    colour_temperature=(2000.0, 10000.0),
    light_tint_probability=0.3,
    window_probability=0.35,
    window_half_extent=(0.1, 0.5),
    sun_power=(0.1, 10.0),
    sun_zenith_degrees=(0.0, 60.0),
    partitions=(0, 2),
)
"""The v2 ranges: albedo 0.01-0.95 per surface; 1-3 lights, each on the ceiling, a wall, the floor
or an object, 0.03-0.6 half extent, 2000-10000 K (three in ten tinted), 0.1-10x the Cornell light's power
in all, one light up to twenty times another; a window with the sun in about one room in three; up to two
thin partitions and six objects; each half extent 0.6-1.8 (rooms up to three times longer than high)."""

PRESETS = {"v1": Ranges(), "v2": V2}
"""The ranges a dataset names (`--ranges`)."""

"""What a neural model was trained on, in quantities a scene can be measured by, and the scenes that lie
outside it: an honest guard for the neural GI source.

A model card (models/NAME.json) carries its `Domain`, derived from the procedural rooms' ranges
(`viewer.neural.ranges`) that its dataset was drawn from (`Domain.from_ranges`). `outside(scene,
domain)` measures a loaded scene (`measure`) and returns readable reasons why the network's answer
there is a guess, e.g. "'white' albedo 0.99 is above the trained 0.90".

Only what the network can see is checked. Its input is normalized (viewer.neural.encoding): every length
enters relative to the scene's bounds (the probe lattice spans them, densities are per cell face, the
direct light's near-field clamp r^2 + A/pi scales with them) and each colour pass's light is divided by
its own scale. So the absolute size of a room (a file in millimetres or in miles) and the absolute
power of its lamps are irrelevant; what is not normalized away is checked: albedos, the room's
proportions, how open it is, how many lights there are, where they hang, how large they are relative to
the surface they cover, how their powers compare, and whether there is a sun.
"""

from __future__ import annotations

import sys
from dataclasses import asdict, dataclass, field, fields

import numba
import numpy as np
from scipy import sparse
from scipy.sparse import csgraph

from viewer.rays.moved_faces import changed_rows
from viewer.scene import Scene
from viewer.threads import RUNS, cores_for

ALBEDO_MARGIN = 0.02
"""Albedos this far below the trained minimum still count as inside (a surface that dark reflects
little light, whatever the network makes of it)."""
WHITE_MARGIN = 0.8
"""Above the trained maximum, an albedo counts as outside once 1 - albedo is below this share of the
trained 1 - max: the bounces sum as 1 / (1 - albedo), so 0.92 against a trained 0.90 is a small step
and 0.99 a tenfold one."""
RATIO_MARGIN = 1.25
"""Sizes, proportions and power ratios within this factor of the trained bounds count as inside."""
COVERED = 0.5
"""A side of the scene's box is closed when surfaces cover this share of it."""
SIDE_TOLERANCE = 0.01
"""Surfaces within this share of the largest extent from a side of the box lie on it."""
MIN_SURFACE_SHARE = 0.005
"""Groups with less than this share of the scene's surface are not checked for albedo."""


@dataclass(frozen=True)
class Domain:
    """The training domain of a model, in quantities `measure` finds in any scene."""

    ranges: str
    """The preset of viewer.neural.ranges the dataset was drawn from (`v1`, `v2`)."""
    albedo: tuple[float, float]
    """Lowest and highest albedo component of any surface."""
    room_half_extent: tuple[float, float]
    """Half extents of the rooms along each axis, in the training rooms' units (the Cornell box is 1);
    for reference only: absolute size is normalized away."""
    room_aspect: float
    """Largest ratio of the room's longest side to its shortest."""
    lights: tuple[int, int]
    """Fewest and most lights (lamps and glowing objects) in a room."""
    light_area: tuple[float, float]
    """Smallest and largest area of one rectangular light as a share of the side of the room it lies on."""
    light_power_ratio: float
    """Largest ratio of the brightest light's power to the dimmest's in one room."""
    light_surfaces: tuple[str, ...]
    """Where lights were: `ceiling` (facing down), `wall`, `floor` (facing up), `object` (glowing all round)."""
    sun: bool
    """Whether rooms had a sun (through a window)."""
    open_sides: int
    """Sides of the room's box left open: the procedural rooms are all open at the front, so a scene
    open on more sides, or closed all round (where the light bounces on instead of leaving), is outside."""

    @staticmethod
    def from_ranges(ranges, name: str) -> "Domain":
        """The domain of a dataset drawn with `ranges` (a viewer.neural.ranges.Ranges)."""
        room = np.asarray(ranges.room_scale, np.float64)
        low, high = float(room.min()), float(room.max())
        light_low, light_high = ranges.light_half_extent
        # a light's half extent along a side of half extent h is min(light_high, 0.95 h - 0.05)
        # (viewer.evaluation.lights.rectangle_light): its largest share of that side
        sides = np.linspace(low, high, 256)
        along = float(np.max(np.minimum(light_high, 0.95 * sides - 0.05) / sides))
        if ranges.light_surfaces:
            kinds = {"ceiling": "ceiling", "floor": "floor", "object": "object"}
            surfaces = sorted({kinds.get(s, "wall") for s in ranges.light_surfaces})
        else:
            surfaces = ["ceiling"] + (["wall"] if ranges.wall_light_probability > 0 else []) + (
                ["floor"] if ranges.floor_light_probability > 0 else [])
        shares = ranges.light_share
        return Domain(ranges=name, albedo=tuple(float(a) for a in ranges.albedo), room_half_extent=(low, high),
                      room_aspect=high / low, lights=tuple(int(n) for n in ranges.lights),
                      light_area=((light_low / high) ** 2, along ** 2),
                      light_power_ratio=float(shares[1] / shares[0]) if ranges.lights[1] > 1 else 1.0,
                      light_surfaces=tuple(surfaces), sun=ranges.window_probability > 0, open_sides=1)

    @staticmethod
    def from_preset(name: str) -> "Domain":
        from viewer.neural.ranges import PRESETS

        return Domain.from_ranges(PRESETS[name], name)

    def to_dict(self) -> dict:
        """JSON-able, as a model card stores it."""
        return {k: list(v) if isinstance(v, tuple) else v for k, v in asdict(self).items()}

    @staticmethod
    def from_dict(data: dict) -> "Domain":
        values = {}
        for f in fields(Domain):
            value = data[f.name]
            values[f.name] = tuple(value) if isinstance(value, list) else value
        return Domain(**values)


@dataclass(frozen=True)
class Light:
    """One light of a scene: connected emitting triangles."""

    name: str
    """The group it belongs to."""
    area: float
    power: float
    """Emitted power: pi x area x mean radiance (any units: only ratios are used)."""
    surface: str
    """`ceiling`, `wall`, `floor` or `object`, from its mean normal."""
    share: float
    """Its area over the area of the side of the scene's box it faces away from (over the whole box's
    surface for an `object`)."""


@dataclass(frozen=True)
class Quantities:
    """What `measure` finds in a scene."""

    albedo: dict[str, np.ndarray]
    """Group -> area-weighted albedo (RGB), for the groups that are not lights."""
    aspect: float
    """The box's longest side over its shortest."""
    lights: list[Light]
    sun: bool
    open_sides: int


@dataclass(frozen=True)
class Shape:
    """What `measure` takes from the triangles alone (kept while only colours change)."""

    lo: np.ndarray
    hi: np.ndarray
    areas: np.ndarray
    normals: np.ndarray
    """(F, 3) unit normals (zero for degenerate faces)."""
    aspect: float
    open_sides: int
    sums: list = field(default_factory=lambda: [None], compare=False, repr=False)
    """`_group_albedo`'s last sums on these triangles: [((emitting, face_group), albedo, surface, group
    area, weighted)]."""

    @staticmethod
    def of(scene: Scene) -> "Shape":
        lo, hi = scene.bounds
        triangles, areas, normals = scene.triangles, scene.face_areas, scene.face_normals   # kept by the scene
        extent = hi - lo
        return Shape(lo, hi, areas, normals, float(extent.max() / extent.min()),
                     _open_sides(triangles, areas, normals, lo, hi))


def measure(scene: Scene, shape: Shape | None = None) -> Quantities:
    """The scene's quantities; `shape`: its triangles' (`Shape.of(scene)`), when already known."""
    shape = shape or Shape.of(scene)
    emitting = scene.emitting & (shape.areas > 0)
    return Quantities(albedo=_group_albedo(scene, shape, emitting), aspect=shape.aspect,
                      lights=_lights(scene, emitting, shape),
                      sun=scene.sun is not None and bool(np.any(scene.sun.irradiance > 0)),
                      open_sides=shape.open_sides)


def _group_albedo(scene: Scene, shape: Shape, emitting: np.ndarray) -> dict[str, np.ndarray]:
    """Group -> area-weighted albedo of the groups that are not lights (`Quantities.albedo`). The sums of
    the last call are kept with the triangles' `Shape`: on the same lamps and groups, only the groups whose albedo changed
    are summed again (on a million-triangle scan the sums took 24-30 ms of each colour edit)."""
    kept, count = shape.sums[0], len(scene.groups)
    if kept is not None and kept[0][1] is scene.face_group and np.array_equal(kept[0][0], emitting):
        _, before, surface, group_area, weighted = kept
        if before is not scene.albedo:
            weighted = weighted.copy()
            changed = np.flatnonzero(changed_rows((scene.albedo, before)))
            for g in np.unique(scene.face_group[changed]):
                faces = np.flatnonzero(scene.face_group == g)   # summed in the order bincount sums them
                weighted[g] = [np.bincount(np.zeros(len(faces), np.int64), surface[faces] * scene.albedo[faces, c],
                                           minlength=1)[0] for c in range(3)]
    else:
        surface = shape.areas * ~emitting
        group_area = np.bincount(scene.face_group, surface, minlength=count)
        weighted = np.stack([np.bincount(scene.face_group, surface * scene.albedo[:, c], minlength=count)
                             for c in range(3)], axis=1)
    shape.sums[0] = ((emitting, scene.face_group), scene.albedo, surface, group_area, weighted)
    return {name: weighted[g] / group_area[g] for g, name in enumerate(scene.groups)
            if group_area[g] > MIN_SURFACE_SHARE * group_area.sum()}


def _lights(scene: Scene, emitting: np.ndarray, shape: Shape) -> list[Light]:
    """The emitting triangles in connected pieces (sharing a corner), each a Light."""
    faces = np.flatnonzero(emitting)
    if len(faces) == 0:
        return []
    lo, extent = shape.lo, shape.hi - shape.lo
    corners = scene.vertices[scene.faces[faces]].reshape(-1, 3)
    _, vertex = np.unique(np.round((corners - lo) / (1e-6 * extent.max())).astype(np.int64), axis=0,
                          return_inverse=True)
    vertex = vertex.ravel()
    count = len(faces)
    graph = sparse.coo_matrix((np.ones(len(vertex)), (np.repeat(np.arange(count), 3), count + vertex)),
                              shape=(count + vertex.max() + 1,) * 2)
    _, label = csgraph.connected_components(graph, directed=False)
    areas, normals = shape.areas[faces], shape.normals[faces]
    radiance = scene.emission[faces].mean(axis=1)
    side_area = np.array([extent[1] * extent[2], extent[0] * extent[2], extent[0] * extent[1]])
    out = []
    for piece in np.unique(label[:count]):
        mine = label[:count] == piece
        area = float(areas[mine].sum())
        normal = (areas[mine, None] * normals[mine]).sum(axis=0) / area
        axis = int(np.argmax(np.abs(normal)))
        if np.linalg.norm(normal) < 0.5:           # emits all round: a glowing object
            surface, share = "object", area / (2 * side_area.sum())
        else:
            surface = "wall" if axis != 1 else ("ceiling" if normal[1] < 0 else "floor")
            share = area / side_area[axis]
        group = scene.groups[int(np.bincount(scene.face_group[faces[mine]]).argmax())]
        out.append(Light(group, area, float(np.pi * np.sum(areas[mine] * radiance[mine])), surface, share))
    return out


def _open_sides(triangles: np.ndarray, areas: np.ndarray, normals: np.ndarray, lo: np.ndarray,
                hi: np.ndarray) -> int:
    """How many of the six sides of the scene's box surfaces do not cover (`COVERED`): the area of the
    faces facing each side's axis (|normal| > 0.7 along it) that lie within SIDE_TOLERANCE of its plane,
    in one compiled pass over the faces on every core (a 68k-triangle scan: 8 ms in numpy, every time an
    object moved; a million-triangle one 9 ms on one core)."""
    lo, hi = np.asarray(lo, np.float64), np.asarray(hi, np.float64)
    with cores_for(len(areas)):
        covered = _side_areas(np.ascontiguousarray(triangles, np.float64), np.ascontiguousarray(areas, np.float64),
                              np.ascontiguousarray(normals, np.float64), lo, hi,
                              SIDE_TOLERANCE * float((hi - lo).max())).sum(axis=0)
    extent = hi - lo
    sides = np.repeat([extent[1] * extent[2], extent[0] * extent[2], extent[0] * extent[1]], 2)
    return int(np.sum(covered < COVERED * sides))


@numba.njit(cache=True, nogil=True, parallel=True)
def _side_areas(triangles, areas, normals, lo, hi, tolerance):
    """(RUNS, 6) the area of the faces of each run lying on each side of the box [lo, hi] (low, high
    side of x, y, z)."""
    out = np.zeros((RUNS, 6))
    step = (triangles.shape[0] + RUNS - 1) // RUNS
    for run in numba.prange(RUNS):
        for f in range(run * step, min((run + 1) * step, triangles.shape[0])):
            for axis in range(3):
                if abs(normals[f, axis]) <= 0.7:
                    continue
                a, b, c = triangles[f, 0, axis], triangles[f, 1, axis], triangles[f, 2, axis]
                low, high = min(a, b, c), max(a, b, c)
                if low >= lo[axis] - tolerance and high <= lo[axis] + tolerance:
                    out[run, 2 * axis] += areas[f]
                if low >= hi[axis] - tolerance and high <= hi[axis] + tolerance:
                    out[run, 2 * axis + 1] += areas[f]
    return out


SIDE_NAMES = {"ceiling": "ceiling", "floor": "floor", "wall": "wall"}


def outside(scene: Scene, domain: Domain, quantities: Quantities | None = None) -> list[str]:
    """Readable reasons why `scene` lies outside `domain` (empty: inside, as far as can be measured)."""
    q = quantities or measure(scene)
    reasons = []
    low, high = domain.albedo
    if q.albedo:
        name, top = max(((n, float(a.max())) for n, a in q.albedo.items()), key=lambda x: x[1])
        if 1.0 - top < WHITE_MARGIN * (1.0 - high):
            reasons.append(f"'{name}' albedo {top:.2f} is above the trained {high:.2f}")
        name, bottom = min(((n, float(a.min())) for n, a in q.albedo.items()), key=lambda x: x[1])
        if bottom < low - ALBEDO_MARGIN:
            reasons.append(f"'{name}' albedo {bottom:.2f} is below the trained {low:.2f}")
    if q.aspect > domain.room_aspect * RATIO_MARGIN:
        reasons.append(f"the room is {q.aspect:.1f} times longer than it is narrow; trained up to "
                       f"{domain.room_aspect:.1f}")
    if q.open_sides > domain.open_sides:
        reasons.append(f"the scene is open on {q.open_sides} sides of its box; trained on rooms open on "
                       f"{domain.open_sides}")
    elif q.open_sides < domain.open_sides:   # light that cannot leave bounces on: more than it ever saw
        reasons.append(f"the scene is open on {q.open_sides} sides of its box; every training room was "
                       f"open on {domain.open_sides}")
    lights = q.lights
    if len(lights) > domain.lights[1]:
        reasons.append(f"{len(lights)} lights; trained with at most {domain.lights[1]}")
    if not lights and q.sun and domain.lights[0] > 0:
        reasons.append("lit by the sun alone; every training room had a lamp")
    if q.sun and not domain.sun:
        reasons.append("a sun; trained without one")
    for kind in dict.fromkeys(light.surface for light in lights):
        if kind not in domain.light_surfaces:
            where = {"floor": "on the floor (facing up)", "object": "on an object (glowing all round)",
                     "wall": "on a wall", "ceiling": "on the ceiling"}[kind]
            reasons.append(f"a light {where}; trained with lights on the {' and '.join(domain.light_surfaces)} only")
    flat = [light for light in lights if light.surface != "object"]
    if flat:
        big = max(flat, key=lambda light: light.share)
        if big.share > domain.light_area[1] * RATIO_MARGIN:
            reasons.append(f"'{big.name}' covers {100 * big.share:.0f}% of the {SIDE_NAMES[big.surface]}; "
                           f"trained up to {100 * domain.light_area[1]:.0f}%")
        small = min(flat, key=lambda light: light.share)
        if small.share < domain.light_area[0] / RATIO_MARGIN:
            reasons.append(f"'{small.name}' covers {100 * small.share:.2g}% of the {SIDE_NAMES[small.surface]}; "
                           f"trained down to {100 * domain.light_area[0]:.2g}%")
    powers = [light.power for light in lights if light.power > 0]
    if len(powers) > 1 and max(powers) / min(powers) > domain.light_power_ratio * RATIO_MARGIN:
        reasons.append(f"the brightest light emits {max(powers) / min(powers):.0f} times the power of the dimmest; "
                       f"trained up to {domain.light_power_ratio:.0f}")
    return reasons


def warning(reasons: list[str]) -> str | None:
    """One line for the viewer and the command line, or None when there is nothing to say."""
    if not reasons:
        return None
    return ("This scene lies outside what the neural model was trained on (" + "; ".join(reasons)
            + "): its light is a guess here. The physical solver computes it: the compute or the CPU source "
              "(`--gi compute` in the window and in capture, `--method solver` in sample).")


def print_warning(scene: Scene, domain: Domain) -> None:
    """The command line's notice: `warning` as one line on stderr when there are reasons (not an error:
    the exit status stays 0)."""
    line = warning(outside(scene, domain))
    if line:
        print(f"warning: {line}", file=sys.stderr)

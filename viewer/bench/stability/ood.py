"""Out of distribution: the neural field's error against a scene's distance from its training set.

Rooms are drawn with `viewer.training.procedural.random_scene` and `Ranges` moved one axis at a time,
from inside the trained ranges to well outside them (`STEPS`): room proportions, colours, lights
(size and placement) and shapes; plus rooms drawn with the training ranges themselves (`in
distribution`: the same generator, seeds the training set never used) as the baseline. Per room:
relative RMSE against Mitsuba at free-space points (as the other studies) for `neural` and, as the
yardstick whose error does not depend on any training set, `physical` at the network's 16^3 voxels
and probes. The distance of each room from the training set, two ways (`distance`): how far its drawn
parameters lie outside the trained ranges on the varied axis, in range widths, and how far its network
input lies from the nearest training scene's, in units of the training set's own neighbour distance.
"""

from __future__ import annotations

import colorsys
from dataclasses import dataclass

import numpy as np

from viewer import gi
from viewer.bench.accuracy import relative_rmse
from viewer.bench.points import free_space_points
from viewer.bench.stability.common import RunConfig, StudyResult, try_method
from viewer.bench.stability.distance import outside, scene_encoding, training_distances
from viewer.bench.stability.methods import MethodSettings, truth_sh
from viewer.training.procedural import Ranges, random_scene

TRAINED = Ranges()
METHODS_HERE = ("neural", "physical", "compute")
"""The methods this study runs when asked for (the others are either no yardstick or, like
`mitsuba-probes`, thousands of Mitsuba probes per room)."""
POINTS = 250
DIRECTIONS = 512
SEED = 505


@dataclass(frozen=True)
class Step:
    axis: str
    label: str
    ranges: Ranges
    new: str = ""
    """What the training set never has (a shape, a light placement): no range to be outside of."""


STEPS = (
    Step("room", "half extents 0.45-0.55", Ranges(room_scale=(0.45, 0.55))),
    Step("room", "half extents 1.45-1.6", Ranges(room_scale=(1.45, 1.6))),
    Step("room", "half extents 1.9-2.1", Ranges(room_scale=(1.9, 2.1))),
    Step("room", "elongated 2.0 x 0.8 x 0.8", Ranges(room_scale=((1.9, 0.75, 0.75), (2.1, 0.85, 0.85)))),
    Step("colour", "near-white 0.95-0.99", Ranges(albedo=(0.05, 0.99), grey_level=(0.95, 0.99),
                                                   saturated_wall_probability=0.0, saturated_object_probability=0.0)),
    Step("colour", "dark 0.01-0.04", Ranges(albedo=(0.01, 0.04), grey_level=(0.01, 0.04), value=(0.01, 0.04))),
    Step("colour", "all fully saturated", Ranges(albedo=(0.0, 0.9), saturation=(1.0, 1.0), saturated_wall_probability=1.0,
                                                 saturated_object_probability=1.0)),
    Step("light", "tiny: half 0.005-0.015", Ranges(light_half_extent=(0.005, 0.015))),
    Step("light", "huge: one, half 0.9-1.3", Ranges(light_half_extent=(0.9, 1.3), lights=(1, 1))),
    Step("light", "on the walls only", Ranges(wall_light_probability=1.0)),
    Step("light", "on the floor, facing up", Ranges(floor_light_probability=1.0, objects=(0, 0)), new="floor light"),
    Step("shape", "10-14 small objects", Ranges(objects=(10, 14), object_half_width=(0.08, 0.2))),
    Step("shape", "thin upright slabs", Ranges(object_kinds=("slab",), objects=(2, 4)), new="slab"),
    Step("shape", "floating under the ceiling", Ranges(hang_probability=1.0, objects=(2, 4)), new="floating"),
)
QUICK_STEPS = tuple(STEPS[i] for i in (3, 5, 8, 11))
IN_DISTRIBUTION = Step("in distribution", "training ranges", TRAINED)


def colours(params: dict) -> np.ndarray:
    """(C, 3) every albedo drawn for a room: walls and objects."""
    return np.array(list(params["walls"].values()) + [o["albedo"] for o in params["objects"]])


def range_distance(axis: str, params: dict) -> float:
    """How far the room's drawn parameters on `axis` lie outside the trained ranges, in range widths."""
    if axis == "room":
        return outside(params["room_half"], TRAINED.room_scale)
    if axis == "colour":
        albedo = colours(params)
        saturation = [colorsys.rgb_to_hsv(*c)[1] for c in albedo]
        return max(outside(albedo, TRAINED.albedo), outside(saturation, (0.0, TRAINED.saturation[1])))
    if axis == "light":
        return outside([light["half"] for light in params["lights"]], TRAINED.light_half_extent)
    if axis == "shape":
        return outside(len(params["objects"]), TRAINED.objects)
    return max(range_distance(a, params) for a in ("room", "colour", "light", "shape"))


LIGHTS = (("all", "all light", True), ("indirect", "indirect", False))
"""(suffix, header, include_emitted): the incident light as `sample` and the other studies compare it,
and its reflected part alone, the probes the renderer shades from (it draws emitters and the sun itself)."""


def error_key(method: str, light: str) -> str:
    return f"{method} {light}"


def columns(methods) -> list[tuple[str, str, str]]:
    return ([("axis", "axis", "{}"), ("step", "step", "{}"), ("scene", "scene", "{}"),
             ("outside", "outside the ranges (widths)", "{:.2f}"), ("new", "never trained", "{}"),
             ("statistics", "distance: statistics", "{:.2f}"), ("layout", "distance: layout", "{:.2f}"),
             ("distance", "distance", "{:.2f}")]
            + [(error_key(m, light), f"{m}, {header}", "{:.3f}") for m in methods for light, header, _ in LIGHTS])


def plan(quick: bool) -> list[Step]:
    """The rooms to draw, one Step each: the in-distribution baseline first."""
    per_step, baseline = (1, 2) if quick else (2, 8)
    return [IN_DISTRIBUTION] * baseline + [step for step in (QUICK_STEPS if quick else STEPS) for _ in range(per_step)]


def measure_room(number: int, step: Step, distances: dict, methods, points_count: int, directions: int,
                 result: StudyResult) -> dict:
    """Draw room `number` of the plan, place it against the training set and measure every method."""
    name = f"ood-{step.axis.split()[0]}-{number}"
    scene, params = random_scene(np.random.default_rng([SEED, number]), name, step.ranges)
    inputs = scene_encoding(scene, 16, 16)
    row = dict(axis=step.axis, step=step.label, scene=name, outside=range_distance(step.axis, params),
               new=step.new or "-", **{view: measure(inputs) for view, measure in distances.items()})
    row["distance"] = max(row[view] for view in distances)
    points = free_space_points(scene, points_count, margin=0.06, seed=number)
    for light, _, include_emitted in LIGHTS:
        truth = truth_sh(scene, points, directions, include_emitted=include_emitted)
        settings = MethodSettings(gi.GISettings(voxels=16, probes=16, directions=256), include_emitted=include_emitted)
        for method in methods:
            grid = try_method(method, scene, settings, result)
            row[error_key(method, light)] = np.nan if grid is None else relative_rmse(grid.interpolate(points), truth)
    return row


def run(config: RunConfig) -> StudyResult:
    methods = [m for m in METHODS_HERE if m in config.methods]
    result = StudyResult("ood", columns(methods))
    if "neural" not in methods:
        result.notes.append("Not run: the study measures `neural`, which was not asked for.")
        return result
    try:
        distances = training_distances(resolution=16)
    except FileNotFoundError as exc:
        result.notes.append(f"Not run: no training set to measure distances from ({exc}).")
        return result
    directions = 128 if config.quick else DIRECTIONS
    points_count = 100 if config.quick else POINTS
    rooms = plan(config.quick)
    for number, step in enumerate(rooms):
        row = measure_room(number, step, distances, methods, points_count, directions, result)
        result.rows.append(row)
        print(f"ood {step.axis} / {step.label}: distance {row['distance']:.2f}, "
              + ", ".join(f"{key} {row[key]:.3f}" for key, _, _ in result.columns[8:]), flush=True)
    baseline = sum(step is IN_DISTRIBUTION for step in rooms)
    result.notes.append(
        f"{len(rooms)} rooms ({baseline} in distribution, {(len(rooms) - baseline) // len(set(rooms[baseline:]))} "
        f"per step), seeded; {points_count} free-space points each, Mitsuba {directions} directions per point; "
        "`physical` at 16^3 voxels and 16^3 probes, the network's. Errors: relative RMSE of the SH at the points, "
        "of all the incident light (as the other studies) and of its indirect part (what the renderer shades "
        "from the probes). Outside the ranges: the varied axis's drawn values (room half extents; albedos and "
        "HSV saturations; light half extents; object count) past `Ranges()`, in widths of the range. "
        "Distance: the network input's nearest-neighbour distance to the 112 training scenes in two views, "
        "`statistics` (per-feature mean, spread and 99th percentile over the lattice, albedo percentiles) and "
        "`layout` (features averaged over 4^3 blocks), each in units of the training set's median "
        "neighbour distance (`viewer/bench/stability/distance.py`); `distance` is the larger.")
    summarize(result, methods)
    return result


def rank_correlation(x, y) -> float:
    """Spearman's rank correlation (no ties expected in measured errors)."""
    rx, ry = np.argsort(np.argsort(x)), np.argsort(np.argsort(y))
    return float(np.corrcoef(rx, ry)[0, 1])


def percent(rows, method: str, light: str) -> str:
    """Median error of rows as a percentage: medians, since one lamp next to the points can make a
    room's error several times its neighbours'."""
    return f"{100 * np.nanmedian([r[error_key(method, light)] for r in rows]):.0f}%"


def ratio(rows, yardstick: str, light: str = "indirect") -> float:
    """Median over rooms of `neural`'s error over the yardstick's: what the network adds to how hard the
    room is for any method at 16^3 (a lamp next to the points, a sunlit patch)."""
    return float(np.median([r[error_key("neural", light)] / r[error_key(yardstick, light)] for r in rows]))


def summarize(result: StudyResult, methods) -> None:
    base = [r for r in result.rows if r["axis"] == IN_DISTRIBUTION.axis]
    away = [r for r in result.rows if r["axis"] != IN_DISTRIBUTION.axis]
    if not base or not away:
        return
    key = error_key("neural", "indirect")
    yardstick = next((m for m in methods if m != "neural"), None)

    def errors(rows) -> str:
        return "; ".join(f"`{m}` {percent(rows, m, 'indirect')} ({percent(rows, m, 'all')})" for m in methods)

    result.summary.append(f"Medians, indirect light (all light in brackets). In distribution ({len(base)} rooms, "
                          f"distance {min(r['distance'] for r in base):.1f}-{max(r['distance'] for r in base):.1f}): "
                          + errors(base) + (f"; `neural` / `{yardstick}` per room {ratio(base, yardstick):.1f} "
                                            f"({ratio(base, yardstick, 'all'):.1f})" if yardstick else "") + ".")
    for axis in dict.fromkeys(r["axis"] for r in away):
        steps: dict[str, list] = {}
        for r in away:
            if r["axis"] == axis:
                steps.setdefault(r["step"], []).append(r)
        worst = max((r for r in away if r["axis"] == axis), key=lambda r: r[key])
        parts = [f"{label} (distance {np.median([r['distance'] for r in rows]):.1f}): `neural` {percent(rows, 'neural', 'indirect')}"
                 + (f", {ratio(rows, yardstick):.1f} x `{yardstick}`" if yardstick else "") for label, rows in steps.items()]
        result.summary.append(f"{axis}: " + "; ".join(parts) + f". Worst `neural` room: {worst['step']}, {100 * worst[key]:.0f}%.")
    worst = max(r[key] for r in base)
    broken = sorted((r for r in away if r[key] > worst), key=lambda r: r["distance"])
    result.summary.append(
        f"Past the worst in-distribution `neural` error ({100 * worst:.0f}%, indirect): "
        + (f"{len(broken)} of {len(away)} rooms outside the ranges; the nearest to the training set {broken[0]['axis']} "
           f"({broken[0]['step']}, distance {broken[0]['distance']:.1f}, {100 * broken[0][key]:.0f}%)."
           if broken else f"none of the {len(away)} rooms outside the ranges."))
    distance = [r["distance"] for r in result.rows]
    correlations = [f"`{m}` {rank_correlation(distance, [r[error_key(m, 'indirect')] for r in result.rows]):+.2f}"
                    for m in methods]
    if yardstick:
        correlations.append(f"`neural` / `{yardstick}` {rank_correlation(distance, [r[key] / r[error_key(yardstick, 'indirect')] for r in result.rows]):+.2f}")
    result.summary.append("Rank correlation with the distance, every room, indirect light: " + ", ".join(correlations) + ".")


AXIS_COLOURS = {"in distribution": "k", "room": "C0", "colour": "C3", "light": "C1", "shape": "C2"}


def chart(result: StudyResult, path) -> None:
    """Error against both distances, all light above and the indirect light below; one colour per axis,
    `neural` filled and the yardstick hollow; the grey band: `neural`'s in-distribution errors."""
    import matplotlib.pyplot as plt
    from matplotlib.lines import Line2D
    from matplotlib.ticker import ScalarFormatter

    methods = list(dict.fromkeys(key.split(" ")[0] for key, _, _ in result.columns[8:]))
    yardstick = next((m for m in methods if m != "neural"), None)
    fig, axes = plt.subplots(2, 2, figsize=(12, 8), sharey="row", sharex="col", gridspec_kw=dict(width_ratios=[3, 2]))
    for row_axes, (light, header, _) in zip(axes, LIGHTS):
        base = [r[error_key("neural", light)] for r in result.rows if r["axis"] == IN_DISTRIBUTION.axis]
        for ax, x_key in zip(row_axes, ("distance", "outside")):
            if base:
                ax.axhspan(min(base), max(base), color="0.88", zorder=0)
            for axis, colour in AXIS_COLOURS.items():
                rows = [r for r in result.rows if r["axis"] == axis]
                x = [r[x_key] for r in rows]
                ax.scatter(x, [r[error_key("neural", light)] for r in rows], color=colour, s=30, zorder=3)
                if yardstick:
                    ax.scatter(x, [r[error_key(yardstick, light)] for r in rows], facecolors="none",
                               edgecolors=colour, s=30, zorder=2)
            ax.set_yscale("log")
            ax.grid(alpha=0.3, which="both")
        row_axes[0].set_xscale("log")
        row_axes[0].xaxis.set_major_formatter(ScalarFormatter())
        row_axes[0].set_ylabel(f"relative RMSE vs Mitsuba, {header}")
    axes[1][0].set_xlabel("distance of the network input from the training set\n"
                          "(1: a training scene's typical distance to its nearest other; log scale)")
    axes[1][1].set_xlabel("outside the trained ranges on the varied axis (range widths;\n"
                          "new shapes and floor lights at 0)")
    handles = [Line2D([], [], ls="", marker="s", color=c, label=a) for a, c in AXIS_COLOURS.items()]
    handles += [Line2D([], [], ls="", marker="o", color="0.3", label="neural"),
                Line2D([], [], ls="", marker="o", mfc="none", color="0.3", label=yardstick or "-"),
                plt.Rectangle((0, 0), 1, 1, color="0.88", label="neural in distribution")]
    axes[0][1].legend(handles=handles, fontsize=8, loc="upper left", bbox_to_anchor=(1.02, 1.0))
    fig.suptitle("The neural field out of its training distribution (filled), the physical solver beside it (hollow)",
                 fontsize=11)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)

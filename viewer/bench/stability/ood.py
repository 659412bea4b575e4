"""Out of distribution: the neural field's error against a scene's distance from its training set.

Rooms are drawn with `viewer.evaluation.procedural.random_scene` and the ranges the shipped model was
trained on (its card's domain, viewer.neural.domain) moved one axis at a time, from inside them to well
outside (`steps`): room proportions, colours, lights
(size and placement) and shapes; plus rooms drawn with the training ranges themselves (`in
distribution`: the same generator, seeds the training set never used) as the baseline. Per room:
relative RMSE against Mitsuba at free-space points (as the other studies) for `neural` and, as the
yardstick whose error does not depend on any training set, `solver` at the network's voxels and
probes. The distance of each room from the training set, two ways (`distance`): how far its drawn
parameters lie outside the trained ranges on the varied axis, in range widths, and how far its network
input lies from the nearest training scene's, in units of the training set's own neighbour distance.
"""

from __future__ import annotations

import colorsys
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from viewer.physical import gi
from viewer.evaluation.error import relative_rmse
from viewer.evaluation.points import free_space_points
from viewer.bench.stability.common import RunConfig, StudyResult, neural_study, try_method
from viewer.bench.stability.distance import ROOT, outside, scene_encoding, training_distances
from viewer.bench.stability.methods import MethodSettings
from viewer.evaluation.truth import truth_sh
from viewer.neural.domain import Domain
from viewer.neural.domain import outside as guard
from viewer.evaluation.procedural import PRESETS, Ranges, random_scene

def shipped_card():
    """The shipped model's card (viewer.neural.field.ModelCard), or None without a model."""
    from viewer.neural.field import DEFAULT_MODEL, ModelCard, ModelError

    try:
        return ModelCard.read(DEFAULT_MODEL)
    except ModelError:
        return None


CARD = shipped_card()
DOMAIN = CARD.domain if CARD is not None else Domain.from_preset("v1")
"""What the shipped network was trained on (its card's domain, viewer.neural.domain; v1 without a model)."""
TRAINED = PRESETS[DOMAIN.ranges]
"""The ranges its rooms were drawn from: the steps below move one axis of them at a time."""
VOXELS, PROBES = (CARD.voxels, CARD.probes) if CARD is not None else (16, 16)
"""The network's voxel and probe resolutions (the yardstick runs at them too)."""
METHODS_HERE = ("neural", "solver", "compute")
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
    quick: bool = False
    """One of the `--quick` run's steps."""


def _round(x: float) -> float:
    """To what the labels print (so that the first dataset's steps are exactly the published ones)."""
    return round(x, 2 if x >= 0.1 else 3)


def steps(trained: Ranges) -> tuple[Step, ...]:
    """The study's rooms, one axis of `trained` moved past its bounds at a time (for the first dataset's
    ranges: half extents 0.45-0.55, 1.45-1.6, 1.9-2.1 and 2.0 x 0.8 x 0.8; albedo 0.95-0.99 and
    0.01-0.04; lights of half extent 0.005-0.015 and 0.9-1.3; 10-14 objects). Placements the trained
    ranges already hold (lights on the walls or the floor, for v2) are left out."""
    low, high = trained.room_scale
    dark, white = trained.albedo
    small, large = trained.light_half_extent
    most = trained.objects[1]
    below = (_round(0.6 * low), _round(0.73 * low))
    above = (_round(1.115 * high), _round(1.23 * high))
    far = (_round(1.46 * high), _round(1.615 * high))
    narrow = (low, _round(1.133 * low))
    whiter = _round(min(white + 0.05, 0.97))
    darker = (_round(0.2 * dark), _round(0.8 * dark))
    tiny = (_round(0.1 * small), _round(0.3 * small))
    huge = (_round(1.5 * large), _round(2.17 * large))
    many = (round(2.5 * most), round(3.5 * most))
    rectangles = tuple(s for s in trained.light_surfaces if s != "object")   # lights with a size to vary

    def room(bounds):
        return replace(trained, room_scale=bounds)

    out = [Step("room", f"half extents {below[0]:g}-{below[1]:g}", room(below)),
           Step("room", f"half extents {above[0]:g}-{above[1]:g}", room(above)),
           Step("room", f"half extents {far[0]:g}-{far[1]:g}", room(far)),
           Step("room", f"elongated {sum(far) / 2:.1f} x {sum(narrow) / 2:.1f} x {sum(narrow) / 2:.1f}",
                room(((far[0], narrow[0], narrow[0]), (far[1], narrow[1], narrow[1]))), quick=True),
           Step("colour", f"near-white {whiter:g}-0.99",
                replace(trained, albedo=(dark, 0.99), grey_level=(whiter, 0.99), saturated_wall_probability=0.0,
                        saturated_object_probability=0.0)),
           Step("colour", f"dark {darker[0]:.3g}-{darker[1]:.3g}",
                replace(trained, albedo=darker, grey_level=darker, value=darker), quick=True),
           Step("colour", "all fully saturated",
                replace(trained, albedo=(0.0, white), saturation=(1.0, 1.0), saturated_wall_probability=1.0,
                        saturated_object_probability=1.0)),
           Step("light", f"tiny: half {tiny[0]:.3g}-{tiny[1]:.3g}",
                replace(trained, light_half_extent=tiny, light_surfaces=rectangles)),
           Step("light", f"huge: one, half {huge[0]:.2g}-{huge[1]:.2g}",
                replace(trained, light_half_extent=huge, lights=(1, 1), light_surfaces=rectangles), quick=True)]
    if not trained.light_surfaces:   # the first dataset's rule: a light on a wall one time in five
        out.append(Step("light", "on the walls only", replace(trained, wall_light_probability=1.0)))
    if "floor" not in Domain.from_ranges(trained, "").light_surfaces:
        out.append(Step("light", "on the floor, facing up",
                        replace(trained, floor_light_probability=1.0, objects=(0, 0), light_surfaces=()),
                        new="floor light"))
    return tuple(out) + (
        Step("shape", f"{many[0]}-{many[1]} small objects",
             replace(trained, objects=many, object_half_width=(0.08, 0.2)), quick=True),
        Step("shape", "thin upright slabs", replace(trained, object_kinds=("slab",), objects=(2, 4)), new="slab"),
        Step("shape", "floating under the ceiling", replace(trained, hang_probability=1.0, objects=(2, 4)),
             new="floating"))


STEPS = steps(TRAINED)
QUICK_STEPS = tuple(step for step in STEPS if step.quick)
IN_DISTRIBUTION = Step("in distribution", "training ranges", TRAINED)


def colours(params: dict) -> np.ndarray:
    """(C, 3) every albedo drawn for a room: walls and objects."""
    return np.array(list(params["walls"].values()) + [o["albedo"] for o in params["objects"]])


def range_distance(axis: str, params: dict, trained: Ranges = TRAINED) -> float:
    """How far the room's drawn parameters on `axis` lie outside the trained ranges, in range widths."""
    if axis == "room":
        return outside(params["room_half"], trained.room_scale)
    if axis == "colour":
        albedo = colours(params)
        saturation = [colorsys.rgb_to_hsv(*c)[1] for c in albedo]
        return max(outside(albedo, trained.albedo), outside(saturation, (0.0, trained.saturation[1])))
    if axis == "light":
        return outside([light["half"] for light in params["lights"] if "half" in light], trained.light_half_extent)
    if axis == "shape":
        return outside(len(params["objects"]), trained.objects)
    return max(range_distance(a, params, trained) for a in ("room", "colour", "light", "shape"))


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
            + [(error_key(m, light), f"{m}, {header}", "{:.3f}") for m in methods for light, header, _ in LIGHTS]
            + [("guard", "the viewer's domain guard (viewer.neural.domain)", "{}")])


ERRORS = slice(8, -1)
"""Where the methods' error columns are among `columns`."""


def training_data(card) -> Path:
    """The dataset the shipped model trained on (its card's `training.data`; data/gi-v1 without one)."""
    return ROOT / str((card.data.get("training", {}) if card is not None else {}).get("data", "data/gi-v1"))


def plan(quick: bool) -> list[Step]:
    """The rooms to draw, one Step each: the in-distribution baseline first."""
    per_step, baseline = (1, 2) if quick else (2, 8)
    return [IN_DISTRIBUTION] * baseline + [step for step in (QUICK_STEPS if quick else STEPS) for _ in range(per_step)]


def measure_room(number: int, step: Step, distances: dict, methods, points_count: int, directions: int,
                 result: StudyResult) -> dict:
    """Draw room `number` of the plan, place it against the training set and measure every method."""
    name = f"ood-{step.axis.split()[0]}-{number}"
    scene, params = random_scene(np.random.default_rng([SEED, number]), name, step.ranges)
    inputs = scene_encoding(scene, VOXELS, PROBES)
    row = dict(axis=step.axis, step=step.label, scene=name, outside=range_distance(step.axis, params),
               new=step.new or "-", **{view: measure(inputs) for view, measure in distances.items()})
    row["guard"] = "; ".join(guard(scene, DOMAIN)) or "-"
    row["distance"] = max(row[view] for view in distances)
    points = free_space_points(scene, points_count, margin=0.06, seed=number)
    for light, _, include_emitted in LIGHTS:
        truth = truth_sh(scene, points, directions, include_emitted=include_emitted)
        settings = MethodSettings(gi.GISettings(voxels=VOXELS, probes=PROBES, directions=256),
                                  include_emitted=include_emitted)
        for method in methods:
            grid = try_method(method, scene, settings, result)
            row[error_key(method, light)] = np.nan if grid is None else relative_rmse(grid.interpolate(points), truth)
    return row


def run(config: RunConfig) -> StudyResult:
    methods, result, runs = neural_study("ood", config, METHODS_HERE, columns)
    if not runs:
        return result
    try:
        distances = training_distances(resolution=PROBES, data=training_data(CARD))
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
              + ", ".join(f"{key} {row[key]:.3f}" for key, _, _ in result.columns[ERRORS]), flush=True)
    baseline = sum(step is IN_DISTRIBUTION for step in rooms)
    result.notes.append(
        f"{len(rooms)} rooms ({baseline} in distribution, {(len(rooms) - baseline) // len(set(rooms[baseline:]))} "
        f"per step), seeded; {points_count} free-space points each, Mitsuba {directions} directions per point; "
        f"`solver` at {VOXELS}^3 voxels and {PROBES}^3 probes, the network's. Errors: relative RMSE of the SH at "
        "the points, of all the incident light (as the other studies) and of its indirect part (what the renderer "
        "shades from the probes). Outside the ranges: the varied axis's drawn values (room half extents; albedos "
        f"and HSV saturations; light half extents; object count) past the ranges `{DOMAIN.ranges}` the shipped "
        "model's card names (its domain), in widths of the range. The guard: the reasons the viewer gives for "
        "the room (viewer.neural.domain, from the card's domain). "
        f"Distance: the network input's nearest-neighbour distance to the {distances['statistics'].count} "
        "training scenes in two views, "
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
    room is for any method at the network's resolution (a lamp next to the points, a sunlit patch)."""
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
    guarded = [r for r in away if r.get("guard", "-") != "-"]
    result.summary.append(
        f"The viewer's domain guard names a reason for {len(guarded)} of the {len(away)} rooms outside the ranges, "
        f"{sum(r.get('guard', '-') != '-' for r in base)} of the {len(base)} in distribution, and "
        f"{sum(r.get('guard', '-') != '-' for r in broken)} of the {len(broken)} past the worst in-distribution error.")
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

    methods = list(dict.fromkeys(key.split(" ")[0] for key, _, _ in result.columns[ERRORS]))
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

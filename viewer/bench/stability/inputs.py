"""Where the network's inputs fail: the rooms that each input of the neural encoding finds hardest, the
network against the solver on the same lattice, both against Mitsuba.

The encoding's direct light is traced per lattice cell, its bounces are read from the voxels and
gathered by SEEN_RAYS rays a probe (viewer/neural/encoding.py). Each case below stresses one of them, drawn
from the v2 generator at the end of its ranges (two rooms each, seeded), plus one room built by hand:

- thin walls: two partitions 0.02 thick in every room; and `two-rooms-door`, two rooms split by a wall
  0.02 thick with a doorway far from the lamp, where the dark room's light is the number to watch
  (its ratio to Mitsuba's: 1 is right);
- small windows: a window 0.2-0.3 across with the sun through it (a small bright patch on the floor,
  finer than the lattice);
- glowing objects: the only lights are objects that glow all over;
- near-black walls: every surface 0.01-0.03;
- near-white walls: every surface 0.9-0.95.

Per room: relative RMSE of the SH at free-space points against Mitsuba, of all the incident light and of
its indirect part (what the renderer shades from the probes), and the ratio of the predicted indirect
light to the true one (mean DC over the points).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from viewer.bench.stability import scenes
from viewer.bench.stability.common import RunConfig, StudyResult, neural_study, try_method
from viewer.bench.stability.methods import MethodSettings
from viewer.evaluation.error import relative_rmse
from viewer.evaluation.points import free_space_points
from viewer.evaluation.procedural import random_scene
from viewer.evaluation.truth import truth_sh
from viewer.neural.ranges import V2
from viewer.physical import gi

SEED = 2727
POINTS = 250
DIRECTIONS = 512
PROBES = VOXELS = 24
"""The shipped network's lattice and voxels; the solver runs on the same."""
METHODS_HERE = ("neural", "solver")


@dataclass(frozen=True)
class Case:
    name: str
    about: str
    ranges: object | None
    """v2 ranges at the end of one axis, or None for the hand-built `two-rooms-door`."""


DARK, WHITE = (0.01, 0.03), (0.9, 0.95)
CASES = (
    Case("thin walls", "two partitions 0.02 thick", replace(V2, partitions=(2, 2), partition_thickness=(0.02, 0.02))),
    Case("thin wall, doorway", "two rooms, a wall 0.02 thick, a doorway far from the lamp", None),
    Case("small window", "the sun through a window 0.2-0.3 across",
         replace(V2, window_probability=1.0, window_half_extent=(0.1, 0.15))),
    Case("glowing objects", "the only lights glow all over objects",
         replace(V2, light_surfaces=("object",), lights=(1, 2), objects=(3, 6))),
    Case("near-black walls", "every surface 0.01-0.03",
         replace(V2, albedo=DARK, grey_level=DARK, value=DARK, saturated_wall_probability=0.0,
                 saturated_object_probability=0.0)),
    Case("near-white walls", "every surface 0.9-0.95",
         replace(V2, albedo=WHITE, grey_level=WHITE, value=WHITE, saturated_wall_probability=0.0,
                 saturated_object_probability=0.0)),
)
LIGHTS = (("all", True), ("indirect", False))


def columns(methods) -> list[tuple[str, str, str]]:
    return ([("case", "case", "{}"), ("scene", "scene", "{}")]
            + [(f"{m} {light}", f"{m}, {light} light", "{:.3f}") for m in methods for light, _ in LIGHTS]
            + [(f"{m} ratio", f"{m}, indirect / truth", "{:.2f}") for m in methods]
            + [(f"{m} dark room", f"{m}, dark room / truth", "{:.2f}") for m in methods])


def case_scenes(case: Case, rooms: int, first: int) -> list:
    if case.ranges is None:
        return [scenes.two_rooms(door=True)]
    return [random_scene(np.random.default_rng([SEED, first + i]), f"inputs-{first + i}", case.ranges)[0]
            for i in range(rooms)]


def mean_dc(sh: np.ndarray) -> float:
    return float(np.mean(sh[:, 0]))


def measure(case: Case, scene, number: int, methods, points_count: int, directions: int,
            result: StudyResult) -> dict:
    row = dict(case=case.name, scene="two-rooms-door" if case.ranges is None else scene.name)
    points = free_space_points(scene, points_count, margin=0.06, seed=number)
    dark = scenes.in_dark_room(points) if case.ranges is None else None
    for light, include_emitted in LIGHTS:
        truth = truth_sh(scene, points, directions, include_emitted=include_emitted)
        settings = MethodSettings(gi.GISettings(voxels=VOXELS, probes=PROBES, directions=256),
                                  include_emitted=include_emitted)
        for method in methods:
            grid = try_method(method, scene, settings, result)
            found = None if grid is None else grid.interpolate(points)
            row[f"{method} {light}"] = np.nan if found is None else relative_rmse(found, truth)
            if light != "indirect":
                continue
            row[f"{method} ratio"] = np.nan if found is None else mean_dc(found) / max(mean_dc(truth), 1e-30)
            row[f"{method} dark room"] = (np.nan if found is None or dark is None else
                                          mean_dc(found[dark]) / max(mean_dc(truth[dark]), 1e-30))
    return row


def run(config: RunConfig) -> StudyResult:
    methods, result, runs = neural_study("inputs", config, METHODS_HERE, columns)
    if not runs:
        return result
    rooms = 1 if config.quick else 2
    directions = 128 if config.quick else DIRECTIONS
    points_count = 100 if config.quick else POINTS
    number = 0
    for case in CASES:
        for scene in case_scenes(case, rooms, number):
            row = measure(case, scene, number, methods, points_count, directions, result)
            number += 1
            result.rows.append(row)
            print(f"inputs {case.name} / {scene.name}: " + ", ".join(
                f"{key} {row[key]:.3f}" for key, _, _ in result.columns[2:] if not np.isnan(row[key])), flush=True)
    result.notes.append(
        f"Rooms of the v2 generator at the end of one axis ({rooms} a case, seeds [{SEED}, n]) and the "
        f"leaking study's `two-rooms-door`; {points_count} free-space points each, Mitsuba {directions} "
        f"directions a point; `solver` at {VOXELS}^3 voxels and {PROBES}^3 probes, the network's. Cases: "
        + "; ".join(f"{c.name}: {c.about}" for c in CASES) + ".")
    summarize(result, methods)
    return result


def summarize(result: StudyResult, methods) -> None:
    for case in dict.fromkeys(r["case"] for r in result.rows):
        rows = [r for r in result.rows if r["case"] == case]
        parts = []
        for m in methods:
            part = (f"`{m}` indirect {100 * np.median([r[f'{m} indirect'] for r in rows]):.0f}% "
                    f"(x{np.median([r[f'{m} ratio'] for r in rows]):.2f} of the truth), "
                    f"all {100 * np.median([r[f'{m} all'] for r in rows]):.0f}%")
            dark = [r[f"{m} dark room"] for r in rows if not np.isnan(r[f"{m} dark room"])]
            if dark:
                part += f", dark room x{np.median(dark):.2f}"
            parts.append(part)
        result.summary.append(f"{case} (medians): " + "; ".join(parts) + ".")


def chart(result: StudyResult, path) -> None:
    import matplotlib.pyplot as plt

    from viewer.bench.stability.common import style

    methods = [key.split(" ")[0] for key, _, _ in result.columns if key.endswith(" indirect")]
    labels = [f"{r['case']}\n{r['scene']}" for r in result.rows]
    x = np.arange(len(result.rows))
    fig, ax = plt.subplots(figsize=(max(8, 0.8 * len(x)), 4.5))
    width = 0.8 / max(len(methods), 1)
    for i, m in enumerate(methods):
        ax.bar(x + (i - (len(methods) - 1) / 2) * width, [100 * r[f"{m} indirect"] for r in result.rows], width,
               label=m, color=style(m).get("color"))
    ax.set_xticks(x, labels, rotation=60, ha="right", fontsize=7)
    ax.set_ylabel("indirect light, relative RMSE against Mitsuba (%)")
    ax.set_title("Where the network's inputs fail")
    ax.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)

"""The neural source's time against the physical solver's, edit by edit on the same scene: the neural
source's speed bar (a new scene or a moved object in at most a third of the solver's time).

    python -m viewer.bench.share [SCENE ...] [--rooms N] [--move GROUP] [--repeats 5] [--threads N]

For each scene: the largest group's albedo, the brightest lamp moved by a tenth of the scene, a group
moved as far (`--move`; by default the non-emitting group of the most triangles, the smaller by area
where two tie: a box room's small box, a scan room's scan) and a new scene (each source made afresh).
An edit flips the scene to the edited one and back, every update timed from the edit to the probes:
`NeuralGI.update` (voxelizing, every ray and the network included) against `PhysicalGI.update` and its
`probe_grid`, the two in turn, so that both meet the machine's same moments. Medians of `repeats`
updates (four times as many for the albedo), wall-clock milliseconds on all the cores, the share the
neural source's time is of the solver's. The network runs on one thread unless `--threads` (the
viewer's: viewer.ui.neural_source.NETWORK_THREADS). `--rooms N` adds the training generator's first N
validation rooms (`viewer.training.evaluate`'s, before the dataset rounds them to its file's
precisions): rooms of one to three lamps, some large, some with the sun through a window.
"""

from __future__ import annotations

import os
import statistics
import time
from pathlib import Path

import numpy as np

from viewer import scene as scenes
from viewer.bench.edit_methods import Edit, moved_a_tenth
from viewer.cli_parsing import add_repeats, tool_parser
from viewer.evaluation import procedural
from viewer.neural.field import DEFAULT_MODEL, ModelError, NeuralField, NeuralGI
from viewer.neural.ranges import PRESETS
from viewer.physical.gi import GISettings, PhysicalGI
from viewer.scene import Scene, SceneError
from viewer.ui.scene_edits import emitter_group, largest_object

VALIDATION_SEED, VALIDATION_SPLIT = 14, 1
"""The dataset's seed and the validation split's number in each room's generator seed."""


def moved_group(scene: Scene) -> str | None:
    """The non-emitting group with the most triangles (the smaller by area of a tie): what a user drags
    (viewer.ui.scene_edits.largest_object)."""
    return largest_object(scene)


def edits(scene: Scene, group: str | None) -> dict[str, Scene]:
    """The edits timed, each against `scene` (the new scene is timed apart)."""
    settings = GISettings()
    out = {"albedo": Edit(settings, "colour").edited(scene)}
    if emitter_group(scene) is not None:
        out["lamp moved"] = Edit(settings, "lamp").edited(scene)
    if group is not None:
        out[f"{group} moved"] = moved_a_tenth(scene, group)
    return out


def validation_room(index: int) -> Scene:
    """The training generator's validation room `index` (seed 14, v2 ranges: `viewer.training.dataset.
    make_scene("val", index, 14, "v2")`, unrounded)."""
    rng = np.random.default_rng([VALIDATION_SEED, VALIDATION_SPLIT, index])
    return procedural.random_scene(rng, f"val-{index:05d}", PRESETS["v2"])[0]


def _ms(function) -> float:
    clock = time.perf_counter()
    function()
    return 1000 * (time.perf_counter() - clock)


def _solve(solver: PhysicalGI, scene: Scene) -> None:
    solver.update(scene)
    solver.probe_grid(include_emitted=False)


def measure(scene: Scene, field: NeuralField, group: str | None, repeats: int) -> dict[str, tuple[float, float]]:
    """{edit: (neural ms, solver ms)}: medians, the two sources in turn."""
    rows = {}
    for what, edited in edits(scene, group).items():
        field.forget()
        neural, solver = NeuralGI(field), PhysicalGI(GISettings())
        neural.update(scene)
        _solve(solver, scene)
        times: tuple[list, list] = ([], [])
        flip = [scene, edited]
        for _ in range(4 * repeats if what == "albedo" else repeats):
            flip.reverse()
            times[0].append(_ms(lambda: neural.update(flip[0])))
            times[1].append(_ms(lambda: _solve(solver, flip[0])))
        rows[what] = (statistics.median(times[0]), statistics.median(times[1]))
    times = ([], [])
    for _ in range(repeats):
        field.forget()
        times[0].append(_ms(lambda: NeuralGI(field).update(scene)))
        times[1].append(_ms(lambda: _solve(PhysicalGI(GISettings()), scene)))
    rows["new scene"] = (statistics.median(times[0]), statistics.median(times[1]))
    return rows


def table(results: dict[str, dict[str, tuple[float, float]]]) -> list[str]:
    lines = ["| scene | edit | neural ms | solver ms | share |", "| --- | --- | --- | --- | --- |"]
    for name, rows in results.items():
        lines += [f"| {name} | {what} | {a:.0f} | {b:.0f} | {a / b:.2f} |" for what, (a, b) in rows.items()]
    return lines


def main(argv: list[str] | None = None) -> int:
    parser = tool_parser(__doc__, prog="python -m viewer.bench.share")
    parser.add_argument("scenes", nargs="*", default=None, help="scene files or built-in names (default: cornell, "
                        "unless --rooms)")
    parser.add_argument("--rooms", type=int, default=0, metavar="N",
                        help="also the training generator's first N validation rooms")
    parser.add_argument("--move", help="the group moved (default: the non-emitting group of the most triangles)")
    parser.add_argument("--threads", type=int, default=1, help="onnxruntime's threads (the viewer's: up to 4)")
    parser.add_argument("--model", type=Path, default=DEFAULT_MODEL,
                        help="the network (.onnx with its card; the seen rays it casts are the card's)")
    add_repeats(parser, 5)
    args = parser.parse_args(argv)
    if args.rooms < 0:
        parser.error(f"--rooms must be 0 or more, not {args.rooms}")
    names = args.scenes if args.scenes or args.rooms else ["cornell"]
    try:
        field = NeuralField(args.model, threads=args.threads)
    except ModelError as exc:
        parser.error(str(exc))
    results = {}
    for name in [*names, *range(args.rooms)]:
        try:
            scene = validation_room(name) if isinstance(name, int) else scenes.load(name)
        except SceneError as exc:
            parser.error(str(exc))
        if args.move is not None and args.move not in scene.groups:
            parser.error(f"{name} has no group {args.move!r} (its groups: {', '.join(scene.groups)})")
        group = args.move if args.move is not None else moved_group(scene)
        measure(scene, field, group, 1)   # compile and warm up first
        results[scene.name] = measure(scene, field, group, args.repeats)
        print("\n".join(table({scene.name: results[scene.name]})[2:]), flush=True)
    command = " ".join(names + (["--rooms", str(args.rooms)] if args.rooms else [])
                       + (["--model", str(args.model)] if args.model != DEFAULT_MODEL else []))
    print("\n".join(["", *table(results), "",
                     f"`python -m viewer.bench.share {command} --threads {args.threads} --repeats "
                     f"{args.repeats}`, {time.strftime('%Y-%m-%d')}, 1-minute load average {os.getloadavg()[0]:.1f} "
                     f"on {os.cpu_count()} cores."]))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

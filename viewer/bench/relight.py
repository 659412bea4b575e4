"""Time from an edit to converged GI, stage by stage: the number every change to the physical GI is judged by.

    python -m viewer.bench.relight [SCENE ...] [--repeats 5] [--write]

For each scene at the product defaults (32^3 voxels, 24^3 probes): a new scene (voxelize, the geometry
stage, the lamp and sun paths, the relight, the probes), a colour edit (the relight and the probes), a
lamp move (the lamp paths on the traced geometry, then the relight) and a lamp move traced exactly (the
whole geometry again), on the CPU relight and on the compute-shader relight; medians of `repeats` runs,
wall-clock and CPU milliseconds, with the machine's load. Also the tracer against the numpy ray march it
replaced (rays per second on the same probe rays), which is what numba has to earn its place with.
`--write` puts the tables into docs/PERFORMANCE.md.
"""

from __future__ import annotations

import os
import statistics
import time
from pathlib import Path

import numpy as np

from viewer.rays import dda
from viewer.physical import gi
from viewer.probes import sh
from viewer import scene as scenes
from viewer.evaluation.report import replace_block
from viewer.probes.grid import ProbeGrid

ROOT = Path(__file__).resolve().parents[2]
MARKER = "<!-- bench-relight -->"


def _edits(scene):
    """(a colour edit, the lamp moved by a tenth of the scene), as viewer.bench.edit_methods times them."""
    from viewer.bench.edit_methods import Edit

    settings = gi.GISettings()
    return Edit(settings, "colour").edited(scene), Edit(settings, "lamp").edited(scene)


def _timed(function, repeats: int) -> tuple[float, float]:
    """Median wall and CPU milliseconds of `function()`."""
    wall, cpu = [], []
    for _ in range(repeats):
        clock, cpu_clock = time.perf_counter(), time.process_time()
        function()
        wall.append(time.perf_counter() - clock)
        cpu.append(time.process_time() - cpu_clock)
    return 1000 * statistics.median(wall), 1000 * statistics.median(cpu)


def measure_scene(scene, relighter_factory, repeats: int) -> dict[str, tuple[float, float]]:
    colour, lamp = _edits(scene)

    def new_scene():
        solver = gi.PhysicalGI(gi.GISettings(), relighter_factory())
        solver.update(scene)
        solver.probe_grid(include_emitted=False)

    solver = gi.PhysicalGI(gi.GISettings(), relighter_factory())
    solver.update(scene)
    flip = [scene, colour]

    def colour_edit():
        flip.reverse()
        solver.update(flip[0])
        solver.probe_grid(include_emitted=False)

    moves = [scene, lamp]

    def lamp_move():
        moves.reverse()
        solver.update(moves[0], stale_geometry=True)
        solver.probe_grid(include_emitted=False)

    def lamp_exact():
        moves.reverse()
        solver.update(moves[0])
        solver.probe_grid(include_emitted=False)

    return {"new scene": _timed(new_scene, repeats), "colour edit": _timed(colour_edit, repeats),
            "lamp move": _timed(lamp_move, repeats), "lamp move, traced exactly": _timed(lamp_exact, repeats)}


def tracer_speed(scene, repeats: int) -> dict[str, float]:
    """Million rays per second, the probe rays of the defaults: the numba DDA (all cores, and one) and
    the numpy ray march it replaced (viewer.rays.raymarch.Tracer, on a tenth of the rays)."""
    import numba

    from viewer.rays.raymarch import Tracer
    from viewer.rays.voxels import voxelize_with_faces

    voxelization = voxelize_with_faces(scene, 32)
    cells = dda.Cells.of(voxelization, scene)
    points = ProbeGrid.positions_for(*scene.bounds, 24).reshape(-1, 3)
    directions, _ = sh.sphere_directions(256)
    rays = len(points) * len(directions)
    out = {}
    threads = numba.get_num_threads()
    for count in (threads, 1):
        numba.set_num_threads(count)
        ms, _ = _timed(lambda: dda.bundle_hits(cells, points, directions), repeats)
        out[f"numba DDA, {count} thread{'s' if count > 1 else ''}"] = rays / ms / 1000
    numba.set_num_threads(threads)
    tracer = Tracer.build(voxelization.grid)
    few = points[::10]
    ms, _ = _timed(lambda: tracer.first_hits(np.repeat(few, len(directions), 0), np.tile(directions, (len(few), 1))),
                   max(1, repeats // 2))
    out["numpy ray march (before)"] = len(few) * len(directions) / ms / 1000
    return out


def main(argv=None) -> int:
    from viewer.cli_parsing import add_repeats, add_scenes, add_write, tool_parser

    parser = tool_parser(__doc__)
    add_scenes(parser)
    add_repeats(parser, 5)
    add_write(parser, "write the tables into docs/PERFORMANCE.md")
    args = parser.parse_args(argv)
    from viewer.physical import relight
    from viewer.gpu.compute_relight import ComputeRelight
    from viewer.gpu.context import create_context

    ctx = create_context()
    backends = {"CPU relight": lambda: relight, "compute relight": lambda: ComputeRelight(ctx)}
    lines = ["| scene | relight on | stage | ms (median) | CPU ms |", "|---|---|---|---|---|"]
    for name in args.scenes:
        scene = scenes.load(name)
        for backend, factory in backends.items():
            measure_scene(scene, factory, 1)             # compile and cache first
            for what, (ms, cpu) in measure_scene(scene, factory, args.repeats).items():
                lines.append(f"| {scene.name} | {backend} | {what} | {ms:.0f} | {cpu:.0f} |")
                print(lines[-1], flush=True)
    speed = tracer_speed(scenes.load(args.scenes[0]), args.repeats)
    lines += ["", f"Tracing the default probe rays of {args.scenes[0]} (24^3 probes x 256 directions), million "
              "rays per second:", ""]
    lines += [f"- {what}: {rate:.2f}" for what, rate in speed.items()]
    load = os.getloadavg()[0]
    lines += ["", f"`python -m viewer.bench.relight {' '.join(args.scenes)}`, {args.repeats} runs each, "
              f"{time.strftime('%Y-%m-%d')}, 1-minute load average {load:.1f} on {os.cpu_count()} cores."]
    print("\n".join(lines[-(len(speed) + 4):]))
    if args.write:
        replace_block(ROOT / "docs" / "PERFORMANCE.md", MARKER, "\n".join(lines), "# Performance")
    ctx.release()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

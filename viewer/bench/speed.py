"""Seconds per stage of the numpy solver: voxelize, direct light, transition matrix, bounces, probes.

    python -m viewer.bench.speed [--scene cornell] [--voxels 16 32] [--repeats 3]

Prints the median of the repeats per stage and writes docs/PERFORMANCE.md's solver table.
"""

from __future__ import annotations

import platform
import time
from pathlib import Path

import numpy as np

from viewer.physical import projection
from viewer.physical import transport
from viewer import scene as scenes
from viewer.evaluation.report import replace_block
from viewer.physical.gi import GISettings
from viewer.rays.raymarch import Tracer
from viewer.rays.voxels import voxelize

ROOT = Path(__file__).resolve().parents[2]
STAGES = ("voxelize", "direct light", "transition matrix", "bounces", "probe projection", "total")


def one_run(scene, n: int, m: int) -> dict[str, float]:
    times = {}
    clock = time.perf_counter()

    def lap(name):
        nonlocal clock
        now = time.perf_counter()
        times[name] = now - clock
        clock = now

    grid = voxelize(scene, n)
    tracer = Tracer.build(grid)
    lap("voxelize")
    transport.direct_irradiance(grid, tracer)
    transport.sun_irradiance(grid, scene.sun, tracer)
    lap("direct light")
    g = transport.transition_matrix(grid, "physical", tracer)
    lap("transition matrix")
    light = transport.solve(grid, scene.sun, transition=g, tracer=tracer)
    # solve() recomputes the direct light; count only its bounces here
    lap("bounces")
    times["bounces"] = max(times["bounces"] - times["direct light"], 0.0)
    projection.project(grid, light, scene.sun, scene.bounds, projection.ProbeSettings(resolution=m), tracer)
    lap("probe projection")
    times["total"] = sum(times[s] for s in STAGES[:-1])
    return times


def main(argv=None):
    from viewer.cli_parsing import add_out, add_repeats, tool_parser

    parser = tool_parser(__doc__)
    parser.add_argument("--scene", default="cornell")
    parser.add_argument("--voxels", type=int, nargs="+", default=[16, 32])
    parser.add_argument("--probes", type=int, default=GISettings().probes)
    add_repeats(parser, 3)
    add_out(parser, str(ROOT / "docs" / "PERFORMANCE.md"), type=str)
    args = parser.parse_args(argv)
    scene = scenes.load(args.scene)
    table = []
    for n in args.voxels:
        runs = [one_run(scene, n, args.probes) for _ in range(args.repeats)]
        median = {s: float(np.median([r[s] for r in runs])) for s in STAGES}
        table.append((n, median))
        print(f"N={n}: " + ", ".join(f"{s} {median[s]:.2f}s" for s in STAGES), flush=True)
    lines = ["| voxels N | " + " | ".join(STAGES) + " |", "|---|" + "---|" * len(STAGES)]
    lines += [f"| {n} | " + " | ".join(f"{m[s]:.2f}" for s in STAGES) + " |" for n, m in table]
    block = "\n".join(lines)
    header = (f"Numpy solver on `{args.scene}`, {args.probes}^3 probes, median of {args.repeats} runs, seconds, "
              f"on {platform.machine()} with 2 cores.\n\nRegenerate: `.venv/bin/python -m viewer.bench.speed "
              f"--voxels {' '.join(map(str, args.voxels))} --repeats {args.repeats}`\n\n")
    replace_block(Path(args.out), "<!-- solver-speed -->", header + block, "# Performance\n\n## Numpy solver")


if __name__ == "__main__":
    main()

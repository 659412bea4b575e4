"""Milliseconds of the compute-shader solver: per bounce, to the first picture and to convergence.

    python -m viewer.bench.compute_speed [--scene cornell] [--voxels 16 32 64] [--kernels physical paper]
                                         [--repeats 3] [--large-repeats 1] [--out docs/PERFORMANCE_COMPUTE.md]

Every pass is timed with glFinish after it (the solver does this itself, ComputeSolver.seconds); each
size runs `--repeats` times (`--large-repeats` from 64^3 voxels on, where one run takes minutes on
llvmpipe) and the table gives medians. Programs are compiled once before timing. Prints the table and
writes it as Markdown.
"""

from __future__ import annotations

import os
import platform
import time
from pathlib import Path

import numpy as np

from viewer import scene as scenes
from viewer.physical.gi import GISettings
from viewer.gpu.compute_solver import ComputeSettings, ComputeSolver
from viewer.gpu.context import create_context, describe
from viewer.gpu.programs import ProgramLibrary
from viewer.rays.voxels import voxelize

ROOT = Path(__file__).resolve().parents[2]
COLUMNS = ("voxels", "kernel", "K", "bitset MiB", "first light ms", "visibility ms", "ms / bounce",
           "bounces", "probe update ms", "converged ms")


def one_run(ctx, programs, grid, scene, settings: GISettings) -> dict[str, float]:
    clock = time.perf_counter()
    solver = ComputeSolver(ctx, grid, scene.sun, settings, scene.bounds, programs=programs)
    setup = time.perf_counter() - clock
    solver.run()
    total = time.perf_counter() - clock
    s = solver.seconds
    probe_update = float(np.median(solver.update_seconds))
    result = {
        "setup": setup,
        # direct light, the probes' rays and emitted light, and the first projection: what the viewer
        # shows before the first bounce through the transition
        "first light": setup + sum(s.get(k, 0.0) for k in ("direct light", "probe rays", "emitted light"))
                       + probe_update,
        "visibility": s.get("cluster visibility", 0.0) + s.get("visibility", 0.0),
        "bounce": float(np.median(solver.bounce_seconds)) if solver.bounce_seconds else 0.0,
        "bounces": solver.bounces,
        "probe update": probe_update,
        "converged": total,
        "bitset": solver.visibility_bytes / 2 ** 20,
    }
    solver.release()
    return result


def measure(ctx, programs, scene, n: int, kernel: str, probes: int, repeats: int) -> dict:
    grid = voxelize(scene, n)
    settings = GISettings(voxels=n, probes=probes, kernel=kernel)
    ComputeSolver(ctx, grid, scene.sun, settings, scene.bounds, programs=programs).release()  # compile
    runs = [one_run(ctx, programs, grid, scene, settings) for _ in range(repeats)]
    median = {key: float(np.median([r[key] for r in runs])) for key in runs[0]}
    return {"voxels": f"{n}^3", "kernel": kernel, "K": grid.count, "bitset MiB": f"{median['bitset']:.1f}",
            "first light ms": f"{1000 * median['first light']:.0f}",
            "visibility ms": f"{1000 * median['visibility']:.0f}",
            "ms / bounce": f"{1000 * median['bounce']:.0f}", "bounces": f"{median['bounces']:.0f}",
            "probe update ms": f"{1000 * median['probe update']:.0f}",
            "converged ms": f"{1000 * median['converged']:.0f}", "repeats": repeats}


def visibility_choice(ctx, programs, scene, n: int, probes: int) -> dict[str, float]:
    """Milliseconds of the physical kernel's two ways to V_ij at n^3: the bitset (traced once, then
    read by every bounce) against tracing every pair again in every bounce. Two bounces each."""
    grid = voxelize(scene, n)
    settings = GISettings(voxels=n, probes=probes, bounces=3)
    out = {}
    for mode in ("bitset", "on-the-fly"):
        solver = ComputeSolver(ctx, grid, scene.sun, settings, scene.bounds, ComputeSettings(visibility=mode),
                               programs=programs).run()
        out[f"{mode} table"] = 1000 * (solver.seconds.get("visibility", 0.0) + solver.seconds.get("cluster visibility", 0.0))
        out[f"{mode} bounce"] = 1000 * float(np.median(solver.bounce_seconds))
        solver.release()
    return out


def table(rows: list[dict]) -> str:
    lines = ["| " + " | ".join(COLUMNS) + " |", "|" + "---|" * len(COLUMNS)]
    lines += ["| " + " | ".join(str(row[c]) for c in COLUMNS) + " |" for row in rows]
    return "\n".join(lines)


def main(argv=None):
    from viewer.cli_parsing import add_out, add_repeats, tool_parser

    parser = tool_parser(__doc__)
    parser.add_argument("--scene", default="cornell")
    parser.add_argument("--voxels", type=int, nargs="+", default=[16, 32, 64])
    parser.add_argument("--kernels", nargs="+", default=["physical", "paper"], choices=("physical", "paper"))
    parser.add_argument("--probes", type=int, default=GISettings().probes)
    add_repeats(parser, 3)
    parser.add_argument("--large-repeats", type=int, default=1, help="repeats from 64^3 voxels on")
    add_out(parser, str(ROOT / "docs" / "PERFORMANCE_COMPUTE.md"), type=str)
    args = parser.parse_args(argv)

    ctx = create_context()
    programs = ProgramLibrary(ctx)
    scene = scenes.load(args.scene)
    rows, loads = [], []
    for n in args.voxels:
        for kernel in args.kernels:
            repeats = args.large_repeats if n >= 64 else args.repeats
            rows.append(measure(ctx, programs, scene, n, kernel, args.probes, repeats))
            loads.append(os.getloadavg()[0])
            print(" | ".join(f"{c} {rows[-1][c]}" for c in COLUMNS), flush=True)
    text = table(rows)
    print(text)
    n = min(args.voxels)
    choice = visibility_choice(ctx, programs, scene, n, args.probes)
    loads.append(os.getloadavg()[0])
    choice_text = (f"At {n}^3 voxels the bitset takes {choice['bitset table']:.0f} ms to trace once, then "
                   f"{choice['bitset bounce']:.0f} ms per bounce; tracing V_ij again in every bounce takes "
                   f"{choice['on-the-fly bounce']:.0f} ms per bounce.")
    print(choice_text)
    machine = (f"{describe(ctx)}; {os.cpu_count()} CPUs ({platform.machine()}), shared: load average "
               f"{min(loads):.1f}-{max(loads):.1f} during the runs")
    doc = f"""# Compute-shader solver speed

`python -m viewer.bench.compute_speed` on the `{args.scene}` scene, {args.probes}^3 probes x
{GISettings().directions} directions, both kernels, default tolerance; {machine}. Medians of
{args.repeats} runs ({args.large_repeats} from 64^3 voxels on); every pass glFinish-timed.

{text}

- **K**: voxels (one per cell and facing). **bitset MiB**: the physical kernel's table of facing and
  visible pairs (upper triangle of a symmetric K x K bit matrix).
- **first light**: upload, direct light, the probes' first hits and emitted light, and the first
  projection: the viewer shows direct-lit surfaces' reflected light from here on.
- **visibility**: tracing the bitset once per scene (at 32^3 and above far pairs take their clusters'
  visibility, as the numpy solver does); kept across light changes.
- **ms / bounce**: one pass over all receivers and senders (eq. 30); median over the run's bounces.
- **probe update**: projecting the reflected light onto the probes and writing the seven RGBA16F 3D
  textures. While the viewer steps the solver, it updates them after a bounce once the bounces since
  the last update took as long as an update (ComputeSettings.probe_update_share).
- **converged**: from a new scene to the last bounce and one probe update (tolerance 1e-4, as the
  numpy solver), blocking (`ComputeSolver.run`); stepping adds the intermediate probe updates.

Visibility, bitset or on the fly: {choice_text} The bitset pays for itself from the second bounce on,
so it is the default wherever it fits one shader storage block (128 MiB on llvmpipe: up to about 46k
voxels); `ComputeSettings(visibility="on-the-fly")` remains for larger grids.
"""
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(doc)
    print(f"wrote {out}")


if __name__ == "__main__":
    main()

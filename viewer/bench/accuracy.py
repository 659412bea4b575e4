"""Accuracy of the numpy solver against Mitsuba 3: relative RMSE of `sample --method solver` at
free-space points, for both kernels and a few voxel and probe resolutions.

    python -m viewer.bench.accuracy [--quick] [--out docs/ACCURACY.md]
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from viewer.physical import gi
from viewer.reference import mitsuba as reference
from viewer import scene as scenes
from viewer.evaluation.points import free_space_points
from viewer.evaluation.error import benchmark_scenes, relative_rmse
from viewer.evaluation.report import replace_block

ROOT = Path(__file__).resolve().parents[2]


def evaluate(scene, settings: gi.GISettings, points: np.ndarray, truth: np.ndarray) -> tuple[float, float]:
    start = time.perf_counter()
    grid = gi.solve(scene, settings)
    seconds = time.perf_counter() - start
    return relative_rmse(grid.interpolate(points), truth), seconds


def main(argv=None):
    from viewer.cli_parsing import add_out, tool_parser

    parser = tool_parser(__doc__)
    parser.add_argument("--quick", action="store_true", help="one configuration per scene")
    parser.add_argument("--points", type=int, default=500)
    parser.add_argument("--config", action="append", metavar="KERNEL:N:M",
                        help="only these configurations, e.g. physical:32:24 (repeatable)")
    add_out(parser, str(ROOT / "docs" / "ACCURACY.md"), type=str)
    args = parser.parse_args(argv)
    sources = benchmark_scenes()
    configs = [("physical", 32, 24)] if args.quick else [
        ("physical", 16, 16), ("physical", 32, 16), ("physical", 32, 24), ("paper", 32, 24)]
    if args.config:
        configs = [(k, int(n), int(m)) for k, n, m in (c.split(":") for c in args.config)]
    rows = []
    for source in sources:
        scene = scenes.load(source)
        points = free_space_points(scene, args.points, margin=0.06, seed=1)
        truth = reference.probe_sh(scene, points, directions=4096)
        for kernel, n, m in configs:
            error, seconds = evaluate(scene, gi.GISettings(voxels=n, probes=m, kernel=kernel), points, truth)
            rows.append((scene.name, kernel, n, m, error, seconds))
            print(f"{scene.name:22s} {kernel:8s} N={n:3d} M={m:3d}  rel RMSE {error:6.3f}  {seconds:7.1f} s", flush=True)
    write_report(Path(args.out), rows, args)


MARKER = "<!-- accuracy-table -->"


def write_report(path: Path, rows, args):
    """Replace the table between the two markers in `path` (the prose around it stays)."""
    lines = [
        f"Mitsuba 3 `{reference.variant()}`, 4096 directions per point with light sampling; {args.points} "
        "free-space points per scene. Seconds: the whole solve, one run, on this 2-core machine.",
        "",
        "| scene | kernel | voxels N | probes M | rel. RMSE | seconds |",
        "|---|---|---|---|---|---|",
    ]
    lines += [f"| {s} | {k} | {n} | {m} | {e:.3f} | {t:.1f} |" for s, k, n, m, e, t in rows]
    replace_block(path, MARKER, "\n".join(lines), "# Accuracy against Mitsuba 3")


if __name__ == "__main__":
    main()

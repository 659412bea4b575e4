"""Resolution: relative RMSE against Mitsuba for voxel grids N^3 x probe grids M^3.

Two scenes: the Cornell box (large smooth walls, boxes a few voxels wide) and `thin_shelf` (a shelf 0.02
thick across the lit room: thinner than a voxel at every N here, with a shadow under it). The numpy
solver (`solver`) is solved once per N and projected at every M; at 64^3 voxels its sparse transition
matrix would need ~10 GB, so the compute-shader solver (the same transport, probes within 0.1% of the
numpy ones, docs/PERFORMANCE.md) takes that row, keeping its visibility table across the M.
`mitsuba-probes` (path-traced probes, interpolated) is the floor that the probe grid alone sets at each
M: the difference to it is what the voxels cost.
"""

from __future__ import annotations

import numpy as np

from viewer.physical import projection
from viewer.probes import grid as probe_grid
from viewer.reference import mitsuba as reference
from viewer.physical import transport
from viewer import scene as scene_files
from viewer.evaluation.error import relative_rmse
from viewer.evaluation.points import free_space_points
from viewer.bench.stability import scenes
from viewer.bench.stability.common import RunConfig, StudyResult, try_method
from viewer.bench.stability.methods import MethodSettings, MethodUnavailable, gl_context
from viewer.physical.gi import GISettings
from viewer.rays.raymarch import Tracer
from viewer.rays.voxels import voxelize

COLUMNS = [("scene", "scene", "{}"), ("method", "method", "{}"), ("voxels", "voxels N", "{}"),
           ("probes", "probes M", "{}"), ("rmse", "rel. RMSE", "{:.3f}"), ("seconds", "seconds", "{:.1f}")]
POINTS = 500
DIRECTIONS = 256
GOALS = (0.05, 0.10)


def numpy_grids(scene, voxels: int, resolutions) -> dict[int, probe_grid.ProbeGrid]:
    """`gi.solve` with the physical kernel at one voxel resolution and several probe resolutions: the
    voxels are lit once and projected onto each probe grid."""
    grid = voxelize(scene, voxels)
    tracer = Tracer.build(grid)
    light = transport.solve(grid, scene.sun, tracer=tracer)
    return {m: projection.project(grid, light, scene.sun, scene.bounds,
                                  projection.ProbeSettings(resolution=m, directions=DIRECTIONS), tracer)
            for m in resolutions}


def compute_grids(scene, voxels: int, resolutions) -> dict[int, probe_grid.ProbeGrid]:
    """The same with the compute-shader solver (MethodUnavailable without GL)."""
    from viewer.gpu.compute_solver import ComputeSolver

    grid = voxelize(scene, voxels)
    solver, grids = None, {}
    try:
        for m in resolutions:
            settings = GISettings(voxels=voxels, probes=m, directions=DIRECTIONS)
            if solver is None:
                solver = ComputeSolver(gl_context(), grid, scene.sun, settings, bounds=scene.bounds)
            else:
                solver.restart(settings=settings)
            grids[m] = solver.run().probe_grid(include_emitted=True)
    finally:
        if solver is not None:
            solver.release()
    return grids


NUMPY_LIMIT = 32
"""Largest N the numpy solver is run at here (memory)."""


def run(config: RunConfig) -> StudyResult:
    import time

    result = StudyResult("resolution", COLUMNS)
    voxel_sizes = (16,) if config.quick else (16, 32, 64)
    probe_sizes = (8, 16) if config.quick else (8, 16, 24, 32)
    for scene in (scene_files.load("cornell"), scenes.thin_shelf()):
        points = free_space_points(scene, POINTS, margin=0.06, seed=1)   # as viewer.bench.accuracy: cached truth
        truth = reference.probe_sh(scene, points, directions=4096)
        if "solver" in config.methods:
            for n in voxel_sizes:
                start = time.perf_counter()
                method = "solver" if n <= NUMPY_LIMIT else "compute"
                try:
                    grids = (numpy_grids if method == "solver" else compute_grids)(scene, n, probe_sizes)
                except MethodUnavailable as exc:
                    result.notes.append(f"{n}^3 voxels skipped: {exc}")
                    continue
                seconds = (time.perf_counter() - start) / len(probe_sizes)
                for m, grid in grids.items():
                    result.rows.append(dict(scene=scene.name, method=method, voxels=n, probes=m,
                                            rmse=relative_rmse(grid.interpolate(points), truth), seconds=seconds))
                    print(f"resolution {scene.name} N={n} M={m}: {result.rows[-1]['rmse']:.3f}", flush=True)
        if "mitsuba-probes" in config.methods:
            for m in probe_sizes:
                grid = try_method("mitsuba-probes", scene, MethodSettings(GISettings(probes=m)), result)
                if grid is not None:
                    result.rows.append(dict(scene=scene.name, method="mitsuba-probes", voxels="-", probes=m,
                                            rmse=relative_rmse(grid.interpolate(points), truth), seconds=np.nan))
    result.notes.append(f"{POINTS} free-space points per scene; Mitsuba 4096 directions per point; the solvers "
                        f"with {DIRECTIONS} gather directions per probe. Seconds: the solve divided by the probe "
                        "grids projected from it (a shared machine, and the GPU solver on llvmpipe: compare "
                        "within a method only).")
    summarize(result)
    return result


def summarize(result: StudyResult) -> None:
    for scene in dict.fromkeys(r["scene"] for r in result.rows):
        rows = [r for r in result.rows if r["scene"] == scene and r["method"] in ("solver", "compute")]
        for goal in GOALS:
            good = sorted((r for r in rows if r["rmse"] <= goal), key=lambda r: (r["voxels"] ** 3 + r["probes"] ** 3))
            result.summary.append(f"{scene}: " + (f"the smallest grids within {100 * goal:.0f}% are {good[0]['voxels']}^3 "
                                                  f"voxels with {good[0]['probes']}^3 probes ({good[0]['rmse']:.3f})"
                                                  if good else f"no grid measured here is within {100 * goal:.0f}%"))


def chart(result: StudyResult, path) -> None:
    import matplotlib.pyplot as plt

    scene_names = list(dict.fromkeys(r["scene"] for r in result.rows))
    fig, axes = plt.subplots(1, len(scene_names), figsize=(5 * len(scene_names), 4), sharey=True, squeeze=False)
    for ax, scene in zip(axes[0], scene_names):
        rows = [r for r in result.rows if r["scene"] == scene]
        for voxels in dict.fromkeys(r["voxels"] for r in rows):
            mine = [r for r in rows if r["voxels"] == voxels]
            label = ("Mitsuba probes (floor)" if voxels == "-" else f"{voxels}^3 voxels"
                     + (" (compute)" if mine[0]["method"] == "compute" else ""))
            ax.plot([r["probes"] for r in mine], [r["rmse"] for r in mine], "k--" if voxels == "-" else "-",
                    marker="o", label=label)
        for goal in GOALS:
            ax.axhline(goal, color="grey", lw=0.8, ls=":")
        ax.set_xlabel("probes per axis M")
        ax.set_title(scene, fontsize=10)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
    axes[0][0].set_ylabel("relative RMSE vs Mitsuba")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)

"""The visibility ladder: the solver's converged surface light gathered into the probes with more and
more visibility, each gather scored against the solver's reflected light at the probes.

`viewer.training.bounce_floor --ladder` runs it. The rungs, each raw and after a 3x3x3 box filter over
the valid probes:

- no visibility: the encoding's bounce gather (patches as points, no shadows; viewer.neural.bounce);
- voxel cone tracing with 6 and 16 cones a probe (viewer.training.cones);
- exact rays, 8 to 64 a probe, cast on the scene's triangles (viewer.neural.seen.SeenRays, the network's
  seen feature: each ray takes the light of the voxel whose surface it hits, a back face or nothing
  brings none; the directions are dealt out over the lattice: every 3x3x3 block of probes shares one
  Fibonacci lattice, `seen.interleaved_lattices`; the table in docs/TRAINING.md was measured with a
  lattice turned at random per probe, which leaves the box filtered rungs 1-2 points worse);
- the solver's own probe rays on the same voxels (256 a probe): what any gather of this light reaches,
  the rest being the target's finer voxels (the dataset's solver runs on 32^3, the ladder on the
  encoder's 24^3).

Every gather is timed on what changes with the light (the rays are cast once per geometry, and a
relight is a product with the hits), and its one-off geometry cost beside.
"""

from __future__ import annotations

import time

import numpy as np

from viewer.physical import relight
from viewer.probes import sh
from viewer.probes.grid import ProbeGrid
from viewer.rays.voxel_rays import VoxelRays
from viewer.training.cones import ConeTracer
from viewer.neural.seen import SeenRays

CONES = (6, 16)
RAYS = (8, 16, 32, 64)
TIMING_RUNS = 3


def best_gain_error(estimate: np.ndarray, target: np.ndarray, valid: np.ndarray) -> float:
    """Relative RMSE of `estimate` (3, 9, M, M, M) against `target` over the `valid` (M, M, M) probes,
    after the one gain that fits it best (a network learns a gain for free)."""
    e, t = estimate[..., valid], target[..., valid]
    gain = float((e * t).sum() / max(float((e * e).sum()), 1e-30))
    return float(np.sqrt(((gain * e - t) ** 2).sum() / max(float((t ** 2).sum()), 1e-30)))


def box_filtered(estimate: np.ndarray, valid: np.ndarray) -> np.ndarray:
    """The mean of each probe's 3x3x3 neighbourhood (itself included) over its valid probes: the plainest
    denoiser. `estimate` (..., M, M, M), `valid` (M, M, M)."""
    m = valid.shape[0]
    pad = ((0, 0),) * (estimate.ndim - 3) + ((1, 1),) * 3
    values = np.pad(np.where(valid, estimate, 0.0), pad)
    weights = np.pad(valid.astype(np.float64), 1)
    total, count = np.zeros_like(estimate, np.float64), np.zeros(valid.shape)
    for dx in range(3):
        for dy in range(3):
            for dz in range(3):
                total += values[..., dx:dx + m, dy:dy + m, dz:dz + m]
                count += weights[dx:dx + m, dy:dy + m, dz:dz + m]
    return total / np.maximum(count, 1.0)


def timed(run, runs: int = TIMING_RUNS) -> tuple[object, float]:
    """(the result of run(), the median milliseconds of `runs` calls after a first one that compiles)."""
    result = run()
    times = []
    for _ in range(runs):
        clock = time.perf_counter()
        run()
        times.append(1000.0 * (time.perf_counter() - clock))
    return result, float(np.median(times))


def rungs(scene, lo, hi, probes: int, solver, bounce) -> list[tuple[str, np.ndarray, float, float]]:
    """(name, estimate (P, 9, 3), gather ms, once-per-geometry ms) of every rung for one room, from the
    solver's converged light (`solver`, a PhysicalGI brought up to date) and the encoding's bounce
    gather (`bounce`, a viewer.neural.bounce.Bounce on the same voxels)."""
    reflected = solver.lighting.reflected.astype(np.float64)
    voxels = solver.geometry.voxels
    points = ProbeGrid.positions_for(np.asarray(lo, np.float64), np.asarray(hi, np.float64), probes).reshape(-1, 3)
    found, ms = timed(lambda: bounce.gathered(reflected))
    out = [("no visibility (patches as points)", found, ms, 0.0)]
    for cones in CONES:
        clock = time.perf_counter()
        tracer = ConeTracer(voxels, cones)
        setup = 1000.0 * (time.perf_counter() - clock)
        found, ms = timed(lambda: tracer.gathered(reflected, points))
        out.append((f"cone traced, {cones} cones", found, ms, setup))
    for rays in RAYS:
        clock = time.perf_counter()
        cast = SeenRays(solver.geometry.rays, voxels.count, points, rays, seed=rays)
        setup = 1000.0 * (time.perf_counter() - clock)
        found, ms = timed(lambda: cast.gathered(reflected))
        out.append((f"exact rays, {rays} a probe", found, ms, setup))
    # the ceiling of these voxels' light: the solver's own probe rays (256 directions, the same lattice at
    # every probe, traced on the voxels with its geometry)
    g = solver.geometry
    found, ms = timed(lambda: relight.probe_coefficients(g, solver.lights, solver.sun, solver.materials,
                                                         solver.lighting, include_emitted=False))
    out.append((f"the solver's own probe rays ({g.settings.directions} a probe)", found.astype(np.float64),
                ms, 0.0))
    return out


def lattice(sh_values: np.ndarray, probes: int) -> np.ndarray:
    """(P, 9, 3) -> (3, 9, M, M, M), the split's layout."""
    return sh_values.reshape(probes, probes, probes, 9, 3).transpose(4, 3, 0, 1, 2)


def room_ladder(scene, lo, hi, target: np.ndarray, valid: np.ndarray, probes: int, solver, bounce) -> dict:
    """{rung: {raw, filtered, ms, setup_ms}} for one room: best-gain relative RMSE against `target`
    (3, 9, M, M, M) on the `valid` probes, raw and box filtered."""
    out = {}
    for name, found, ms, setup in rungs(scene, lo, hi, probes, solver, bounce):
        estimate = lattice(found, probes)
        out[name] = {"raw": best_gain_error(estimate, target, valid),
                     "filtered": best_gain_error(box_filtered(estimate, valid), target, valid),
                     "ms": ms, "setup_ms": setup}
    return out


def table(rows: list[dict]) -> tuple[str, dict]:
    """The markdown table of the rooms' ladders and its numbers: medians and worst per rung."""
    names = list(rows[0]["ladder"])
    summary = {}
    lines = ["| gather of the converged surface light | median | worst | 3x3x3 filtered: median | worst "
             "| ms a gather (2 cores) | ms once a geometry |", "|---|---|---|---|---|---|---|"]
    for name in names:
        of = [r["ladder"][name] for r in rows]
        s = {k: float(np.median([o[k] for o in of])) for k in ("raw", "filtered", "ms", "setup_ms")}
        s.update(raw_worst=float(max(o["raw"] for o in of)), filtered_worst=float(max(o["filtered"] for o in of)))
        summary[name] = s
        lines.append(f"| {name} | {100 * s['raw']:.1f}% | {100 * s['raw_worst']:.1f}% | {100 * s['filtered']:.1f}% "
                     f"| {100 * s['filtered_worst']:.1f}% | {s['ms']:.0f} | {s['setup_ms']:.0f} |")
    return "\n".join(lines), summary


"""Sunlight through a window: where the out-of-distribution study saw the physical solver fail.

Every room of that study where `physical` was more than 50% off had a window with the sun shining through
it. Here, rooms of the training generator with a window certain (`Ranges(window_probability=1)`, seeded)
are measured two ways:

- the sunlight the voxels receive (sum over voxels of the sun's irradiance x area, `transport.
  sun_irradiance`) at 16, 32 and 64 voxels, as a multiple of the power that enters through the window
  (irradiance x window area x cosine to the window; the generator aims the sun at the floor from behind
  the open front, so all of it lands inside): 1 is right;
- the error of `physical` against Mitsuba at free-space points, with the sun and with the sun taken away
  (the window stays), so the part that the sun brings shows: for all the light (as `sample` returns it,
  the sun's beam included) and for the indirect light alone (what the renderer shades from the probes;
  it draws the sun itself, with a shadow map).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from viewer.physical import gi
from viewer.evaluation.error import relative_rmse
from viewer.evaluation.points import free_space_points
from viewer.bench.stability.common import RunConfig, StudyResult
from viewer.evaluation.truth import truth_sh
from viewer.evaluation.procedural import Ranges, random_scene

COLUMNS = [("scene", "room", "{}"), ("window", "window", "{}"), ("voxels", "voxels", "{}"),
           ("sun_power", "sunlight on the voxels / through the window", "{:.2f}"),
           ("sunny_floor", "floor points that see the sun (exact)", "{:.3f}"),
           ("false_escapes", "... that the tracer wrongly lets see it", "{:.3f}"), ("probes", "probes", "{}"),
           ("with_sun", "solver, all light, with the sun", "{:.3f}"), ("without_sun", "all light, no sun", "{:.3f}"),
           ("indirect_with_sun", "indirect light, with the sun", "{:.3f}"),
           ("indirect_without_sun", "indirect light, no sun", "{:.3f}")]
ERRORS = {(True, True): "with_sun", (False, True): "without_sun", (True, False): "indirect_with_sun",
          (False, False): "indirect_without_sun"}
"""Column of each (sun, include_emitted)."""
SEED = 909
POINTS = 250
DIRECTIONS = 512
WALL_AXIS = {"ceiling": 1, "back": 2, "left-wall": 0, "right-wall": 0}
"""The axis of each wall's normal (the window's cosine is taken against it)."""


def sunny_room(number: int):
    """Room `number`: the generator's room with a window and the sun through it, and its parameters."""
    return random_scene(np.random.default_rng([SEED, number]), f"sun-{number}", Ranges(window_probability=1.0))


def entering_power(scene, window: dict) -> float:
    """Sunlight through the window (mean of RGB): irradiance x area x cosine to the window's normal."""
    cosine = abs(scene.sun.direction[WALL_AXIS[window["wall"]]])
    return float(np.mean(scene.sun.irradiance)) * 4 * window["half"][0] * window["half"][1] * cosine


def voxel_sun_power(scene, voxels: int) -> float:
    """Sunlight the solver's voxels receive (mean of RGB), as its first bounce sees it."""
    from viewer.physical.transport import sun_irradiance
    from viewer.rays.voxels import voxelize

    grid = voxelize(scene, voxels)
    return float((sun_irradiance(grid, scene.sun).mean(axis=1) * grid.area).sum())


FLOOR_POINTS = 1500


def blocked(origins: np.ndarray, direction: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """(P,) whether a ray from each origin along `direction` hits any of the (T, 3, 3) triangles (exact,
    Moller-Trumbore over every pair: for the few hundred triangles of these rooms)."""
    v0, e1, e2 = triangles[:, 0], triangles[:, 1] - triangles[:, 0], triangles[:, 2] - triangles[:, 0]
    p = np.cross(direction, e2)
    det = np.einsum("tk,tk->t", e1, p)
    usable = np.abs(det) > 1e-12
    inverse = np.where(usable, 1.0 / np.where(usable, det, 1.0), 0.0)
    s = origins[:, None, :] - v0[None]
    u = np.einsum("ptk,tk->pt", s, p) * inverse
    q = np.cross(s, e1[None])
    v = (q @ direction) * inverse
    t = np.einsum("ptk,tk->pt", q, e2) * inverse
    return (usable & (u >= 0) & (v >= 0) & (u + v <= 1) & (t > 1e-6)).any(axis=1)


def floor_sun_visibility(scene, voxels: int) -> tuple[float, float]:
    """Of random points just above the floor: the fraction that truly see the sun (exact ray casts
    against the triangles) and the fraction that the voxel tracer lets see it although a surface is in
    the way (`Tracer.escapes`, as the solver's sun term and its probes use it)."""
    from viewer.rays.raymarch import Tracer
    from viewer.rays.voxels import voxelize

    lo, hi = scene.bounds
    rng = np.random.default_rng(0)
    points = np.stack([rng.uniform(lo[0] + 0.05, hi[0] - 0.05, FLOOR_POINTS), np.full(FLOOR_POINTS, lo[1] + 0.02),
                       rng.uniform(lo[2] + 0.05, hi[2] - 0.05, FLOOR_POINTS)], axis=1)
    direction = np.asarray(scene.sun.direction, np.float64)
    hit = blocked(points, direction, scene.triangles)
    escapes = Tracer.build(voxelize(scene, voxels)).escapes(points, direction)
    return float((~hit).mean()), float((escapes & hit).mean())


def run(config: RunConfig) -> StudyResult:
    result = StudyResult("sun", COLUMNS)
    rooms = [0] if config.quick else [0, 1, 2]
    sizes = [(16, 16)] if config.quick else [(16, 16), (32, 24)]
    for number in rooms:
        scene, params = sunny_room(number)
        window = params["window"]
        label = f"{window['wall']}, {2 * window['half'][0]:.2f} x {2 * window['half'][1]:.2f}"
        bound = entering_power(scene, window)
        points = free_space_points(scene, POINTS, margin=0.06, seed=number)
        dark = replace(scene, sun=None)
        for voxels in (16, 32) if config.quick else (16, 32, 64):
            sunny_floor, false_escapes = floor_sun_visibility(scene, voxels)
            row = dict(scene=scene.name, window=label, voxels=voxels, sun_power=voxel_sun_power(scene, voxels) / bound,
                       sunny_floor=sunny_floor, false_escapes=false_escapes, probes="-",
                       **{column: np.nan for column in ERRORS.values()})
            probes = dict(sizes).get(voxels)
            if probes is not None:
                row["probes"] = probes
                for sunny, target in ((True, scene), (False, dark)):
                    grids = gi.solve_parts(target, gi.GISettings(voxels=voxels, probes=probes, directions=256))
                    for include_emitted, grid in zip((True, False), grids):
                        truth = truth_sh(target, points, DIRECTIONS, include_emitted=include_emitted)
                        row[ERRORS[sunny, include_emitted]] = relative_rmse(grid.interpolate(points), truth)
            result.rows.append(row)
            print(f"sun {scene.name} {voxels}: sunlight x{row['sun_power']:.2f}, error {row['with_sun']:.3f} "
                  f"(no sun {row['without_sun']:.3f}), indirect {row['indirect_with_sun']:.3f} "
                  f"(no sun {row['indirect_without_sun']:.3f})", flush=True)
    result.notes.append(
        f"Rooms of `viewer.evaluation.procedural` with a window (seeds [{SEED}, n]); {POINTS} free-space points, "
        f"Mitsuba {DIRECTIONS} directions per point. `compute` gives the same probes as `physical` (1e-6), so it "
        "is not run again. Sunlight on the voxels: the first bounce's sun term, mean of RGB, over the power "
        "that enters through the window.")
    summarize(result)
    return result


def span(values, scale: float = 1.0, digits: int = 1) -> str:
    """'a-b' over the rooms, or 'a' when they agree to the digits shown."""
    low, high = (f"{scale * v:.{digits}f}" for v in (min(values), max(values)))
    return low if low == high else f"{low}-{high}"


def summarize(result: StudyResult) -> None:
    for voxels in sorted({r["voxels"] for r in result.rows}):
        rows = [r for r in result.rows if r["voxels"] == voxels]
        line = (f"{voxels}^3 voxels: the voxels receive {span([r['sun_power'] for r in rows])} x the sunlight "
                "that enters through the window; the tracer lets "
                f"{span([r['false_escapes'] for r in rows], 100)}% of the floor see the sun through a surface "
                f"(truly sunlit: {span([r['sunny_floor'] for r in rows], 100)}%)")
        measured = [r for r in rows if not np.isnan(r["with_sun"])]
        if measured:
            errors = {column: span([r[column] for r in measured], 100, 0) for column in ERRORS.values()}
            line += (f"; `physical` at {measured[0]['probes']}^3 probes is {errors['with_sun']}% off on all the light "
                     f"with the sun ({errors['without_sun']}% with the sun taken away), "
                     f"{errors['indirect_with_sun']}% on the indirect light ({errors['indirect_without_sun']}%)")
        result.summary.append(line + ".")


def chart(result: StudyResult, path) -> None:
    import matplotlib.pyplot as plt

    fig, (left, right) = plt.subplots(1, 2, figsize=(10, 4))
    for scene in dict.fromkeys(r["scene"] for r in result.rows):
        rows = [r for r in result.rows if r["scene"] == scene]
        left.plot([r["voxels"] for r in rows], [r["sun_power"] for r in rows], marker="o", label=f"{scene} ({rows[0]['window']})")
        measured = [r for r in rows if not np.isnan(r["with_sun"])]
        line, = right.plot([r["voxels"] for r in measured], [r["indirect_with_sun"] for r in measured], marker="o",
                           label=f"{scene}, with the sun")
        right.plot([r["voxels"] for r in measured], [r["indirect_without_sun"] for r in measured], marker="o",
                   ls=":", color=line.get_color(), mfc="none", label=f"{scene}, sun taken away")
    left.axhline(1.0, color="k", lw=0.8, ls="--")
    left.set(xlabel="voxels per axis", ylabel="sunlight on the voxels / through the window",
             title="Sunlight the first bounce lets in (1 is right)")
    right.set(xlabel="voxels per axis (probes 16^3 at 16, 24^3 at 32)",
              ylabel="relative RMSE vs Mitsuba (indirect light)", title="solver, indirect light, sun on / off")
    for ax in (left, right):
        ax.set_xscale("log", base=2)
        ax.set_xticks([16, 32, 64], ["16", "32", "64"])
        ax.minorticks_off()
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)

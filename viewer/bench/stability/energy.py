"""Energy: albedo up to 0.99 must neither diverge nor create light.

- White furnace (a closed room whose every side emits 1 and reflects `albedo`): L = 1 / (1 - albedo)
  everywhere inside, exactly. The eq. 30 series converges only because no receiver gathers more than
  its hemisphere (rows of T clamped to pi, viewer.physical.transport); the discretised `physical` rows gather
  ~1.5% less than pi, and the furnace amplifies a missing fraction d of the hemisphere into a relative
  error of about albedo * d / (1 - albedo): the measured price of the discretisation.
- The closed lit room of the other studies at the same albedos, against Mitsuba; no light may exceed
  the bound Le_max / (1 - albedo) (B_i <= Le_i + albedo max B, since E_i <= pi max B).
"""

from __future__ import annotations

import numpy as np

from viewer.physical import gi
from viewer.reference import mitsuba as reference
from viewer.evaluation.points import free_space_points
from viewer.bench.stability import scenes
from viewer.bench.stability.common import RunConfig, StudyResult, radiance, style, try_method
from viewer.bench.stability.methods import MethodSettings

COLUMNS = [("scene", "scene", "{}"), ("albedo", "albedo", "{:.2f}"), ("method", "method", "{}"),
           ("finite", "finite", "{}"), ("mean", "mean L / truth", "{:.3f}"), ("low", "min L / truth", "{:.3f}"),
           ("high", "max L / truth", "{:.3f}"), ("bound", "max L / bound", "{:.3f}"),
           ("rmse", "rel. RMSE", "{:.3f}")]
SETTINGS = MethodSettings(gi.GISettings(voxels=12, probes=8, directions=128))
"""Small grids: a furnace emits from every surface, the slowest case for the direct light."""
POINTS = 128


def run(config: RunConfig) -> StudyResult:
    result = StudyResult("energy", COLUMNS)
    albedos = (0.5, 0.99) if config.quick else (0.5, 0.8, 0.9, 0.95, 0.99)
    methods = [m for m in config.methods if m != "mitsuba-probes"]
    for albedo in albedos:
        for scene, emitted in ((scenes.furnace(albedo), 1.0),
                               (scenes.lit_room(albedo=albedo, name=f"lit-room-{albedo:g}"), 5.0)):
            furnace = scene.name.startswith("furnace")
            points = free_space_points(scene, POINTS, margin=0.06, seed=7)
            bound = emitted / (1.0 - albedo)
            if furnace:
                truth_sh = None
                truth = np.full(len(points), bound)
            else:
                truth_sh = reference.probe_sh(scene, points, directions=1024)
                truth = radiance(truth_sh)
                result.rows.append(row(scene.name, albedo, "Mitsuba (truth)", truth_sh, truth, bound, truth_sh))
            for name in methods:
                grid = try_method(name, scene, SETTINGS, result)
                if grid is None:
                    continue
                estimate = grid.interpolate(points)
                r = row(scene.name, albedo, name, estimate, truth, bound, truth_sh)
                r["finite"] = bool(np.isfinite(grid.coefficients).all())
                result.rows.append(r)
                print(f"energy {scene.name} {name}: mean {r['mean']:.3f} bound {r['bound']:.3f}", flush=True)
    result.notes.append(f"{SETTINGS.gi.voxels}^3 voxels, {SETTINGS.gi.probes}^3 probes, {SETTINGS.gi.directions} "
                        f"directions; {POINTS} free-space points. Truth: 1 / (1 - albedo) for the furnace, "
                        "Mitsuba (1024 directions per point, unbounded path depth) for the lit room. Bound: "
                        "Le_max / (1 - albedo).")
    summarize(result)
    return result


def row(scene, albedo, method, sh_values, truth, bound, truth_sh) -> dict:
    light = radiance(sh_values)
    ratio = light / np.where(truth > 0, truth, np.nan)
    rmse = (np.nan if truth_sh is None else
            float(np.sqrt(np.mean((sh_values - truth_sh) ** 2)) / np.sqrt(np.mean(truth_sh ** 2))))
    return dict(scene=scene, albedo=albedo, method=method, finite=bool(np.isfinite(sh_values).all()),
                mean=light.mean() / truth.mean(), low=np.nanmin(ratio), high=np.nanmax(ratio),
                bound=light.max() / bound, rmse=rmse)


def summarize(result: StudyResult) -> None:
    furnace = [r for r in result.rows if r["scene"].startswith("furnace")]
    for method in dict.fromkeys(r["method"] for r in furnace):
        rows = sorted((r for r in furnace if r["method"] == method), key=lambda r: r["albedo"])
        errors = ", ".join(f"{100 * (r['mean'] - 1):+.1f}% at {r['albedo']:g}" for r in rows)
        finite = all(r["finite"] for r in rows)
        bounded = max(r["bound"] for r in rows)
        result.summary.append(f"`{method}` furnace: {errors}; {'always finite' if finite else 'NOT FINITE'}, "
                              f"at most {bounded:.3f} of the bound 1 / (1 - albedo).")


def chart(result: StudyResult, path) -> None:
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(10, 4))
    for ax, prefix, title in ((axes[0], "furnace", "White furnace: L = 1 / (1 - albedo)"),
                              (axes[1], "lit-room", "Closed lit room vs Mitsuba")):
        rows = [r for r in result.rows if r["scene"].startswith(prefix)]
        for method in dict.fromkeys(r["method"] for r in rows if not r["method"].startswith("Mitsuba")):
            mine = sorted((r for r in rows if r["method"] == method), key=lambda r: r["albedo"])
            ax.plot([r["albedo"] for r in mine], [r["mean"] for r in mine], label=method, **style(method))
        ax.axhline(1.0, color="k", lw=0.8)
        ax.set_xlabel("albedo")
        ax.set_ylabel("mean radiance / truth")
        ax.set_title(title, fontsize=10)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)

"""Temporal stability: a small lamp moving along a ceiling diagonal in equal steps.

Each frame is solved from scratch (as the viewer does after a light moves). At free-space points, for the
six axis normals, the indirect irradiance E (what the renderer shades from probes) changes from frame to
frame because the light moved. Per method:

- change: mean over frames of ||E_t - E_t-1|| / ||E_t-1||, against the truth's (Mitsuba's reflected
  light, same directions and seed every frame, so that its noise is partly shared between frames);
- jerk: mean over frames of ||E_t+1 - 2 E_t + E_t-1|| / ||E_t||. The lamp moves at constant speed, so a
  smooth answer has a small second difference; light that snaps from voxel to voxel or from probe to
  probe jumps and shows here as flicker. It needs no truth, so the deterministic solvers are measured
  without the reference's noise (Mitsuba's own jerk is mostly its noise: see the noise floor);
- error: mean over frames of ||E_t - T_t|| / ||T_t||.
"""

from __future__ import annotations

import numpy as np

from viewer.physical import gi
from viewer.evaluation.points import free_space_points
from viewer.bench.stability import scenes
from viewer.bench.stability.common import RunConfig, StudyResult, axis_irradiance, style, try_method
from viewer.bench.stability.methods import METHODS, MethodSettings, size_label, truth_sh

COLUMNS = [("method", "method", "{}"), ("size", "voxels / probes", "{}"), ("change", "frame-to-frame change", "{:.3f}"),
           ("ratio", "change / true change", "{:.2f}"), ("jerk", "jerk (flicker)", "{:.4f}"),
           ("worst", "worst frame's jerk", "{:.4f}"), ("error", "mean rel. error", "{:.3f}")]
POINTS = 200


def relative_norm(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.linalg.norm(a) / max(np.linalg.norm(b), 1e-30))


def run(config: RunConfig) -> StudyResult:
    result = StudyResult("temporal", COLUMNS)
    steps = 6 if config.quick else 16
    sizes = [(16, 16)] if config.quick else [(16, 16), (32, 24)]
    frames = [scenes.moving_lamp(t) for t in np.linspace(0.0, 1.0, steps)]
    points = free_space_points(frames[0], POINTS, margin=0.1, seed=13)
    directions = 1024 if config.quick else 4096
    truth = [axis_irradiance(truth_sh(f, points, directions, include_emitted=False)) for f in frames]
    second_seed = axis_irradiance(truth_sh(frames[0], points, directions, include_emitted=False, seed=1))
    noise = relative_norm(second_seed - truth[0], truth[0]) / np.sqrt(2.0)   # one estimate's noise
    result.rows.append(measure("Mitsuba (truth)", "-", truth, truth))
    series = {"Mitsuba (truth)": truth}
    for voxels, probes in sizes:
        settings = MethodSettings(gi.GISettings(voxels=voxels, probes=probes, directions=256), include_emitted=False)
        for name in config.methods:
            if (name in ("mitsuba-probes", "paper") or not METHODS[name].resolution) and (voxels, probes) != sizes[0]:
                continue   # the oracle is slow at 24^3 probes, paper is slow and wrong, the others ignore the size
            grids = []
            for frame in frames:
                grid = try_method(name, frame, settings, result)
                if grid is None:
                    break
                grids.append(axis_irradiance(grid.interpolate(points)))
            if len(grids) < len(frames):
                continue
            size = size_label(name, voxels, probes)
            result.rows.append(measure(name, size, grids, truth))
            series[f"{name} {size}"] = grids
            print(f"temporal {name} {size}: jerk {result.rows[-1]['jerk']:.4f}", flush=True)
    result.notes.append(f"{steps} frames along the lamp's path ({np.linalg.norm(scenes.PATH[1] - scenes.PATH[0]) / (steps - 1):.3f} "
                        f"per step; a voxel is 0.133 at 16^3, 0.065 at 32^3); {POINTS} free-space points, six "
                        f"normals each; Mitsuba {directions} directions per point, reflected light only, whose "
                        f"noise is {noise:.3f} of the light (two seeds of one frame).")
    result.series = {label: dict(mean=[f.mean() for f in frames],
                                 jerk=[relative_norm(c - 2 * b + a, b) for a, b, c in zip(frames, frames[1:], frames[2:])])
                     for label, frames in series.items()}
    summarize(result)
    return result


def measure(name: str, size: str, frames: list[np.ndarray], truth: list[np.ndarray]) -> dict:
    change = [relative_norm(b - a, a) for a, b in zip(frames, frames[1:])]
    true_change = [relative_norm(b - a, a) for a, b in zip(truth, truth[1:])]
    jerk = [relative_norm(c - 2 * b + a, b) for a, b, c in zip(frames, frames[1:], frames[2:])]
    error = [relative_norm(f - t, t) for f, t in zip(frames, truth)]
    return dict(method=name, size=size, change=float(np.mean(change)),
                ratio=float(np.mean(change) / max(np.mean(true_change), 1e-30)),
                jerk=float(np.mean(jerk)), worst=float(np.max(jerk)), error=float(np.mean(error)))


def summarize(result: StudyResult) -> None:
    truth = result.rows[0]["change"]
    for r in result.rows[1:]:
        result.summary.append(f"`{r['method']}` {r['size']}: changes {r['change']:.3f} per frame (truth {truth:.3f}); "
                              f"jerk {r['jerk']:.4f}, worst frame {r['worst']:.4f}; error {r['error']:.3f}.")


def chart(result: StudyResult, path) -> None:
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(11, 4))
    truth = np.asarray(result.series["Mitsuba (truth)"]["mean"])
    for label, values in result.series.items():
        t = np.linspace(0, 1, len(values["mean"]))
        keywords = dict(style(label), ms=4, label=label)
        if label.endswith("32 / 24"):
            keywords.update(alpha=0.6, ls="-.")
        axes[0].plot(t, np.asarray(values["mean"]) / truth, **keywords)
        axes[1].plot(t[1:-1], values["jerk"], **keywords)
    axes[0].set_ylabel("mean indirect irradiance / Mitsuba's")
    axes[0].set_yscale("log")
    axes[0].set_title("Indirect light per frame, against the truth", fontsize=10)
    axes[1].set_ylabel("||E(t+1) - 2 E(t) + E(t-1)|| / ||E(t)||")
    axes[1].set_yscale("log")
    axes[1].set_title("Jerk per frame (flicker; Mitsuba's includes its noise)", fontsize=10)
    for ax in axes:
        ax.set_xlabel("lamp position along its path")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)

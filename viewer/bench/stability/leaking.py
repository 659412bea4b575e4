"""Light leaking: a wall thinner than a voxel between a lit room and a dark one.

`two_rooms()`: the lamp lights the room at x < 0; the room at x > 0 is closed off by a wall 0.02 thick,
so Mitsuba finds no light there at all. With `door=True` light reaches it through a doorway far from the
lamp, and the dark room's light has a true value to compare with; `two-rooms-door-sheet` is the same with a
wall of no thickness, a two-sided sheet (two quads on the same corners, one facing each room). Measured
per method, with and without the product's leak reduction:

- in free space (what `sample` returns): probe validity on or off (`GISettings.invalid_backface_fraction`
  0.25 or 1: probes that see backfaces are filled from their neighbours, or used as they are);
- on the dark face of the wall (what the renderer shades): on = `ProbeGrid.surface_irradiance`, the
  renderer's interpolation (probes sampled half a spacing off the surface, probes behind the surface
  plane and invalid probes weighted down); off = plain trilinear interpolation at the surface point.

Light is given as a fraction of the lit room's (Mitsuba) light, so 0.01 is 1% of it.
"""

from __future__ import annotations


import numpy as np

from viewer.physical import gi
from viewer.reference import mitsuba as reference
from viewer.evaluation.points import free_space_points
from viewer.bench.stability import scenes
from viewer.bench.stability.common import RunConfig, StudyResult, radiance, try_method
from viewer.bench.stability.methods import METHODS, MethodSettings, size_label, without_leak_reduction

COLUMNS = [("scene", "scene", "{}"), ("method", "method", "{}"), ("size", "voxels / probes", "{}"),
           ("reduction", "leak reduction", "{}"), ("lit", "lit room (rel. to truth)", "{:.3f}"),
           ("dark", "dark room, free space", "{:.4f}"), ("near", "dark, within a probe spacing of the wall", "{:.4f}"),
           ("wall", "dark face of the wall", "{:.4f}"), ("dark_vs_truth", "dark room / truth", "{:.2f}")]
POINTS = 800
SURFACE_SPP = 1024


def wall_points(scene_has_door: bool, side: int, count: int = 9, wall: float = scenes.WALL_THICKNESS
                ) -> tuple[np.ndarray, np.ndarray]:
    """Points on one face of the dividing wall `wall` thick (side +1: the dark room's), with its normal;
    the doorway left out. A sheet's (`wall` 0) lie a millimetre off it, clear of the hair by which Mitsuba
    gets its two faces apart (viewer.reference.conversion.sheets_apart)."""
    y, z = np.meshgrid(np.linspace(-0.9, 0.9, count), np.linspace(-0.9, 0.9, count), indexing="ij")
    y, z = y.ravel(), z.ravel()
    if scene_has_door:
        (z0, z1), (y0, y1) = scenes.DOOR
        keep = ~((z > z0 - 0.05) & (z < z1 + 0.05) & (y < y1 + 0.05))
        y, z = y[keep], z[keep]
    x = np.full_like(y, side * max(0.5 * wall, 1e-3))
    normals = np.tile([side, 0.0, 0.0], (len(y), 1))
    return np.stack([x, y, z], axis=1), normals


def surface_light(grid, points, normals, reduction: bool) -> np.ndarray:
    """(P,) irradiance (mean of RGB) at surface points as the renderer shades them, clamped at 0 like the
    shader; `reduction` False: plain trilinear interpolation at the point."""
    if reduction and hasattr(grid, "surface_irradiance"):
        e = grid.surface_irradiance(points, normals)
    elif reduction:  # a renderer without plane weighting: the normal offset alone
        e = grid.irradiance(points + 0.5 * grid.spacing.min() * normals, normals)
    else:
        e = grid.irradiance(points, normals)
    return np.maximum(e, 0.0).mean(axis=1)


def run(config: RunConfig) -> StudyResult:
    result = StudyResult("leaking", COLUMNS)
    sizes = [(16, 16)] if config.quick else [(16, 16), (32, 24)]
    for door, thickness in ([(False, scenes.WALL_THICKNESS)] if config.quick
                            else [(False, scenes.WALL_THICKNESS), (True, scenes.WALL_THICKNESS), (True, 0.0)]):
        scene = scenes.two_rooms(door=door, wall=thickness)
        points = free_space_points(scene, POINTS, margin=0.06, seed=5)
        dark = scenes.in_dark_room(points)
        truth = radiance(reference.probe_sh(scene, points, directions=1024))
        lit_truth = truth[~dark].mean()
        dark_truth = truth[dark].mean()
        wall, wall_normal = wall_points(door, +1, wall=thickness)
        lit_wall, lit_normal = wall_points(door, -1, wall=thickness)
        lit_wall_truth = reference.irradiance(scene, lit_wall, lit_normal, spp=SURFACE_SPP).mean()
        wall_truth = reference.irradiance(scene, wall, wall_normal, spp=SURFACE_SPP).mean(axis=1)
        result.rows.append(dict(scene=scene.name, method="Mitsuba (truth)", size="-", reduction="-", lit=1.0,
                                dark=dark_truth / lit_truth, near=np.nan, wall=wall_truth.mean() / lit_wall_truth,
                                dark_vs_truth=1.0 if door else np.nan))
        for voxels, probes in sizes:
            settings = MethodSettings(gi.GISettings(voxels=voxels, probes=probes, directions=256))
            spacing = (scene.bounds[1] - scene.bounds[0])[0] / probes
            near = dark & (points[:, 0] < spacing)
            for name in config.methods:
                if (name == "paper" or not METHODS[name].resolution) and (voxels, probes) != sizes[0]:
                    continue   # without visibility (or at a fixed resolution) the leak does not depend on the size
                for reduction in ((True, False) if METHODS[name].leak_reduction else (None,)):
                    run_settings = settings if reduction in (True, None) else without_leak_reduction(settings)
                    grid = try_method(name, scene, run_settings, result)
                    if grid is None:
                        break
                    estimate = radiance(grid.interpolate(points))
                    dark_mean = estimate[dark].mean()
                    result.rows.append(dict(
                        scene=scene.name, method=name, size=size_label(name, voxels, probes),
                        reduction={True: "on", False: "off", None: "-"}[reduction],
                        lit=estimate[~dark].mean() / lit_truth, dark=dark_mean / lit_truth,
                        near=estimate[near].mean() / lit_truth,
                        wall=surface_light(grid, wall, wall_normal, reduction is not False).mean() / lit_wall_truth,
                        dark_vs_truth=dark_mean / dark_truth if door else np.nan))
                    print(f"leaking {scene.name} {name} {voxels}/{probes} reduction {reduction}: "
                          f"dark {result.rows[-1]['dark']:.4f} wall {result.rows[-1]['wall']:.4f}", flush=True)
    result.notes.append(f"{POINTS} random free-space points (0.06 from every surface), split by room; "
                        f"Mitsuba: 1024 directions per point, {SURFACE_SPP} cosine samples per wall point. "
                        "Every column is light as a fraction of the lit room's true light (free space: mean "
                        "radiance; wall: irradiance on the lit face of the wall), except `dark room / truth`.")
    summarize(result)
    return result


def summarize(result: StudyResult) -> None:
    rows = [r for r in result.rows if r["scene"] == "two-rooms" and (
        r["size"] == "16 / 16" or (r["method"] in METHODS and not METHODS[r["method"]].resolution))]
    for r in rows:
        if r["reduction"] in ("on", "-"):
            size = f"{r['size'].replace(' / ', '^3 voxels, ')}^3 probes" if "/" in r["size"] else "no grid"
            result.summary.append(
                f"`{r['method']}` ({size}): the closed dark room gets {100 * r['dark']:.2f}% of the "
                f"lit room's light in free space ({100 * r['near']:.1f}% within a probe spacing of the wall) and "
                f"{100 * r['wall']:.1f}% on the wall's dark face; the truth is 0.")


def chart(result: StudyResult, path) -> None:
    import matplotlib.pyplot as plt

    rows = [r for r in result.rows if r["scene"] == "two-rooms" and r["method"] != "Mitsuba (truth)"]
    labels = [f"{r['method']}\n{r['size']}" + (f"\nreduction {r['reduction']}" if r["reduction"] != "-" else "")
              for r in rows]
    x = np.arange(len(rows))
    fig, ax = plt.subplots(figsize=(max(6, 0.75 * len(rows) + 2), 4.2))
    for offset, key, label in ((-0.27, "dark", "dark room, free space"),
                               (0.0, "near", "within a probe spacing of the wall"),
                               (0.27, "wall", "dark face of the wall (renderer)")):
        ax.bar(x + offset, [max(r[key], 1e-5) for r in rows], 0.27, label=label)
    ax.set_yscale("log")
    ax.set_xticks(x, labels, fontsize=7)
    ax.set_ylabel("light in the closed dark room\n(fraction of the lit room's; truth: 0)")
    ax.set_title("Light leaking through a 0.02 wall (two-rooms)")
    ax.legend(fontsize=8)
    ax.grid(axis="y", alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)

"""Where the seen input's error comes from: the light of the surfaces it gathers, or the gather.

    python -m viewer.training.surface_light [--val 20] [--dark 4] [--out docs/data/surface_light.json]

For each scene of `viewer.training.evaluate`'s set (the public scenes, fresh validation rooms, dark
rooms), the seen light (viewer/neural/seen.py: SEEN_RAYS rays a probe, `SEEN_BOUNCES` bounces and a tail) is gathered
from three surface lights on the encoder's 24^3 voxels:
- `probes`: the voxels' direct light read from the probes' direct SH half a voxel in front (encoding
  versions up to 8);
- `voxels`: the voxels' direct light summed at each voxel (`irradiance.voxel_direct`, version 9);
- `solver direct`: the physical solver's own direct light on the same voxels, the bounces as above;
- `solver converged`: the solver's converged light of every voxel (every bounce), gathered once;
and each is filtered over the 3x3x3 probes around it, plainly (`box`) or each probe weighted by its
rays' open share (`open`, as the network's filter is). Scored as `evaluate` scores the networks: the
relative RMSE of the indirect light against Mitsuba at 500 free-space points (its answers are cached),
with the solver on the same voxels beside them. Medians by kind of scene, and every scene's rows.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np

from viewer.evaluation.error import relative_rmse
from viewer.evaluation.points import free_space_points
from viewer.evaluation.truth import truth_sh
from viewer.neural import encoding
from viewer.physical.gi import GISettings, PhysicalGI
from viewer.probes.grid import ProbeGrid
from viewer.rays.voxels import voxelize

LATTICE = 24


def filtered(light: np.ndarray, weight: np.ndarray, m: int) -> np.ndarray:
    """(P, 9, 3) `light` averaged over the 3x3x3 probes around each, weighted by `weight` (P,), the
    lattice's faces repeated outward (as the network's filter pads)."""
    from scipy import ndimage

    w = weight.reshape(m, m, m).astype(np.float64)
    x = light.reshape(m, m, m, 27) * w[..., None]
    num = ndimage.uniform_filter(x, size=(3, 3, 3, 1), mode="nearest")
    den = ndimage.uniform_filter(w, size=3, mode="nearest")
    return (num / np.maximum(den, 1.0 / 27.0)[..., None]).reshape(-1, 9, 3)


def scored_scene(scene, m: int = LATTICE):
    """What the gather studies start from: the evaluation's 500 free-space points of `scene`, Mitsuba's
    indirect light there (cached), and the scene voxelized at `m` with its occluders."""
    points = free_space_points(scene, 500, margin=0.06, seed=1)
    truth = truth_sh(scene, points, 4096, include_emitted=False)
    grid = voxelize(scene, m)
    return points, truth, grid, encoding.occluders(scene, grid)


def scene_rows(scene) -> dict:
    m = LATTICE
    points, truth, grid, blockers = scored_scene(scene, m)
    lo, hi = scene.bounds
    spacing = (hi - lo) / m
    flat = encoding.lattice_cells(grid.position, lo, spacing, m)
    lights = encoding.emitting_patches(flat, grid)
    pieces = encoding.patch_pieces(flat, grid, lights[3], encoding.NEAR_PIECES * spacing.max())
    probes = ProbeGrid.positions_for(lo, hi, m).reshape(-1, 3)
    visible = encoding.lattice_visibility(blockers, probes, lights[0], lights[1], lo, spacing)
    direct = encoding.emitter_sh(lights, probes, visible, pieces) + encoding.sun_sh(scene.sun, blockers, probes)
    once = encoding.Bounce(grid, lo, hi, m)
    once.sh(grid.albedo, direct)
    rays = encoding.seen_rays(blockers, grid, probes)
    solver = PhysicalGI(GISettings(voxels=m, probes=m))
    solver.update(scene)

    def seen(irradiance):
        return encoding.seen_light(rays, once, grid.albedo, (grid.albedo * irradiance / np.pi).astype(np.float32))[0]

    lights_on_surfaces = {
        "probes": encoding.seen_light(rays, once, grid.albedo, once.leaving(grid.albedo))[0],
        "voxels": seen(encoding.voxel_direct(grid, lights, pieces, blockers, scene.sun, lo, spacing))}
    if solver.geometry.voxels.count == grid.count:   # the solver's voxels are the encoder's
        lights_on_surfaces["solver direct"] = seen(solver.lighting.direct)
        lights_on_surfaces["solver converged"] = rays.gathered(solver.lighting.reflected)
    row = {}
    for name, light in lights_on_surfaces.items():
        for how, weight in (("box", np.ones(m ** 3)), ("open", rays.open)):
            grid_sh = filtered(np.asarray(light, np.float64), weight, m).reshape(m, m, m, 9, 3)
            everywhere = ProbeGrid(lo, hi, grid_sh, np.ones((m,) * 3, bool))
            row[f"{name}, {how}"] = relative_rmse(everywhere.interpolate(points), truth)
    row["solver on the same voxels"] = relative_rmse(solver.probe_grid(False).interpolate(points), truth)
    return row


def main(argv=None) -> int:
    from viewer.cli_parsing import add_out, tool_parser
    from viewer.training.evaluate import evaluation_scenes

    parser = tool_parser(__doc__, prog="python -m viewer.training.surface_light")
    parser.add_argument("--val", type=int, default=20, help="fresh validation rooms")
    parser.add_argument("--dark", type=int, default=4, help="dark rooms (every surface 0.01-0.04)")
    parser.add_argument("--seed", type=int, default=14)
    add_out(parser, help="JSON of every scene's rows and the medians")
    args = parser.parse_args(argv)
    rows = []
    for kind, scene in evaluation_scenes(args.val, args.dark, args.seed, "v2"):
        row = {"scene": scene.name, "kind": kind, **scene_rows(scene)}
        rows.append(row)
        print(kind, scene.name, {k: round(100 * v, 1) for k, v in row.items() if isinstance(v, float)}, flush=True)
    summary = {}
    for kind in dict.fromkeys(r["kind"] for r in rows):
        mine = [r for r in rows if r["kind"] == kind]
        keys = [k for k in mine[0] if all(k in r for r in mine) and isinstance(mine[0][k], float)]
        summary[kind] = {k: float(np.median([r[k] for r in mine])) for k in keys}
        print(kind, len(mine), {k: f"{100 * v:.1f}%" for k, v in summary[kind].items()})
    if args.out:
        args.out.write_text(json.dumps({"summary": summary, "rows": rows}, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""The seen rays shared between neighbouring probes: how close their gather comes to the solver's probes.

    python -m viewer.training.seen_reuse [--rays 32] [--only NAME ...] [--val 20] [--dark 0] [--out F]

The network's seen light is gathered by a few rays a probe (viewer/neural/seen.py) and averaged over the
3x3x3 probes around each by its filter: noise traded for blur. Here each probe also reads the rays of its
26 neighbours, reprojected to it: each hit is seen from the probe (its direction from there; a hit whose
surface faces away from the probe, or a neighbour across a closed link, is dropped), and weighted by the
balance heuristic (Veach 1997): its density from this probe's point of view over the sum of its densities
from all the probes whose rays could have found it. A uniform direction from probe j finds a point x of
a surface with density rays x cos(theta_j) / (4 pi r_j^2), theta_j the angle at the surface, r_j the
distance; the sum runs over the same 27 probes (or the 7 of the faces, `--faces`).

For each scene of `viewer.training.evaluate`'s set, the solver's converged light of the encoder's voxels
is gathered four ways (each probe's own rays raw, the open-weighted 3x3x3 box the network's filter
starts from, the neighbours' rays with the balance heuristic) and scored as `evaluate` scores the
networks: the relative RMSE of the indirect light against Mitsuba at 500 free-space points (its answers
cached), beside the solver's own probes. What it measures is the gather, not the surface light: the
network's inputs reflect their own estimate of it (docs/PERFORMANCE.md, "64 seen rays a probe").
"""

from __future__ import annotations

import json
import sys
import time

import numba
import numpy as np

from viewer.evaluation.error import relative_rmse
from viewer.neural.seen import SeenRays, lattice_rays
from viewer.physical.gi import GISettings, PhysicalGI
from viewer.probes.grid import ProbeGrid
from viewer.probes.sh import add_basis
from viewer.rays.voxels import VoxelGrid
from viewer.training.surface_light import LATTICE, scored_scene


def reused(rays: SeenRays, voxels: VoxelGrid, radiance: np.ndarray, reach: str = "block") -> np.ndarray:
    """(P, 9, C) the light of the voxels leaving with `radiance` (K, C), gathered at each probe of `rays`
    (a cubic lattice) from its own rays and its neighbours' (`reach`: "self" its own only, which is
    `rays.gathered`; "faces" the 6 across its faces; "block" the 26 of its 3x3x3 block), reprojected and
    weighted by the balance heuristic over the probes read."""
    if rays.links is None or rays.distances is None:
        raise ValueError("the neighbours' rays need the probes on a cubic lattice, with the rays' distances")
    side = rays.links.shape[1]
    directions = lattice_rays(rays.probes, rays.rays, rays.seed)[0]
    landed = rays.voxel.reshape(rays.probes, rays.rays)
    return _reused(np.asarray(rays.points, np.float64), np.asarray(directions, np.float64),
                   np.asarray(rays.distances, np.float64), np.where(landed < rays.count, landed, -1).astype(np.int64),
                   np.asarray(voxels.normal, np.float64), np.asarray(radiance, np.float64), side,
                   np.ascontiguousarray(rays.links), {"self": 0, "faces": 1, "block": 2}[reach])


@numba.njit(cache=True, nogil=True)
def _reachable(links, i, j, k, a, b, c) -> bool:
    """Whether probe (a, b, c) is reached from (i, j, k) along open links, x first, then y, then z."""
    x, y, z = i, j, k
    while x != a:
        s = 1 if a > x else -1
        if not links[0, min(x, x + s), y, z]:
            return False
        x += s
    while y != b:
        s = 1 if b > y else -1
        if not links[1, x, min(y, y + s), z]:
            return False
        y += s
    while z != c:
        s = 1 if c > z else -1
        if not links[2, x, y, min(z, z + s)]:
            return False
        z += s
    return True


@numba.njit(cache=True, nogil=True, parallel=True)
def _reused(points, directions, distances, landed, normals, radiance, m, links, reach):
    """`reused` on arrays: each probe of the m^3 lattice reads the probes of `reach` around it that its
    `links` reach, and every hit of theirs that faces it, weighed by its density from this probe over the
    sum of its densities from all the probes read (the balance heuristic); the probes split over the cores."""
    probes, rays = landed.shape
    channels = radiance.shape[1]
    out = np.zeros((probes, 9, channels))
    for p in numba.prange(probes):
        i, j, k = p // (m * m), (p // m) % m, p % m
        read = np.empty(27, np.int64)
        basis = np.empty(9)   # a hit's SH weights
        count = 0
        for di in range(-1, 2):
            for dj in range(-1, 2):
                for dk in range(-1, 2):
                    steps = abs(di) + abs(dj) + abs(dk)
                    a, b, c = i + di, j + dj, k + dk
                    if (reach == 0 and steps > 0) or (reach == 1 and steps > 1):
                        continue
                    if min(a, b, c) < 0 or max(a, b, c) >= m or not _reachable(links, i, j, k, a, b, c):
                        continue
                    read[count] = (a * m + b) * m + c
                    count += 1
        for u in range(count):
            q = read[u]
            for r in range(rays):
                v = landed[q, r]
                if v < 0:
                    continue
                t = distances[q, r]
                hx = points[q, 0] + t * directions[q, r, 0]
                hy = points[q, 1] + t * directions[q, r, 1]
                hz = points[q, 2] + t * directions[q, r, 2]
                nx, ny, nz = normals[v, 0], normals[v, 1], normals[v, 2]
                sx, sy, sz = hx - points[p, 0], hy - points[p, 1], hz - points[p, 2]
                far2 = sx * sx + sy * sy + sz * sz
                if far2 < 1e-12:
                    continue
                far = np.sqrt(far2)
                cosine = -(sx * nx + sy * ny + sz * nz) / far
                if cosine <= 0.0:
                    continue
                density = 0.0   # the hit's density over the probes read, rays x cos / (4 pi r^2) each
                for w in range(count):
                    o = read[w]
                    ox, oy, oz = hx - points[o, 0], hy - points[o, 1], hz - points[o, 2]
                    r2 = ox * ox + oy * oy + oz * oz
                    c = -(ox * nx + oy * ny + oz * nz) / max(np.sqrt(r2), 1e-12)
                    if c > 0.0:
                        density += rays * c / (4.0 * np.pi * r2)
                if density <= 0.0:
                    continue
                weight = cosine / far2 / density
                basis[:] = 0.0
                add_basis(sx / far, sy / far, sz / far, basis, weight)
                for b in range(9):
                    for ch in range(channels):
                        out[p, b, ch] += basis[b] * radiance[v, ch]
    return out


def scene_row(scene, rays_a_probe: int) -> dict:
    """The relative RMSE of each gather of the solver's converged light, and of the solver's probes, against
    Mitsuba's indirect light at the evaluation's points; the reuse's seconds."""
    m = LATTICE
    points, truth, grid, blockers = scored_scene(scene, m)
    lo, hi = scene.bounds
    probes = ProbeGrid.positions_for(lo, hi, m).reshape(-1, 3)
    rays = SeenRays(blockers.landing, grid.count, probes, rays_a_probe, voxels=grid)
    solver = PhysicalGI(GISettings(voxels=m, probes=m))
    solver.update(scene)
    if solver.geometry.voxels.count != grid.count:
        raise ValueError(f"{scene.name}: the solver's voxels are not the encoder's")
    light = np.asarray(solver.lighting.reflected, np.float32)

    def error(sh_values) -> float:
        grid_sh = np.asarray(sh_values, np.float64).reshape(m, m, m, 9, 3)
        return relative_rmse(ProbeGrid(lo, hi, grid_sh, np.ones((m,) * 3, bool)).interpolate(points), truth)

    raw = rays.gathered(light)
    row = {"solver": relative_rmse(solver.probe_grid(False).interpolate(points), truth), "raw": error(raw),
           "box": error(rays.filtered(raw))}
    for reach in ("faces", "block"):
        clock = time.perf_counter()
        row[f"reused, {reach}"] = error(reused(rays, grid, light, reach))
        row[f"seconds, {reach}"] = time.perf_counter() - clock
    return row


def main(argv=None) -> int:
    from viewer.cli_parsing import add_out, tool_parser
    from viewer.training.evaluate import evaluation_scenes

    parser = tool_parser(__doc__, prog="python -m viewer.training.seen_reuse")
    parser.add_argument("--rays", type=int, default=32, help="seen rays a probe")
    parser.add_argument("--val", type=int, default=20, help="fresh validation rooms")
    parser.add_argument("--dark", type=int, default=0, help="dark rooms (every surface 0.01-0.04)")
    parser.add_argument("--only", nargs="+", metavar="NAME", help="only these scenes of the set")
    parser.add_argument("--seed", type=int, default=14)
    add_out(parser, help="JSON of every scene's row")
    args = parser.parse_args(argv)
    if args.rays < 1:
        parser.error("--rays must be at least 1")
    chosen = [(kind, scene) for kind, scene in evaluation_scenes(args.val, args.dark, args.seed, "v2")
              if not args.only or scene.name in args.only]
    if args.only and len(chosen) < len(set(args.only)):
        parser.error(f"--only: not in the set: {', '.join(sorted(set(args.only) - {s.name for _, s in chosen}))}")
    rows = []
    for kind, scene in chosen:
        row = {"scene": scene.name, "kind": kind, "rays": args.rays, **scene_row(scene, args.rays)}
        rows.append(row)
        print(scene.name, "  ".join(f"{k} {v:.2f} s" if k.startswith("seconds") else f"{k} {100 * v:.1f}%"
                                     for k, v in row.items() if isinstance(v, float)), flush=True)
    if args.out:
        args.out.write_text(json.dumps({"rows": rows}, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())

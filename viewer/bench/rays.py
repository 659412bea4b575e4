"""Rays a second of the lightmap's final gather: Embree (called from compiled loops, and through embreex's
own binding) and the numba DDA on the same rays, 1 and 2 threads.

    python -m viewer.bench.rays cornell path/to/mesh.obj

For each scene, the renderer's own gather rays (its lightmap at the default texel, RenderSettings'
final_gather rays from each of its gather records, both sides) are cast by `GatherRays.of` through each backend of
viewer/rays/cast.py, the caster's build (Embree's BVH, the DDA's 32^3 cells) included, after one small
cast that compiles or loads the kernels. embreex's binding holds Python's lock while it traces, so its
rows run on one core whatever numba's thread count; Embree called from compiled loops (viewer/rays/embree.py)
and the DDA's kernels run on numba's threads. Runs alternate
backends, so that other work on the machine weighs on both alike.
"""

from __future__ import annotations

import time

import numba
import numpy as np


def gather_inputs(ctx, scene):
    """(points, normals, face_tile, tile_origin, tile_n, width, lift) of the renderer's gather samples (its
    records: `gather_records`)."""
    from viewer.gpu.direct_bake import BakedDirectLight, fitted_texel
    from viewer.gpu.lightmaps import max_texture_side
    from viewer.gpu.render_settings import RenderSettings
    from viewer.gpu.texel_samples import gather_records, strided_samples

    lo, hi = scene.bounds
    texel = fitted_texel(scene, RenderSettings().lightmap_texel * float(np.max(hi - lo)), max_texture_side(ctx))
    lightmap = BakedDirectLight(ctx, scene, texel)
    try:
        rows, columns = np.nonzero(lightmap.covered)
        samples = np.flatnonzero(strided_samples(lightmap, rows, columns)[0])
        sample = samples[gather_records(lightmap, samples)[0]]
        points = lightmap.texel_points[sample].astype(np.float64)
        normals = lightmap.texel_normals[sample].astype(np.float64)
        keep = scene.face_areas > 0
        face_tile = np.where(keep, np.cumsum(keep) - 1, -1)
        return (np.concatenate([points, points]), np.concatenate([normals, -normals]), face_tile,
                lightmap.tile_origin, lightmap.tile_n, lightmap.covered.shape[1], 4e-6 * float(np.min(hi - lo)))
    finally:
        lightmap.release()


def measure(ctx, name: str, rays: int, threads: list[int]) -> list[str]:
    from viewer.gpu.final_gather import GatherRays
    from viewer.gpu.mesh import in_draw_order
    from viewer.rays import dda
    from viewer.rays.cast import TriangleCaster, embree_available
    from viewer.rays.voxels import grid_frame
    from viewer.scene import load

    scene = in_draw_order(load(name))[1]
    points, normals, *layout = gather_inputs(ctx, scene)
    backends = ["dda"] + (["embreex", "embree"] if embree_available() else [])
    lines = []
    for count in threads:
        numba.set_num_threads(count)
        rate = {}
        for backend in backends:
            start = time.perf_counter()
            cells = dda.Cells.blocking(scene, *grid_frame(scene, 32), 32) if backend == "dda" else None
            caster = TriangleCaster(scene, cells, backend)
            build = time.perf_counter() - start
            GatherRays.of(points[:8], normals[:8], caster, *layout, rays)     # compile or load the kernels
            start = time.perf_counter()
            GatherRays.of(points, normals, caster, *layout, rays)
            rate[backend] = len(points) * rays / (build + time.perf_counter() - start) / 1e6
            lines.append(f"| {scene.name} | {len(scene.faces)} | {len(points) * rays / 1e6:.1f} | {backend} | "
                         f"{count} | {build:.3f} | {rate[backend]:.2f} |")
            print(lines[-1], flush=True)
    return lines


def main(argv=None) -> int:
    from viewer.cli_parsing import add_scenes, tool_parser
    from viewer.gpu.context import create_context

    parser = tool_parser(__doc__)
    add_scenes(parser, default=("cornell",))
    parser.add_argument("--rays", type=int, default=72, help="gather rays per sample (2 r^2)")
    parser.add_argument("--threads", type=int, nargs="+", default=[1, 2], help="numba threads, one run each")
    args = parser.parse_args(argv)
    ctx = create_context()
    print("| scene | triangles | rays (M) | caster | threads | build (s) | M rays/s, build included |\n"
          "|---|---|---|---|---|---|---|")
    try:
        for name in args.scenes:
            measure(ctx, name, args.rays, args.threads)
    finally:
        ctx.release()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

"""How even the indirect light is on faces, against Mitsuba: the probe grid's dark streaks and blotches
on the boxes of the Cornell scenes, and steps along silhouettes.

    python -m viewer.bench.blotches [--scenes cornell paper-test] [--size 256] [--spp 256]
                                    [--points 4000] [--gather-rays 72 ...] [--gather-only]

For the default renderer (`gather`: the indirect light baked per lightmap texel by the final gather of
viewer/gpu/final_gather.py, the probes lighting the second bounce on), the probes alone baked per texel with
the weights of viewer/probes/weights.py (`baked`, RenderSettings.final_gather = 0) and the exact path
(the probes interpolated per fragment, shaders/probe_grid.glsl), per scene:

- **PSNR** of the final image (8-bit sRGB, no MSAA) against Mitsuba's, as the gallery measures it.
- **streaks** (`face_blocks`): the final view (no MSAA, linear HDR) against Mitsuba's render, on
  16x16-pixel blocks lying wholly on one face: ours / Mitsuba of the blocks' mean luminance, the worst
  block on the faces off the room's axes (the boxes' sides) and on all faces, and the RMS distance
  from 1 over all blocks.
- **silhouette steps** (`silhouette_steps`, at 640x360): the largest and the 99th percentile jump of
  the indirect light between consecutive pixels along silhouettes.
- **points**: the probes' lookup at random points on the faces (`SurfaceWeights`, or
  `ProbeGrid.surface_irradiance` for the exact path, tested against the shaders) against Mitsuba's
  indirect irradiance there (`reference.irradiance(indirect_only=True)`), relative RMS error of the
  luminance (errors relative to the point's own value, or to a fifth of the median where that is
  darker), for the faces off the axes and for the others (walls, floor, ceiling) apart. Points that
  another surface covers closely (within 2% of the scene's size along the normal: the ceiling 1 cm
  behind the lamp) or that lie inside a solid (the floor under the boxes) are left out: no camera sees
  them.

Probes come from the compute solver at the GISettings defaults, indirect light only.
"""

from __future__ import annotations

import numpy as np

LUMINANCE = np.array([0.2126, 0.7152, 0.0722])
def off_axis(normals: np.ndarray) -> np.ndarray:
    """Unit normals (..., 3) not along one of the coordinate axes."""
    return np.abs(normals).max(axis=-1) < 0.99


STREAK_BLOCK = 16
"""Block size (pixels) of the streak metric (`face_blocks`)."""


def face_blocks(ours: np.ndarray, truth: np.ndarray, normals: np.ndarray, block: int = STREAK_BLOCK):
    """Ours / Mitsuba luminance of the block x block blocks lying wholly on one plane's normal, emitters
    left out (a block whose brightest truth pixel is over 4x its median holds an emitter's edge):
    (ratios (K,), block corners (K, 2) as (x, y), off_axis (K,) whether the block's normal is off the
    room's axes). The dark vertical streaks of the probe grid on the boxes' faces were this metric's
    worst blocks (0.78-0.80 of Mitsuba on cornell and paper-test at 256x256)."""
    h, w = ours.shape[:2]
    ratios, corners, tilted = [], [], []
    for y in range(0, h - block + 1, block):
        for x in range(0, w - block + 1, block):
            n = normals[y:y + block, x:x + block].reshape(-1, 3)
            if np.abs(n - n[0]).max() > 1e-3 or np.linalg.norm(n[0]) < 0.5:
                continue
            t = truth[y:y + block, x:x + block] @ LUMINANCE
            if t.mean() < 1e-3 or t.max() > 4.0 * np.median(t):
                continue
            ratios.append((ours[y:y + block, x:x + block] @ LUMINANCE).mean() / t.mean())
            corners.append((x, y))
            tilted.append(bool(off_axis(n[0])))
    return np.asarray(ratios), np.asarray(corners).reshape(-1, 2), np.asarray(tilted, bool)


def silhouette_steps(indirect: np.ndarray, normals: np.ndarray, depth: np.ndarray, jump: float = 0.05) -> np.ndarray:
    """Steps of the indirect light along silhouettes (P,): the pixels at the edge of a face in front of
    another (a neighbour across the edge has another normal and lies more than `jump` x its view depth
    further away) form lines; between two consecutive pixels of such a line (the next row's, or
    column's, edge pixel of the same face within one pixel), |L(next) / L(this) - 1| of the indirect
    luminance. Indirect light varies over a probe spacing, many pixels here, so along an edge it is
    smooth when each pixel gets the light of its own surface point; an upsampling from a lower
    resolution that mixes in the face behind in some pixels of the edge and not others makes steps
    (quarter resolution: a period of 4 pixels)."""
    lum = indirect @ LUMINANCE
    steps = []
    for axis in (0, 1):
        for flip in (False, True):
            n, l, d = (np.moveaxis(a, axis, 0) for a in (normals, lum, depth))
            if flip:
                n, l, d = n[::-1], l[::-1], d[::-1]
            same = np.all(np.abs(n[1:] - n[:-1]) < 1e-3, axis=-1)    # rows i and i+1 share a normal
            edge = np.zeros(l.shape, bool)
            edge[:-1] = ~same & (d[1:] > (1.0 + jump) * d[:-1]) & (np.linalg.norm(n, axis=-1)[:-1] > 0.5)
            for i, j in zip(*np.nonzero(edge)):
                for dj in (0, -1, 1):           # the line goes on in the next column, within a pixel
                    k = j + 1
                    if 0 <= i + dj < l.shape[0] and k < l.shape[1] and edge[i + dj, k] \
                            and np.abs(n[i + dj, k] - n[i, j]).max() < 1e-3 and l[i, j] > 1e-4:
                        steps.append(abs(l[i + dj, k] / l[i, j] - 1.0))
                        break
    return np.asarray(steps)


def view_depth(offscreen, camera, bounds) -> np.ndarray:
    """(H, W) view-space depth of the last frame drawn into the offscreen renderer's HDR target
    (single-sampled), from its depth buffer; the far plane where nothing was drawn."""
    from viewer.gpu.camera import clip_range

    near, far = clip_range(camera, *bounds)
    w, h = offscreen.size
    z = np.frombuffer(offscreen.hdr.framebuffer.read(attachment=-1, dtype="f4", components=1), np.float32)
    z = z.reshape(h, w)[::-1].astype(np.float64)
    return near * far / (far - z * (far - near))


def surface_points(scene, count: int, seed: int = 0):
    """Random points (count, 3) uniform by area on the scene's non-emitting faces, with their normals."""
    rng = np.random.default_rng(seed)
    weight = np.where(scene.emission.max(axis=1) > 0, 0.0, scene.face_areas)
    face = rng.choice(len(weight), count, p=weight / weight.sum())
    u, v = rng.random(count), rng.random(count)
    flip = u + v > 1
    u[flip], v[flip] = 1 - u[flip], 1 - v[flip]
    a, b, c = (scene.triangles[face, k] for k in range(3))
    return a + u[:, None] * (b - a) + v[:, None] * (c - a), scene.face_normals[face]


def covered(scene, points: np.ndarray, normals: np.ndarray, distance: float) -> np.ndarray:
    """Which points have another face within `distance` straight along their normal (Moller-Trumbore
    against every face)."""
    a, b, c = (scene.triangles[:, k][None] for k in range(3))       # (1, F, 3)
    d = normals[:, None, :]
    e1, e2 = b - a, c - a
    h = np.cross(d, e2)
    det = np.einsum("pfc,pfc->pf", np.broadcast_to(e1, h.shape), h)
    ok = np.abs(det) > 1e-12
    inv = np.where(ok, 1.0 / np.where(ok, det, 1.0), 0.0)
    s = points[:, None, :] - a
    u = np.einsum("pfc,pfc->pf", s, h) * inv
    q = np.cross(s, e1)
    v = np.einsum("pfc,pfc->pf", np.broadcast_to(d, q.shape), q) * inv
    t = np.einsum("pfc,pfc->pf", np.broadcast_to(e2, q.shape), q) * inv
    hit = ok & (u >= 0) & (v >= 0) & (u + v <= 1) & (t > 1e-6 * max(distance, 1e-9)) & (t < distance)
    return hit.any(axis=1)


def relative_rms(ours: np.ndarray, truth: np.ndarray) -> float:
    o, t = ours @ LUMINANCE, truth @ LUMINANCE
    return float(np.sqrt(np.mean(((o - t) / np.maximum(t, 0.2 * np.median(t))) ** 2)))


def measure(ctx, name: str, size: int, spp: int, points: int, gather_rays=(72,),
            others: bool = True) -> list[dict]:
    from viewer.rays import dda
    from viewer.reference import mitsuba as reference
    from viewer import scene as scenes
    from viewer.bench.gallery import psnr, to_srgb8
    from viewer.physical.geometry import voxelize_with_faces
    from viewer.physical.gi import GISettings
    from viewer.gpu.compute_relight import solve_probes
    from viewer.gpu.offscreen import OffscreenRenderer
    from viewer.gpu.renderer import RenderSettings
    from viewer.probes.weights import SurfaceWeights

    scene = scenes.load(name)
    probes = solve_probes(ctx, scene, GISettings(), include_emitted=False)
    truth = reference.render(scene, scene.camera, size, size, spp)
    p, n = surface_points(scene, points)
    indirect = reference.irradiance(scene, p, n, indirect_only=True)
    lo, hi = scene.bounds
    seen = ~covered(scene, p, n, 0.02 * float(np.linalg.norm(hi - lo))) & (indirect.max(axis=1) > 1e-4)
    p, n, indirect = p[seen], n[seen], indirect[seen]
    tilted = off_axis(n)
    cells = dda.Cells.of(voxelize_with_faces(scene, 32), scene)
    rows = []
    paths = [("gather" if rays == RenderSettings().final_gather else f"gather, {rays} rays",
              RenderSettings(final_gather=rays)) for rays in gather_rays]
    if others:
        paths += [("baked", RenderSettings(final_gather=0)), ("exact", RenderSettings(baked=False))]
    for path, settings in paths:
        images = {}
        for image_size, views in (((size, size), ("final", "normals")), ((640, 360), ("final", "direct", "normals"))):
            offscreen = OffscreenRenderer(image_size, settings, samples=0, ctx=ctx)
            try:
                offscreen.renderer.set_scene(scene)
                offscreen.renderer.set_probes(probes)
                for view in views:
                    images[image_size, view] = offscreen.render_hdr(view=view)
                images[image_size, "depth"] = view_depth(offscreen, scene.camera, scene.bounds)
            finally:
                offscreen.release()
        ratios, _, on_tilted = face_blocks(images[(size, size), "final"], truth,
                                           2.0 * _srgb(images[(size, size), "normals"]) - 1.0)
        wide = (640, 360)
        steps = silhouette_steps(images[wide, "final"] - images[wide, "direct"],
                                 2.0 * _srgb(images[wide, "normals"]) - 1.0, images[wide, "depth"])
        if path != "exact":
            lookup = SurfaceWeights.of(p, n, probes, cells).irradiance(probes, n)
        else:
            lookup = probes.surface_irradiance(p, n, settings.probe_normal_offset, settings.probe_plane_falloff)
        final8 = to_srgb8(images[(size, size), "final"])
        rows.append(dict(scene=name, path=path, psnr=psnr(final8, to_srgb8(truth)),
                         worst_tilted=_worst(ratios[on_tilted]), worst=_worst(ratios),
                         rms=float(np.sqrt(np.mean((ratios - 1.0) ** 2))), step_max=float(steps.max()),
                         step_p99=float(np.percentile(steps, 99)),
                         tilted=relative_rms(lookup[tilted], indirect[tilted]),
                         aligned=relative_rms(lookup[~tilted], indirect[~tilted])))
        print(line(rows[-1]), flush=True)
    return rows


def _worst(ratios: np.ndarray) -> float:
    """The ratio farthest from 1."""
    return float(ratios[np.argmax(np.abs(ratios - 1.0))])


def _srgb(x: np.ndarray) -> np.ndarray:
    """The sRGB encoding (the normals view stores the decoded n/2 + 1/2)."""
    x = np.clip(x, 0.0, 1.0)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1 / 2.4) - 0.055)


HEADER = ("| scene | path | PSNR (dB) | worst 16-px block, boxes' faces | worst block, all faces | RMS off 1 | "
          "silhouette steps: largest, 99% | points: faces off the axes | points: walls |\n"
          "|---|---|---|---|---|---|---|---|---|")


def line(r: dict) -> str:
    return (f"| {r['scene']} | {r['path']} | {r['psnr']:.2f} | {r['worst_tilted']:.3f} | {r['worst']:.3f} | "
            f"{r['rms']:.3f} | {r['step_max']:.3f}, {r['step_p99']:.3f} | {r['tilted']:.3f} | {r['aligned']:.3f} |")


def main(argv=None) -> int:
    from viewer.cli_parsing import add_scenes, tool_parser
    from viewer.gpu.context import create_context

    parser = tool_parser(__doc__)
    add_scenes(parser, flag="--scenes")
    parser.add_argument("--size", type=int, default=256)
    parser.add_argument("--spp", type=int, default=256)
    parser.add_argument("--points", type=int, default=4000)
    parser.add_argument("--gather-rays", type=int, nargs="+", default=[72],
                        help="final-gather rays per sample (RenderSettings.final_gather), one row each")
    parser.add_argument("--gather-only", action="store_true", help="leave out the probes-only and exact paths")
    args = parser.parse_args(argv)
    ctx = create_context()
    print(HEADER)
    try:
        for name in args.scenes:
            measure(ctx, name, args.size, args.spp, args.points, args.gather_rays, not args.gather_only)
    finally:
        ctx.release()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

"""How even the indirect light is on faces, against Mitsuba: the measure of the probe grid's dark
blotches (leaks) on the boxes of the Cornell scenes.

    python -m viewer.bench.blotches [--scenes cornell paper-test] [--size 256] [--spp 256]
                                    [--points 4000] [--falloff 3 0]

Two numbers per scene, for each RenderSettings.probe_plane_falloff given (0: the back-side weight off,
validity weights only):

- **blocks**: the final view (256x256, 4x MSAA, linear HDR) against Mitsuba's render, on 8x8-pixel
  blocks that lie wholly on one face not aligned with the room's axes (the boxes' sides, the sphere's
  facets): the ratio of the blocks' mean luminance, ours / Mitsuba, as median, 5-95% range and RMS
  distance from 1. Mitsuba's noise (256 spp) widens the spread a little.
- **points**: `ProbeGrid.surface_irradiance` (what the renderer's probe lookup computes, tested against
  the shader) at random points on the faces against Mitsuba's indirect irradiance there
  (`reference.irradiance(indirect_only=True)`), relative RMS error of the luminance (errors relative
  to the point's own value, or to a fifth of the median where that is darker), for the faces off the
  axes and for the others (walls, floor, ceiling) apart. Points that another surface covers closely
  (within 2% of the scene's size along the normal: the ceiling 1 cm behind the lamp) or that lie
  inside a solid (no light at all: the floor under the boxes) are left out: no camera sees them.

Probes come from the compute solver at the GISettings defaults, indirect light only.
"""

from __future__ import annotations

import argparse

import numpy as np

LUMINANCE = np.array([0.2126, 0.7152, 0.0722])
BLOCK = 8


def off_axis(normals: np.ndarray) -> np.ndarray:
    """Unit normals (..., 3) not along one of the coordinate axes."""
    return np.abs(normals).max(axis=-1) < 0.99


def block_ratios(ours: np.ndarray, truth: np.ndarray, normals: np.ndarray) -> np.ndarray:
    """Ours / Mitsuba luminance of the BLOCK x BLOCK blocks lying wholly on one off-axis face."""
    h, w = ours.shape[:2]
    ratios = []
    for y in range(0, h - BLOCK + 1, BLOCK):
        for x in range(0, w - BLOCK + 1, BLOCK):
            n = normals[y:y + BLOCK, x:x + BLOCK].reshape(-1, 3)
            if not off_axis(n[0]) or np.abs(n - n[0]).max() > 1e-3:
                continue
            o = ours[y:y + BLOCK, x:x + BLOCK] @ LUMINANCE
            t = truth[y:y + BLOCK, x:x + BLOCK] @ LUMINANCE
            ratios.append(o.mean() / max(t.mean(), 1e-9))
    return np.asarray(ratios)


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


def measure(ctx, name: str, size: int, spp: int, points: int, falloffs) -> list[dict]:
    from viewer import reference
    from viewer import scene as scenes
    from viewer.gi import GISettings
    from viewer.gpu.compute_relight import solve_probes
    from viewer.gpu.offscreen import OffscreenRenderer
    from viewer.gpu.renderer import RenderSettings

    scene = scenes.load(name)
    probes = solve_probes(ctx, scene, GISettings(), include_emitted=False)
    truth = reference.render(scene, scene.camera, size, size, spp)
    p, n = surface_points(scene, points)
    indirect = reference.irradiance(scene, p, n, indirect_only=True)
    lo, hi = scene.bounds
    seen = ~covered(scene, p, n, 0.02 * float(np.linalg.norm(hi - lo))) & (indirect.max(axis=1) > 1e-4)
    p, n, indirect = p[seen], n[seen], indirect[seen]
    rows = []
    for falloff in falloffs:
        settings = RenderSettings(probe_plane_falloff=falloff)
        offscreen = OffscreenRenderer((size, size), settings, ctx=ctx)
        try:
            offscreen.renderer.set_scene(scene)
            offscreen.renderer.set_probes(probes)
            ours = offscreen.render_hdr(view="final")
            normals = 2.0 * _srgb(offscreen.render_hdr(view="normals")) - 1.0
        finally:
            offscreen.release()
        ratios = block_ratios(ours, truth, normals)
        lookup = probes.surface_irradiance(p, n, settings.probe_normal_offset, falloff)
        tilted = off_axis(n)
        rows.append(dict(scene=name, falloff=falloff, blocks=len(ratios), median=np.median(ratios),
                         low=np.percentile(ratios, 5), high=np.percentile(ratios, 95),
                         rms=float(np.sqrt(np.mean((ratios - 1.0) ** 2))),
                         tilted=relative_rms(lookup[tilted], indirect[tilted]),
                         aligned=relative_rms(lookup[~tilted], indirect[~tilted])))
        print(line(rows[-1]), flush=True)
    return rows


def _srgb(x: np.ndarray) -> np.ndarray:
    """The sRGB encoding (the normals view stores the decoded n/2 + 1/2)."""
    x = np.clip(x, 0.0, 1.0)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1 / 2.4) - 0.055)


HEADER = ("| scene | plane falloff | blocks | ours / Mitsuba: median | 5-95% | RMS off 1 | "
          "points: faces off the axes | points: walls |\n|---|---|---|---|---|---|---|---|")


def line(r: dict) -> str:
    return (f"| {r['scene']} | {r['falloff']:g} | {r['blocks']} | {r['median']:.2f} | {r['low']:.2f}-{r['high']:.2f} | "
            f"{r['rms']:.3f} | {r['tilted']:.3f} | {r['aligned']:.3f} |")


def main(argv=None) -> int:
    from viewer.gpu.context import create_context

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenes", nargs="+", default=["cornell", "paper-test"])
    parser.add_argument("--size", type=int, default=256)
    parser.add_argument("--spp", type=int, default=256)
    parser.add_argument("--points", type=int, default=4000)
    parser.add_argument("--falloff", type=float, nargs="+", default=[3.0, 0.0])
    args = parser.parse_args(argv)
    ctx = create_context()
    print(HEADER)
    try:
        for name in args.scenes:
            measure(ctx, name, args.size, args.spp, args.points, args.falloff)
    finally:
        ctx.release()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

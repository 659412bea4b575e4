"""How good each kind of edge anti-aliasing of the window's still image is: PSNR against Mitsuba (1024
samples a pixel, the box filter) with the plain tone curve (clamp and sRGB, as an 8-bit Mitsuba image),
and against the limit of the window's refinement (64 images), for the box scenes.

    python -m viewer.bench.antialiasing [--scenes cornell paper-test] [--size 512]

Rows: one single-sampled image (none); 4x multisampling (`--msaa 4`); refinement after 4, 8, 16 and 64
images (`--refine N`, the window's default 8: viewer/ui/viewport.py), averaged in display values as a
multisample resolve does; and the capture's `--supersample 16`, 16 x 16 images averaged in linear light
(the gallery's). Frame costs are `python -m viewer.bench.frame --aa`'s.
"""

from __future__ import annotations

import numpy as np

REFINED = (4, 8, 16, 64)


def images(ctx, scene, probes, size: int) -> dict[str, np.ndarray]:
    from viewer.gpu.offscreen import OffscreenRenderer
    from viewer.gpu.renderer import RenderSettings
    from viewer.gpu.targets import DisplayTarget, RefiningTarget

    offscreen = OffscreenRenderer((size, size), RenderSettings(tonemap="none"), ctx=ctx, samples=0)
    renderer = offscreen.renderer
    renderer.set_scene(scene)
    renderer.set_probes(probes)
    out = {}
    try:
        for name, target in (("none", DisplayTarget(ctx, (size, size))),
                             ("4x multisampling", DisplayTarget(ctx, (size, size), samples=min(4, ctx.max_samples)))):
            renderer.draw(target)
            out[name] = target.read()
            target.release()
        for count in REFINED:
            target = RefiningTarget(ctx, (size, size), renderer.programs)
            for _ in range(count):
                renderer.draw(target)
            out[f"refined, {count} images"] = target.read()
            target.release()
        out["capture --supersample 16 (linear light)"] = offscreen.render(supersample=16)
    finally:
        offscreen.release()
    return out


def main(argv=None) -> int:
    from viewer.bench.gallery import psnr, solve, to_srgb8
    from viewer.cli_parsing import tool_parser
    from viewer.gpu.context import create_context
    from viewer.reference import mitsuba as reference
    from viewer import scene as scenes

    parser = tool_parser(__doc__, prog="python -m viewer.bench.antialiasing")
    parser.add_argument("--scenes", nargs="+", default=["cornell", "paper-test"])
    parser.add_argument("--size", type=int, default=512)
    args = parser.parse_args(argv)
    ctx = create_context()
    print("| scene | anti-aliasing | PSNR against Mitsuba | against 64 refined images |\n|---|---|---|---|")
    for name in args.scenes:
        scene = scenes.load(name)
        truth = to_srgb8(reference.render(scene, scene.camera, args.size, args.size, 1024))
        found = images(ctx, scene, solve(ctx, scene, "compute"), args.size)
        limit = found[f"refined, {REFINED[-1]} images"]
        for kind, image in found.items():
            print(f"| {name} | {kind} | {psnr(image, truth):.2f} dB | {psnr(image, limit):.2f} dB |", flush=True)
    ctx.release()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

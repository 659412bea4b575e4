"""Frame time of the renderer, headless (EGL): median milliseconds of a frame at a given size, for each
view, with the probe grid from the compute-shader solver, for the interactive path (the default
RenderSettings: baked direct light, indirect light sampled at a lower resolution) and, with --exact, the
exact per-fragment path as well.

    python -m viewer.bench.frame [--scene cornell] [--size 1280x720] [--frames 7] [--exact]
"""

from __future__ import annotations

import argparse

from viewer import scene as scenes
from viewer.gi import GISettings
from viewer.gpu.compute_solver import solve_probes
from viewer.gpu.context import create_context, describe
from viewer.gpu.offscreen import OffscreenRenderer, parse_size
from viewer.gpu.renderer import RenderSettings

VIEWS = ("final", "direct", "indirect", "albedo")


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scene", default="cornell")
    parser.add_argument("--size", default="1280x720")
    parser.add_argument("--frames", type=int, default=7)
    parser.add_argument("--light-samples", type=int, nargs="+", default=[16, 32])
    parser.add_argument("--exact", action="store_true",
                        help="also time the exact path (direct light and probe grid per fragment)")
    args = parser.parse_args(argv)
    size = parse_size(args.size)
    scene = scenes.load(args.scene)
    ctx = create_context()
    print(describe(ctx))
    probes = solve_probes(ctx, scene, GISettings(), include_emitted=False)
    paths = {"fast": {}, "exact": dict(baked_direct=False, half_indirect=False)}
    if not args.exact:
        del paths["exact"]
    print(f"| path | light samples | {' | '.join(VIEWS)} |\n|---|---|" + "---|" * len(VIEWS))
    for samples in args.light_samples:
        for path, overrides in paths.items():
            settings = RenderSettings(light_samples=samples, **overrides)
            offscreen = OffscreenRenderer(size, settings, samples=0, ctx=ctx)
            offscreen.renderer.set_scene(scene)
            offscreen.renderer.set_probes(probes)
            times = [offscreen.frame_time(view=view, frames=args.frames) for view in VIEWS]
            print(f"| {path} | {samples} | " + " | ".join(f"{t:.0f}" for t in times) + " |", flush=True)
            offscreen.release()
    ctx.release()


if __name__ == "__main__":
    main()

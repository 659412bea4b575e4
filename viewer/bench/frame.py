"""Frame time of the renderer, headless (EGL), as the window draws: median milliseconds of a frame at a
given size for each view, with the probe grid from the compute-shader solver; the same per render pass
(GPU timer query and CPU wall clock); and frame times while the compute solver converges in the
background of the frames, as in the viewer.

    python -m viewer.bench.frame [--scene cornell] [--size 1280x720] [--frames 15] [--exact]
                                 [--aa] [--passes] [--progressive] [--write]

A frame is what the viewer does to redraw its view: draw into an 8-bit display target (tone mapping in
the surface pass) and blit it to another framebuffer, waited for with glFinish. `--exact` adds the exact
path (direct light and probe grid per fragment). `--aa` times still frames with each kind of edge
anti-aliasing (none, the window's refinement, 4x multisampling). `--passes` times each pass of a fast final frame with
a glFinish after it. `--progressive` runs the viewer's GI controller and viewport frame by frame from
a new scene to a converged compute solver: each frame steps the solver within its budget (or publishes
its probes) and redraws when the probes changed, at the preview scale while the solver works, and the
worst and 95th-percentile frames are what it is judged by. `--write` puts the tables into
docs/PERFORMANCE.md (between the `frame-times` markers). The machine's load average is printed with the
numbers: llvmpipe shares the CPU cores with everything else that runs.
"""

from __future__ import annotations

import os
import platform
import sys
import time
from pathlib import Path

import numpy as np

from viewer import scene as scenes
from viewer.evaluation.report import replace_block
from viewer.physical.gi import GISettings
from viewer.gpu.compute_relight import solve_probes
from viewer.gpu.context import create_context, describe
from viewer.gpu.offscreen import OffscreenRenderer
from viewer.gpu.pass_timer import PassTimer
from viewer.gpu.renderer import RenderSettings
from viewer.gpu.targets import DisplayTarget

VIEWS = ("final", "direct", "indirect", "albedo")
ROOT = Path(__file__).resolve().parents[2]
MARKER = "<!-- frame-times -->"
TARGET_MS = 1000.0 / 30.0


def frame_table(ctx, scene, probes, size, light_samples, exact: bool, frames: int) -> str:
    """Median ms (and frames per second) of each view, fast path (and exact)."""
    paths = {"fast": {}}
    if exact:
        paths["exact"] = dict(baked=False)
    lines = [f"| path | light samples | {' | '.join(VIEWS)} | final fps |", "|---|---|" + "---|" * (len(VIEWS) + 1)]
    for samples in light_samples:
        for path, overrides in paths.items():
            offscreen = OffscreenRenderer(size, RenderSettings(light_samples=samples, **overrides), samples=0, ctx=ctx)
            offscreen.renderer.set_scene(scene)
            offscreen.renderer.set_probes(probes)
            times = [offscreen.frame_time(view=view, frames=frames) for view in VIEWS]
            offscreen.release()
            lines.append(f"| {path} | {samples} | " + " | ".join(f"{t:.1f}" for t in times)
                         + f" | {1000.0 / times[0]:.0f} |")
            print(lines[-1], flush=True)
    return "\n".join(lines)


def anti_aliasing_table(ctx, scene, probes, size, light_samples: int, frames: int, refine: int = 8) -> str:
    """Still frames of the fast final view with each kind of edge anti-aliasing, as the window draws them
    (the draw and its blit, waited for): none; refinement, a frame per image of `refine` averaged (the
    window's default, viewer/ui/viewport.py); 4x multisampling, every still frame."""
    from viewer.gpu.targets import RefiningTarget

    offscreen = lit_offscreen(ctx, scene, probes, size, light_samples)
    renderer = offscreen.renderer
    screen = DisplayTarget(ctx, size)
    kinds = {"none": (DisplayTarget(ctx, size), 1), f"refined, {refine} images": (RefiningTarget(ctx, size, renderer.programs), refine),
             "4x multisampling": (DisplayTarget(ctx, size, samples=min(4, ctx.max_samples)), 1)}
    lines = ["| anti-aliasing | frame ms, median | worst | frames to the anti-aliased image | ms to it |",
             "|---|---|---|---|---|"]
    try:
        for name, (target, images) in kinds.items():
            times = []
            for _ in range(max(frames, images) + 1):   # the first: compiles the variant
                if isinstance(target, RefiningTarget) and target.images >= images:
                    target.restart()
                start = time.perf_counter()
                renderer.draw(target, None, "final")
                renderer.present(target, screen.resolved, "final")
                ctx.finish()
                times.append(1e3 * (time.perf_counter() - start))
            median = float(np.median(times[1:]))
            lines.append(f"| {name} | {median:.1f} | {max(times[1:]):.1f} | {images} | {images * median:.0f} |")
            print(lines[-1], flush=True)
    finally:
        for target, _ in kinds.values():
            target.release()
        screen.release()
        offscreen.release()
    return "\n".join(lines)


def lit_offscreen(ctx, scene, probes, size, light_samples: int) -> OffscreenRenderer:
    """A single-sampled renderer of `scene` lit by `probes`, drawn once (shadows, lightmaps, compiles)."""
    offscreen = OffscreenRenderer(size, RenderSettings(light_samples=light_samples), samples=0, ctx=ctx)
    offscreen.renderer.set_scene(scene)
    offscreen.renderer.set_probes(probes)
    offscreen.render()
    return offscreen


def pass_table(ctx, scene, probes, size, light_samples: int, frames: int) -> str:
    """Median GPU and CPU ms of each pass of the fast final view, each pass waited for."""
    offscreen = lit_offscreen(ctx, scene, probes, size, light_samples)
    screen = DisplayTarget(ctx, size)
    try:
        renderer = offscreen.renderer
        renderer.timer = PassTimer(ctx)
        rows = []
        for _ in range(frames):
            renderer.draw(offscreen.display, None, "final")
            renderer.present(offscreen.display, screen.resolved, "final")
            rows.append(renderer.timer.frame())
    finally:
        screen.release()
        offscreen.release()
    lines = ["| pass | GPU ms | CPU ms |", "|---|---|---|"]
    for name in rows[0]:
        gpu = np.median([r[name][0] for r in rows])
        cpu = np.median([r[name][1] for r in rows])
        lines.append(f"| {name} | {gpu:.1f} | {cpu:.1f} |")
    gpu_total = np.median([sum(v[0] for v in r.values()) for r in rows])
    cpu_total = np.median([sum(v[1] for v in r.values()) for r in rows])
    lines.append(f"| all (each pass waited for) | {gpu_total:.1f} | {cpu_total:.1f} |")
    text = "\n".join(lines)
    print(text, flush=True)
    return text


def progressive(ctx, scene, size, light_samples: int, budget_ms: float | None, timeout: float = 300.0) -> dict:
    """Frame times (ms) from a new scene to a converged compute solver, frame by frame as the viewer
    runs them (GIController.update, then Viewport.frame), the solver's steps and the redraws apart."""
    from viewer.gpu.renderer import Renderer
    from viewer.ui.gi_sources import GIController
    from viewer.ui.viewport import Viewport

    renderer = Renderer(ctx, RenderSettings(light_samples=light_samples))
    renderer.background_bake = True   # as the viewer: a new lattice's texel weights on a worker
    renderer.warm_up()
    renderer.set_scene(scene)
    options = {} if budget_ms is None else {"compute_budget_ms": budget_ms}
    gi = GIController(ctx, "compute", GISettings(), **options)
    viewport = Viewport(ctx, renderer)
    screen = ctx.simple_framebuffer(size, components=4)
    frames, steps, redraws = [], [], []
    probes_version = 0
    try:
        viewport.frame(scene.camera, "final", (probes_version,), screen)   # compile, shadows, lightmap
        ctx.finish()
        gi.set_scene(scene, 1)
        start = time.perf_counter()
        while (gi.busy or not viewport.settled) and time.perf_counter() - start < timeout:
            clock = time.perf_counter()
            changed, grid = gi.update()
            solver = time.perf_counter()
            if changed:
                renderer.set_probes(grid)
                probes_version += 1
            drew = viewport.frame(scene.camera, "final", (probes_version,), screen, preview=gi.busy)
            ctx.finish()
            end = time.perf_counter()
            frames.append(1e3 * (end - clock))
            steps.append(1e3 * (solver - clock))
            redraws.append(drew)
            time.sleep(0.001)   # the viewer's loop also waits for events between frames
        seconds = time.perf_counter() - start
    finally:
        viewport.release()
        renderer.release()
        for attachment in (*screen.color_attachments, screen.depth_attachment):
            attachment.release()   # simple_framebuffer made them; releasing the framebuffer leaves them
        screen.release()
        gi.close()
    frames, steps = np.asarray(frames), np.asarray(steps)
    return dict(frames=len(frames), seconds=seconds, budget=gi.compute_budget_ms,
                median=np.median(frames), p95=np.percentile(frames, 95), worst=frames.max(),
                over=(frames > TARGET_MS).mean(), step_median=np.median(steps), step_p95=np.percentile(steps, 95),
                step_worst=steps.max(), redraws=int(np.sum(redraws)))


def progressive_line(result: dict) -> str:
    return (f"| {result['budget']:.0f} | {result['frames']} | {result['seconds']:.1f} | {result['median']:.1f} | "
            f"{result['p95']:.1f} | {result['worst']:.1f} | {100 * result['over']:.1f}% | "
            f"{result['step_median']:.1f} / {result['step_p95']:.1f} / {result['step_worst']:.1f} | "
            f"{result['redraws']} |")


def gi_update_table(ctx, scene, probes, size, frames: int) -> str:
    """Milliseconds from new probes (a relight, a network update) to the frame that shows them: the
    renderer's texel bake (viewer/gpu/indirect_bake.py: the weighted sum per texel on the CPU and its
    upload) and the frame, against a frame alone; the texel weights themselves are made once per scene
    and probe lattice, and timed apart (`weights`)."""
    offscreen = OffscreenRenderer(size, RenderSettings(), samples=0, ctx=ctx)
    renderer = offscreen.renderer
    try:
        renderer.set_scene(scene)
        offscreen.render()
        start = time.perf_counter()
        renderer.set_probes(probes)
        offscreen.render()
        weights = 1e3 * (time.perf_counter() - start)
        updates, plain = [], []
        for k in range(frames):
            renderer.set_probes(probes.with_coefficients(probes.coefficients * (1.0 + 0.01 * (k % 2))))
            start = time.perf_counter()
            renderer.draw(offscreen.display, None, "final")
            ctx.finish()
            updates.append(1e3 * (time.perf_counter() - start))
            start = time.perf_counter()
            renderer.draw(offscreen.display, None, "final")
            ctx.finish()
            plain.append(1e3 * (time.perf_counter() - start))
    finally:
        offscreen.release()
    text = ("| GI update: new probes to the frame that shows them | frame alone | first probes of a lattice "
            "(weights) |\n|---|---|---|\n"
            f"| {np.median(updates):.1f} ms | {np.median(plain):.1f} ms | {weights:.0f} ms |")
    print(text, flush=True)
    return text


def machine(ctx, loads) -> str:
    return (f"{platform.machine()}, {os.cpu_count()} CPU cores shared with other work (load average "
            f"{min(loads):.1f}-{max(loads):.1f} over the run), {describe(ctx)}")


def main(argv=None):
    from viewer.cli_parsing import CAPTURE_SIZES, add_write, parse_size, tool_parser

    parser = tool_parser(__doc__)
    parser.add_argument("--scene", default="cornell")
    parser.add_argument("--size", default="1280x720")
    parser.add_argument("--frames", type=int, default=15)
    parser.add_argument("--light-samples", type=int, nargs="+", default=[16, 32])
    parser.add_argument("--exact", action="store_true",
                        help="also time the exact path (direct light and probe grid per fragment)")
    parser.add_argument("--passes", action="store_true", help="time each pass of a fast final frame")
    parser.add_argument("--aa", action="store_true",
                        help="time still frames with each kind of edge anti-aliasing (none, refined, 4x MSAA)")
    parser.add_argument("--progressive", action="store_true",
                        help="frame times while the compute solver converges, as in the viewer")
    parser.add_argument("--budget", type=float, nargs="*",
                        help="with --progressive: the solver's ms per frame to try (default: the viewer's)")
    add_write(parser, "put the tables into docs/PERFORMANCE.md")
    args = parser.parse_args(argv)
    size = parse_size(args.size, *CAPTURE_SIZES, example="640x480")
    scene = scenes.load(args.scene)
    ctx = create_context()
    loads = [os.getloadavg()[0]]
    print(describe(ctx), f"load average {loads[0]:.2f}", flush=True)
    probes = solve_probes(ctx, scene, GISettings(), include_emitted=False)
    sections = [frame_table(ctx, scene, probes, size, args.light_samples, args.exact, args.frames)]
    loads.append(os.getloadavg()[0])
    sections.append(gi_update_table(ctx, scene, probes, size, args.frames))
    loads.append(os.getloadavg()[0])
    if args.aa:
        sections.append(anti_aliasing_table(ctx, scene, probes, size, args.light_samples[0], args.frames))
        loads.append(os.getloadavg()[0])
    if args.passes:
        sections.append(pass_table(ctx, scene, probes, size, args.light_samples[0], args.frames))
        loads.append(os.getloadavg()[0])
    if args.progressive:
        lines = ["| solver ms / frame | frames | seconds to converge | frame median | p95 | worst | "
                 f"over {TARGET_MS:.1f} ms | solver step median / p95 / worst | redraws |",
                 "|---|---|---|---|---|---|---|---|---|"]
        for budget in args.budget or [None]:
            lines.append(progressive_line(progressive(ctx, scene, size, args.light_samples[0], budget)))
            print(lines[-1], flush=True)
            loads.append(os.getloadavg()[0])
        sections.append("\n".join(lines))
    line = machine(ctx, loads)
    print(line)
    if args.write:
        command = "python -m viewer.bench.frame " + " ".join(argv if argv is not None else sys.argv[1:])
        block = (f"Generated by `{command.strip()}` on {line}; {args.scene}, {size[0]}x{size[1]}, no anti-aliasing but in its own table.\n\n"
                 + "\n\n".join(sections))
        replace_block(ROOT / "docs" / "PERFORMANCE.md", MARKER, block, "# Performance")
        print("wrote docs/PERFORMANCE.md")
    ctx.release()


if __name__ == "__main__":
    main()

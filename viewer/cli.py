"""The command line: `python -m viewer [capture|sample|bake|bench] ...` (see docs/ARCHITECTURE.md).

Exit status 0 on success, 2 for bad input (one line on stderr, no traceback), 1 for an internal error.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

from viewer import sources
from viewer.bench.run import add_arguments as bench_arguments  # no GL, Mitsuba or matplotlib import
from viewer import capture as captures  # no GL import until a capture runs
from viewer.cli_parsing import (NEGATIVE_VALUE_FLAGS, msaa_count, supersample_count, add_dataclass_flags, add_gi_flags, gi_settings,
                                joined_negative_values)
from viewer.errors import ArgumentParser, InputError, exit_status
from viewer.gpu.render_settings import RenderSettings
from viewer.physical.gi import Timings
from viewer.progress import announce_compiles, step
from viewer.ui.options import add_arguments as view_arguments  # no GL or imgui import
from viewer.output import replacing


VIEWS = ("final", "direct", "indirect", "albedo", "normals", "voxels", "probes")
"""The renderer's view modes (viewer.gpu.renderer.VIEWS; listed here so parsing needs no GL)."""
RENDER_CHOICES = {"tonemap": ("aces", "reinhard", "none"), "voxel_color": ("albedo", "radiance")}
RENDER_METAVARS = {"exposure": "EV", "light_samples": "N", "lightmap_faces": "N"}


def _gi_arguments(p: argparse.ArgumentParser):
    add_gi_flags(p)
    p.add_argument("--sun", metavar="dx,dy,dz,r,g,b", help="directional light dx,dy,dz,r,g,b (direction towards the sun, irradiance)")
    p.add_argument("--model", help="the neural source's .onnx file (default: models/probenet.onnx)")


def program_name(argv0: str | None = None) -> str:
    """What the user typed to run the command line: `gi-viewer` for the installed program, else
    `python -m viewer`."""
    name = Path(sys.argv[0] if argv0 is None else argv0).name
    return "gi-viewer" if name.startswith("gi-viewer") else "python -m viewer"


def scene_help(grids: bool = False) -> str:
    """SCENE's help: what it may be, and the built-in scenes by name."""
    from viewer.scene import SUPPORTED_SUFFIXES, builtin_names

    files = f"a scene file ({' '.join(SUPPORTED_SUFFIXES)})" + (" or a baked grid .npz" if grids else "")
    return f"a built-in scene ({', '.join(builtin_names())}) or {files}"


def build_parser(prog: str | None = None) -> argparse.ArgumentParser:
    parser = ArgumentParser(prog=prog or program_name(),
                            description="Real-time diffuse global illumination viewer. Without a command it "
                                        "opens the viewer on SCENE (the Cornell box by default).")
    sub = parser.add_subparsers(dest="command", parser_class=ArgumentParser, metavar="COMMAND")

    view = sub.add_parser("view", help="the interactive viewer (the default command)")
    view.add_argument("scene", nargs="?", default="cornell", metavar="SCENE", help=scene_help(grids=True))
    view_arguments(view)

    sample = sub.add_parser("sample", help="incident-radiance SH at points, as the renderer sees it")
    sample.add_argument("scene", metavar="SCENE", help=scene_help())
    sample.add_argument("--points", required=True, help="(P, 3) float32 world points, .npy")
    sample.add_argument("--method", choices=sources.sample_choices(), default=sources.SOLVER.name,
                        help="the GI source that solves")
    sample.add_argument("--out", required=True, help="(P, 9, 3) float32 SH output, .npy")
    _gi_arguments(sample)

    capture = sub.add_parser("capture", help="render a picture headless (EGL): .png, .jpg or .npy")
    capture.add_argument("scene", nargs="?", default="cornell", metavar="SCENE", help=scene_help(grids=True))
    capture.add_argument("--out", required=True, metavar="FILE",
                         help="the picture to write, by its suffix: .png, .jpg (or .jpeg), or .npy for the "
                              "linear HDR radiance (H, W, 3) float32; .gif with --turntable")
    capture.add_argument("--size", default="1280x720", metavar="WxH", help="the picture's size")
    capture.add_argument("--gi", choices=sources.chosen_by_name(), default=sources.DEFAULT,
                         help="where the indirect light comes from, as in the window (compute: the "
                              "compute-shader solver)")
    capture.add_argument("--view", choices=VIEWS, default="final", help="what the picture shows")
    capture.add_argument("--msaa", type=msaa_count, default=4, metavar="N",
                         help="multisample count: edge anti-aliasing (0: off; default: %(default)s)")
    capture.add_argument("--supersample", type=supersample_count, default=1, metavar="N",
                         help="N x N subpixel images averaged in linear light instead of multisampling: a "
                              "bright lamp's edges as a path tracer draws them (16: 41.6 dB against Mitsuba on "
                              "the box scenes, where multisampling gives 37.4-37.6; costs N^2 draws; "
                              "default: %(default)s, off)")
    capture.add_argument("--turntable", type=int, default=0, metavar="N",
                         help="N frames of a turn around the scene's centre, as an animated .gif --out")
    capture.add_argument("--camera", metavar="ox,oy,oz,tx,ty,tz",
                         help="the camera's position and the point it looks at (default: the view the viewer "
                              "opens the scene with)")
    capture.add_argument("--fov", type=float, metavar="DEG",
                         help="vertical field of view in degrees (default: the camera's)")
    add_dataclass_flags(capture, RenderSettings, fields=captures.RENDER_FIELDS, choices=RENDER_CHOICES,
                        metavars=RENDER_METAVARS)
    _gi_arguments(capture)

    bake = sub.add_parser("bake", help="solve once and write the converged probe grid for other tools")
    bake.add_argument("scene", metavar="SCENE", help=scene_help())
    bake.add_argument("--out", required=True, help="the probe grid, .npz (keys: docs/BAKED.md)")
    bake.add_argument("--dds", help="also write the indirect light as a DDS volume texture (docs/BAKED.md)")
    bake.add_argument("--dds-precision", dest="dds_precision", choices=("32", "16"), default="32",
                      help="bits per channel of the DDS texels (RGBA32F or RGBA16F)")
    _gi_arguments(bake)

    bench = sub.add_parser("bench", help="every GI method's time, memory and error against Mitsuba: CSV, charts")
    bench_arguments(bench)
    return parser


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    if not argv or argv[0] not in ("view", "sample", "capture", "bake", "bench", "-h", "--help"):
        argv = ["view", *argv]
    argv = joined_negative_values(argv, NEGATIVE_VALUE_FLAGS)   # --camera -0.7,0.3,... is a value
    return exit_status(lambda: run_command(build_parser().parse_args(argv)))


def run_command(args) -> int:
    announce_compiles()   # the first run compiles the ray kernels: say so rather than sit silent
    return {"view": run_view, "sample": run_sample, "capture": run_capture,
            "bench": run_bench, "bake": run_bake}[args.command](args)


def run_capture(args) -> int:
    """`capture [SCENE] --out FILE.png ...`: the picture the flags ask for (viewer.capture)."""
    return captures.run_capture(captures.capture_request(args))


def load_points(path: str) -> np.ndarray:
    file = Path(path)
    if not file.is_file():
        raise InputError(f"{path}: no such points file")
    try:
        points = np.load(file, allow_pickle=False)
    except Exception as exc:
        raise InputError(f"{path}: not a readable .npy array ({type(exc).__name__})") from None
    if not isinstance(points, np.ndarray):   # an .npz archive, whatever its name
        points.close()
        raise InputError(f"{path}: an .npz archive, not an .npy array of points")
    if points.ndim != 2 or points.shape[1] != 3 or len(points) == 0:
        raise InputError(f"{path}: points must be a non-empty (P, 3) array, got shape {points.shape}")
    if not np.issubdtype(points.dtype, np.number) or np.issubdtype(points.dtype, np.complexfloating):
        raise InputError(f"{path}: points must be real numbers, got {points.dtype}")
    points = points.astype(np.float64)
    if not np.all(np.isfinite(points)):
        raise InputError(f"{path}: points contain NaN or infinity")
    return points


def _load_scene(args):
    from viewer import scene as scenes

    sun = scenes.parse_sun(args.sun) if getattr(args, "sun", None) else None
    scene = scenes.load(args.scene, sun=sun)
    unlit = scenes.unlit_warning(scene)
    if unlit:
        scenes.note(unlit)
    return scene


def run_sample(args) -> int:
    settings = gi_settings(args)
    points = load_points(args.points)
    out = Path(args.out)
    if out.parent and not out.parent.exists():
        raise InputError(f"{args.out}: folder {out.parent} does not exist")
    start = time.perf_counter()
    scene = _load_scene(args)
    timings = Timings({"load": time.perf_counter() - start})
    options = sources.SolveOptions(include_emitted=True, model=getattr(args, "model", None), timings=timings)
    try:
        with step(f"sample: solving ({sources.lookup(args.method).label})"):
            grid, timings = sources.lookup(args.method).solve(scene, settings, options)
    except sources.SourceError as exc:
        raise InputError(f"--method {args.method}: {exc}") from None
    clock = time.perf_counter()
    sh = grid.interpolate(points).astype(np.float32)
    timings.stages["interpolate"] = time.perf_counter() - clock
    with replacing(out) as fh:   # exactly --out (np.save would add .npy to another suffix), whole or not at all
        np.save(fh, sh)
    print(f"sample {args.method}: {len(points)} points; {timings}", file=sys.stderr)
    return 0


def run_bench(args) -> int:
    from viewer.bench import run

    return run.run(args)


def run_view(args) -> int:
    from viewer import app

    return app.run(args)


def run_bake(args) -> int:
    """`bake SCENE --out FILE.npz [--dds FILE.dds]`: the numpy solver's converged grid, for other tools."""
    from viewer.bake import grid as baked
    from viewer.bake import dds

    settings = gi_settings(args)
    outputs = [(args.out, ".npz")] + ([(args.dds, ".dds")] if args.dds else [])
    for name, suffix in outputs:
        if Path(name).suffix.lower() != suffix:
            raise InputError(f"{name}: expected a {suffix} file")
        if not Path(name).resolve().parent.is_dir():
            raise InputError(f"{name}: folder {Path(name).parent} does not exist")
    scene_path = Path(args.scene)
    if scene_path.suffix and not scene_path.resolve().is_relative_to(Path(args.out).resolve().parent):
        print(f"bake: note: {args.scene} lies outside the folder of {args.out}; opening the grid will need "
              f"its scene beside it or below it", file=sys.stderr)
    start = time.perf_counter()
    scene = _load_scene(args)
    timings = Timings({"load": time.perf_counter() - start})
    with step("bake: solving the probe grid (the CPU solver)"):
        grid = baked.bake(scene, args.scene, settings, timings)
    texels = baked.texture_volumes(grid.indirect) if args.dds else None
    if texels is not None and args.dds_precision == "16":
        if np.abs(texels).max() > float(np.finfo(np.float16).max):
            raise InputError("--dds-precision 16: probe values beyond half-float range; use 32")
        texels = texels.astype(np.float16)
    baked.write_npz(grid, args.out)
    if texels is not None:
        dds.write_volume(args.dds, texels)
    print(f"bake: {args.out}{' and ' + args.dds if args.dds else ''} ({grid.radiance.resolution}^3 probes); "
          f"{timings}", file=sys.stderr)
    return 0

"""The command line: `python -m viewer [capture|sample|bake|bench] ...` (see docs/ARCHITECTURE.md).

Exit status 0 on success, 2 for bad input (one line on stderr, no traceback), 1 for an internal error.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

from viewer.bench.run import add_arguments as bench_arguments  # no GL, Mitsuba or matplotlib import
from viewer.capture import run_capture
from viewer.errors import ArgumentParser, InputError, exit_status
from viewer.physical.gi import GISettings, Timings
from viewer.ui.options import add_arguments as view_arguments  # no GL or imgui import


VIEWS = ("final", "direct", "indirect", "albedo", "normals", "voxels", "probes")
"""The renderer's view modes (viewer.gpu.renderer.VIEWS; listed here so parsing needs no GL)."""


def _gi_arguments(p: argparse.ArgumentParser):
    d = GISettings()
    p.add_argument("--voxels", type=int, default=d.voxels, help="voxels per axis (N)")
    p.add_argument("--probes", type=int, default=d.probes, help="probes per axis (M)")
    p.add_argument("--kernel", choices=("physical", "paper"), default=d.kernel, help="light transition kernel")
    p.add_argument("--bounces", type=int, default=d.bounces, help="most bounces summed")
    p.add_argument("--directions", type=int, default=d.directions, help="directions gathered per probe")
    p.add_argument("--dering", type=float, default=d.dering, help="SH deringing strength 0..1")
    p.add_argument("--normals", choices=("area", "paper"), default=d.normal_mode,
                   help="voxel normals: area-weighted, or the paper's eq. 3 (plain mean)")
    p.add_argument("--sun", help="directional light dx,dy,dz,r,g,b (direction towards the sun, irradiance)")
    p.add_argument("--model", help="the neural source's .onnx file (default: models/probenet.onnx)")


def gi_settings(args) -> GISettings:
    for name, low, high in (("voxels", 4, 256), ("probes", 2, 128), ("bounces", 0, 100000),
                            ("directions", 16, 65536)):
        value = getattr(args, name)
        if not low <= value <= high:
            raise InputError(f"--{name} {value}: must be between {low} and {high}")
    if not 0.0 <= args.dering <= 1.0:
        raise InputError(f"--dering {args.dering}: must be between 0 and 1")
    return GISettings(voxels=args.voxels, probes=args.probes, kernel=args.kernel, bounces=args.bounces,
                      directions=args.directions, dering=args.dering, normal_mode=args.normals)


def build_parser() -> argparse.ArgumentParser:
    parser = ArgumentParser(prog="python -m viewer", description="Real-time diffuse global illumination viewer.")
    sub = parser.add_subparsers(dest="command", parser_class=ArgumentParser)

    view = sub.add_parser("view", help="the interactive viewer (default)")
    view.add_argument("scene", nargs="?", default="cornell")
    view_arguments(view)

    sample = sub.add_parser("sample", help="incident-radiance SH at points, as the renderer sees it")
    sample.add_argument("scene", help="a built-in scene name or a scene file (.obj .glb .gltf .ply)")
    sample.add_argument("--points", required=True, help="(P, 3) float32 world points, .npy")
    sample.add_argument("--method", choices=("solver", "compute", "neural"), default="solver")
    sample.add_argument("--out", required=True, help="(P, 9, 3) float32 SH output, .npy")
    _gi_arguments(sample)

    capture = sub.add_parser("capture", help="render a PNG headless (EGL)")
    capture.add_argument("scene", nargs="?", default="cornell")
    capture.add_argument("--out", required=True, help="PNG file to write")
    capture.add_argument("--size", default="1280x720", help="WxH")
    capture.add_argument("--gi", choices=("off", "compute", "solver", "neural"), default="solver")
    capture.add_argument("--view", choices=VIEWS, default="final")
    capture.add_argument("--tonemap", choices=("aces", "reinhard", "none"), default="aces",
                         help="tone curve; `none` (clamp) for comparisons with Mitsuba")
    capture.add_argument("--msaa", type=int, default=4, help="multisample count")
    capture.add_argument("--light-samples", dest="light_samples", type=int, default=32,
                         help="shadowed points on the emitters for direct light")
    capture.add_argument("--voxel-color", dest="voxel_color", choices=("albedo", "radiance"), default="albedo",
                         help="colour of the voxels view")
    capture.add_argument("--camera", help="ox,oy,oz,tx,ty,tz")
    capture.add_argument("--fov", type=float, help="vertical field of view, degrees")
    capture.add_argument("--exposure", type=float, default=0.0, help="exposure in EV")
    _gi_arguments(capture)

    bake = sub.add_parser("bake", help="solve once and write the converged probe grid for other tools")
    bake.add_argument("scene", help="a built-in scene name or a scene file (.obj .glb .gltf .ply)")
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
    return exit_status(lambda: run_command(build_parser().parse_args(argv)))


def run_command(args) -> int:
    return {"view": run_view, "sample": run_sample, "capture": run_capture,
            "bench": run_bench, "bake": run_bake}[args.command](args)


def load_points(path: str) -> np.ndarray:
    file = Path(path)
    if not file.is_file():
        raise InputError(f"{path}: no such points file")
    try:
        points = np.load(file, allow_pickle=False)
    except Exception as exc:
        raise InputError(f"{path}: not a readable .npy array ({type(exc).__name__})") from None
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
    return scenes.load(args.scene, sun=sun)


def run_sample(args) -> int:
    from viewer.physical import gi
    from viewer.neural.domain import print_warning

    settings = gi_settings(args)
    points = load_points(args.points)
    out = Path(args.out)
    if out.parent and not out.parent.exists():
        raise InputError(f"{args.out}: folder {out.parent} does not exist")
    start = time.perf_counter()
    scene = _load_scene(args)
    timings = Timings({"load": time.perf_counter() - start})
    if args.method == "solver":
        grid = gi.solve(scene, settings, include_emitted=True, timings=timings)
    elif args.method == "compute":
        from viewer.gpu.compute_relight import solve_probes
        from viewer.gpu.context import create_context

        ctx = create_context()
        try:
            grid = solve_probes(ctx, scene, settings, include_emitted=True, timings=timings)
        finally:
            ctx.release()
    else:
        field = neural_field(args)
        grid = field.solve(scene, include_emitted=True, timings=timings.stages)
        print_warning(scene, field.card.domain)
    clock = time.perf_counter()
    sh = grid.interpolate(points).astype(np.float32)
    timings.stages["interpolate"] = time.perf_counter() - clock
    np.save(out, sh)
    print(f"sample {args.method}: {len(points)} points; {timings}", file=sys.stderr)
    return 0


def neural_field(args):
    """The model of `--model` (or the shipped one); a missing or broken model is bad input (exit 2)."""
    from viewer.neural.field import DEFAULT_MODEL, ModelError, NeuralField

    try:
        return NeuralField(getattr(args, "model", None) or DEFAULT_MODEL)
    except ModelError as exc:
        raise InputError(f"--method neural: {exc}") from None


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
    start = time.perf_counter()
    scene = _load_scene(args)
    timings = Timings({"load": time.perf_counter() - start})
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

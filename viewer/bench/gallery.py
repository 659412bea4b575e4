"""Gallery: our renderer next to Mitsuba 3 on the built-in scenes, with PSNR and relative difference.

    python -m viewer.bench.gallery [--size 256] [--spp 1024] [--gi compute neural] [--out docs/GALLERY.md]

For each scene and each of the viewer's two GI sources: the views final, direct, indirect and probes with
the viewer's default tone mapping (probes, indirect light only, from the compute solver at the GISettings
defaults or from the shipped network, models/probenet.onnx), and the final image from the same camera
path-traced by Mitsuba (`reference.render`, cached on disk). The comparison is made
on linear HDR radiance from both, through the one tone map below, never on the viewer's own ACES output.
"""

from __future__ import annotations

import os
import platform
import time
from pathlib import Path

import numpy as np

from viewer import sources
from viewer.evaluation.report import replace_block

ROOT = Path(__file__).resolve().parents[2]
SCENES = ("cornell", "paper-test")
SOURCES = (sources.COMPUTE.name, sources.NEURAL.name)
"""The viewer's GI sources the gallery renders (viewer.sources)."""
OLD_NAMES = {"physical": sources.COMPUTE.name}
"""`--gi physical` named the compute solver's probes here before the sources had one name each."""
VIEWS = ("final", "direct", "indirect", "probes")
MARKER = "<!-- gallery-table -->"


SUPERSAMPLE = 16
"""The final image Mitsuba's is compared with: 16 x 16 subpixel images averaged in linear light, the box
filter Mitsuba's 1024 samples a pixel have (`OffscreenRenderer.render_hdr`). A lamp's edge is hundreds of
times brighter than the ceiling beside it, and the multisampling's 4 samples a pixel (the window's) left
those pixels 37.4-37.6 dB off on the box scenes; 16 x 16 brings them to 41.6 dB."""


def to_srgb8(radiance: np.ndarray, exposure: float = 0.0) -> np.ndarray:
    """Linear radiance -> 8-bit sRGB: scale by 2^exposure, clamp to [0, 1], sRGB transfer function
    (IEC 61966-2-1), round. The same simple map for both images, like an 8-bit Mitsuba PNG."""
    x = np.clip(np.nan_to_num(radiance, nan=0.0, posinf=1.0) * 2.0 ** exposure, 0.0, 1.0)
    encoded = np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1 / 2.4) - 0.055)
    return np.round(255.0 * encoded).astype(np.uint8)


def psnr(image: np.ndarray, reference: np.ndarray, peak: float = 255.0) -> float:
    """10 log10(peak^2 / MSE) in dB over all pixels and channels (inf for identical images)."""
    mse = float(np.mean((image.astype(np.float64) - reference.astype(np.float64)) ** 2))
    return float("inf") if mse == 0.0 else 10.0 * np.log10(peak ** 2 / mse)


def mean_relative_difference(estimate: np.ndarray, truth: np.ndarray) -> float:
    """sum |est - ref| / sum ref over all pixels and channels of linear radiance: the mean absolute
    error relative to the mean radiance (robust to dark pixels, unlike a per-pixel ratio)."""
    return float(np.abs(estimate - truth).sum() / max(float(truth.sum()), 1e-12))


def side_by_side(left: np.ndarray, right: np.ndarray, gap: int = 4) -> np.ndarray:
    """Two (H, W, 3) uint8 images with a white gap between them."""
    spacer = np.full((left.shape[0], gap, 3), 255, np.uint8)
    return np.concatenate([left, spacer, right], axis=1)


def source_names(names) -> list[str]:
    """`--gi` names as a user may have typed them, under the sources' names (`physical` is `compute`)."""
    return [OLD_NAMES.get(name, name) for name in names]


def solve(ctx, scene, source: str):
    """The indirect-light probes the viewer's GI source `source` (SOURCES) gives the scene, at the
    GISettings defaults (the network: at its card's), on the gallery's GL context."""
    from viewer.physical.gi import GISettings

    options = sources.SolveOptions(include_emitted=False, ctx=ctx)
    return sources.lookup(source).solve(scene, GISettings(), options)[0]


def render_ours(ctx, scene, size: int, source: str = sources.COMPUTE.name) -> tuple[dict[str, np.ndarray], np.ndarray, float]:
    """The four views (uint8, default tone mapping), the linear HDR final image and the solve seconds."""
    from viewer.gpu.offscreen import OffscreenRenderer

    start = time.perf_counter()
    probes = solve(ctx, scene, source)
    solve_seconds = time.perf_counter() - start
    offscreen = OffscreenRenderer((size, size), ctx=ctx)
    try:
        offscreen.renderer.set_scene(scene)
        offscreen.renderer.set_probes(probes)
        views = {view: offscreen.render(view=view) for view in VIEWS}
        hdr = offscreen.render_hdr(view="final", supersample=SUPERSAMPLE)
    finally:
        offscreen.release()
    return views, hdr, solve_seconds


def image_stem(name: str, source: str) -> str:
    """`cornell` for the compute source (the names the docs have linked since the first gallery),
    `cornell-neural` for the network."""
    return name if source == SOURCES[0] else f"{name}-{source}"


def run_scene(ctx, name: str, size: int, spp: int, images: Path, sources=SOURCES) -> list[dict]:
    from PIL import Image

    from viewer.reference import mitsuba as reference
    from viewer import scene as scenes

    scene = scenes.load(name)
    name = scene.name   # a file's stem (`textured-point-room`), not its path: it names the images
    start = time.perf_counter()
    truth = reference.render(scene, scene.camera, size, size, spp)
    mitsuba_seconds = time.perf_counter() - start
    truth8 = to_srgb8(truth)
    rows = []
    for source in sources:
        views, ours, solve_seconds = render_ours(ctx, scene, size, source)
        ours8, stem = to_srgb8(ours), image_stem(name, source)
        for view, image in views.items():
            Image.fromarray(image).save(images / f"{stem}-{view}.png")
        Image.fromarray(side_by_side(ours8, truth8)).save(images / f"{stem}-vs-mitsuba.png")
        row = dict(scene=name, source=source, psnr=psnr(ours8, truth8),
                   relative=mean_relative_difference(ours, truth),
                   mean_ratio=float(ours.mean() / max(truth.mean(), 1e-12)), solve=solve_seconds,
                   mitsuba=mitsuba_seconds)
        print(f"{name:12s} {source:8s} PSNR {row['psnr']:5.2f} dB  mean rel. diff {row['relative']:.3f}  "
              f"mean ours/Mitsuba {row['mean_ratio']:.3f}  solve {solve_seconds:.1f} s  "
              f"Mitsuba {mitsuba_seconds:.1f} s", flush=True)
        rows.append(row)
    return rows


def machine(ctx) -> str:
    from viewer.reference import mitsuba as reference
    from viewer.gpu.context import describe

    return (f"{platform.system()} {platform.machine()}, {os.cpu_count()} CPU cores, {describe(ctx)}; "
            f"Mitsuba 3 `{reference.variant()}`")


def write_report(path: Path, rows: list[dict], args, host: str) -> None:
    """Replace the generated part between the two markers in `path` (the prose around it stays)."""
    relative = os.path.relpath(Path(args.images), path.parent)
    lines = [
        f"Generated by `python -m viewer.bench.gallery --size {args.size} --spp {args.spp} --gi "
        f"{' '.join(args.gi)}` on {host}.",
        f"Images {args.size}x{args.size}; Mitsuba path tracer at {args.spp} spp (box filter); ours "
        f"{SUPERSAMPLE} x {SUPERSAMPLE} subpixel images averaged in linear light (the same box filter; "
        "`capture --supersample`; the views below with the window's 4x MSAA), indirect-light probes from "
        "the compute solver at the GISettings defaults (`compute`) or from the shipped network, "
        "models/probenet.onnx (`neural`).",
        "",
        "| scene | GI | PSNR (8-bit sRGB) | mean rel. diff (linear) | mean ours / Mitsuba | probe solve s | Mitsuba s |",
        "|---|---|---|---|---|---|---|",
    ]
    lines += [f"| {r['scene']} | {r['source']} | {r['psnr']:.2f} dB | {r['relative']:.3f} | {r['mean_ratio']:.3f} | "
              f"{r['solve']:.1f} | {r['mitsuba']:.1f} |" for r in rows]
    lines.append("")
    lines.append("(Mitsuba seconds near 0 mean a cache hit.)")
    for r in rows:
        name, stem = r["scene"], image_stem(r["scene"], r["source"])
        lines += ["", f"### {name}, {r['source']} GI", "",
                  "Ours (left) and Mitsuba (right), both clamped and sRGB-encoded the same way:", "",
                  f"![{name}, {r['source']}: ours vs Mitsuba]({relative}/{stem}-vs-mitsuba.png)", "",
                  "Our views with the default tone mapping (ACES): " + ", ".join(VIEWS) + ".", "",
                  " ".join(f"![{name} {r['source']} {v}]({relative}/{stem}-{v}.png)" for v in VIEWS)]
    replace_block(path, MARKER, "\n".join(lines), "# Gallery")


def main(argv=None) -> int:
    from viewer.cli_parsing import tool_parser

    parser = tool_parser(__doc__)
    parser.add_argument("--size", type=int, default=256, help="image width and height in pixels")
    parser.add_argument("--spp", type=int, default=1024, help="Mitsuba samples per pixel (1024: the reference's own noise stays well below the differences measured)")
    parser.add_argument("--scenes", nargs="+", default=list(SCENES))
    parser.add_argument("--gi", nargs="+", choices=(*SOURCES, *OLD_NAMES), default=list(SOURCES),
                        help="the GI sources to render (default: both)")
    parser.add_argument("--out", default=str(ROOT / "docs" / "GALLERY.md"))
    parser.add_argument("--images", default=str(ROOT / "docs" / "images" / "gallery"))
    args = parser.parse_args(argv)
    args.gi = source_names(args.gi)
    from viewer.gpu.context import create_context

    images = Path(args.images)
    images.mkdir(parents=True, exist_ok=True)
    ctx = create_context()
    try:
        rows = [row for name in args.scenes for row in run_scene(ctx, name, args.size, args.spp, images, args.gi)]
        host = machine(ctx)
    finally:
        ctx.release()
    write_report(Path(args.out), rows, args, host)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

"""Soak: hours of use in minutes, watching what the process holds after every step.

    python -m viewer.bench.soak [--steps N] [--parts scenes,solves,lamp,drops] [--sources compute,solver,neural]
                                [--voxels 16] [--probes 8] [--resident] [--write]

Parts, each N steps after which resident memory (VmRSS) and the live GL objects (by kind) are printed:
- `scenes`: for each GI source, load one scene file after another into the viewer (headless, as a drop
  does: viewer/bench/headless.py) and wait until its indirect light has converged and been drawn;
- `solves`: one blocking compute-shader solve after another (compute_relight.solve_probes: what
  `python -m viewer sample --method compute`, `capture --gi compute` and the benchmarks run);
- `lamp`: move the lamp a little every frame with the compute solver running, N frames, then settle;
- `drops`: drop files into the real window under Xvfb, good and bad by turns (viewer/bench/soak_window.py).

The scenes are the built-in Cornell box, paper-test and, where ../shared/scenes has it, the public
CornellBox-Original. A part's growth is its last step against its step `--warmup` (allocators and
caches fill during the first steps). Memory is read after glibc has handed its free heap memory back
(viewer/memory.py): what something still holds, which is what a leak grows; `--resident` reads it as
it is, what a user sees, allocator wobble of tens of MB included. `--write` puts the table into
docs/STABILITY.md; tests/bench/test_soak.py holds what must hold.
"""

from __future__ import annotations

import os
import sys
import tempfile
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from viewer import sources as gi_sources
from viewer.evaluation.report import replace_block
from viewer.physical.gi import GISettings
from viewer.memory import Usage, children_mb
from viewer.scene import ASSETS

ROOT = Path(__file__).resolve().parents[2]
PUBLIC_BOX = ROOT.parent / "shared" / "scenes" / "cornellbox-original" / "CornellBox-Original.obj"
PARTS = ("scenes", "solves", "lamp", "drops")
MARKER = "<!-- stability-soak -->"


def scene_files() -> list[Path]:
    """The scenes the soak cycles through."""
    files = [ASSETS / "cornell.obj", ASSETS / "paper-test.obj"]
    return files + [PUBLIC_BOX] if PUBLIC_BOX.is_file() else files


@dataclass(frozen=True)
class SoakSettings:
    steps: int = 30
    """N: scenes per GI source, solves, lamp frames and dropped files."""
    warmup: int = 5
    """Steps before the one growth is measured from."""
    sources: tuple[str, ...] = gi_sources.solving()
    """GI sources the `scenes` part runs, one after another (viewer.sources: those that solve)."""
    voxels: int = 16
    probes: int = 8
    directions: int = 128
    held: bool = True
    """Hand free heap memory back before every reading: resident memory is then what is held."""

    @property
    def gi(self) -> GISettings:
        return GISettings(voxels=self.voxels, probes=self.probes, directions=self.directions)


@dataclass
class Step:
    part: str
    source: str
    step: int
    label: str
    usage: Usage

    def line(self) -> str:
        return f"{self.part:7s} {self.source:8s} {self.step:4d}  {self.label:24.24s} {self.usage}"


@dataclass
class Soak:
    settings: SoakSettings
    steps: list[Step] = field(default_factory=list)

    def record(self, part: str, source: str, step: int, label: str, usage: Usage) -> None:
        self.steps.append(Step(part, source, step, label, usage))
        print(self.steps[-1].line(), flush=True)


# ---- the parts ---------------------------------------------------------------------------------------

def soak_scenes(soak: Soak, source: str) -> None:
    """Load the scenes one after another with `source` giving the indirect light, each one solved."""
    from viewer.bench.headless import HeadlessViewer

    s, files = soak.settings, scene_files()
    viewer = HeadlessViewer(source, s.gi)
    try:
        if viewer.gi.source != source:
            print(f"scenes  {source}: not available here ({viewer.gi.unavailable.get(source, '')})", flush=True)
            return
        viewer.settle()
        for step in range(1, s.steps + 1):
            viewer.load(files[step % len(files)])
            soak.record("scenes", source, step, viewer.session.name, viewer.usage(s.held))
            if source == gi_sources.SOLVER.name:   # its solves run in a worker process: that one's memory too
                soak.record("scenes", f"{source} worker", step, viewer.session.name, Usage(children_mb()))
    finally:
        viewer.release()


def soak_solves(soak: Soak) -> None:
    """Blocking compute-shader solves, one after another, on one context."""
    from viewer.gpu.compute_relight import solve_probes
    from viewer.gpu.context import create_context
    from viewer.gpu.gl_objects import watch
    from viewer.scene import load

    s = soak.settings
    scenes = [load(path) for path in scene_files()]
    ctx = create_context()
    watch(ctx)
    try:
        for step in range(1, s.steps + 1):
            scene = scenes[step % len(scenes)]
            solve_probes(ctx, scene, s.gi, include_emitted=False)
            soak.record("solves", "compute", step, scene.name, Usage.measure(ctx, s.held))
    finally:
        ctx.release()


def soak_lamp(soak: Soak) -> None:
    """The lamp moved a little every frame (as a dragged slider moves it), the compute solver on."""
    from viewer.bench.headless import HeadlessViewer

    s = soak.settings
    viewer = HeadlessViewer("compute", s.gi)
    try:
        viewer.settle()
        size = viewer.session.scene_size
        for step in range(1, s.steps + 1):
            angle = 2.0 * np.pi * step / s.steps
            viewer.session.edits.set_light(offset=(0.15 * size * np.cos(angle), 0.0, 0.15 * size * np.sin(angle)))
            viewer.frame()
            soak.record("lamp", "compute", step, f"frame {viewer.frames}", viewer.usage(s.held))
        viewer.settle()
        soak.record("lamp", "compute", s.steps + 1, "settled", viewer.usage(s.held))
    finally:
        viewer.release()


def soak_drops(soak: Soak) -> None:
    from viewer.bench.soak_window import drop_files

    s = soak.settings
    with tempfile.TemporaryDirectory(prefix="viewer-soak-") as folder:
        for step, label, usage in drop_files(Path(folder), scene_files(), s.steps, s.gi, held=s.held):
            soak.record("drops", "compute", step, label, usage)


# ---- the report --------------------------------------------------------------------------------------

def summary(soak: Soak) -> list[dict]:
    """Per part and source: memory and GL objects after the warm-up step and at the end, and the most
    memory from the warm-up step on."""
    rows = []
    groups: dict[tuple[str, str], list[Step]] = {}
    for step in soak.steps:
        groups.setdefault((step.part, step.source), []).append(step)
    for (part, source), steps in groups.items():
        base = next((x for x in steps if x.step == soak.settings.warmup), steps[0])
        end = steps[-1]
        rss = [x.usage.rss_mb for x in steps if x.step >= base.step]
        rows.append(dict(part=part, source=source, steps=end.step, base=base.step, rss_base=base.usage.rss_mb,
                         rss_end=end.usage.rss_mb, rss_max=max(rss), gl_base=base.usage.gl_total,
                         gl_end=end.usage.gl_total))
    return rows


def table(rows: list[dict]) -> str:
    lines = ["| part | GI source | steps | MB after step (warm-up) | MB at the end | growth MB | most MB | "
             "GL objects after warm-up | at the end | growth |", "|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r['part']} | {r['source']} | {r['steps']} | {r['rss_base']:.1f} ({r['base']}) | "
                     f"{r['rss_end']:.1f} | {r['rss_end'] - r['rss_base']:+.1f} | {r['rss_max']:.1f} | "
                     f"{r['gl_base']} | {r['gl_end']} | {r['gl_end'] - r['gl_base']:+d} |")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    from viewer.cli_parsing import add_write, tool_parser

    parser = tool_parser(__doc__, prog="python -m viewer.bench.soak")
    d = SoakSettings()
    parser.add_argument("--steps", type=int, default=d.steps, help="N: steps per part (and per GI source)")
    parser.add_argument("--warmup", type=int, default=d.warmup, help="growth is measured from this step on")
    parser.add_argument("--parts", default=",".join(PARTS), help=f"comma-separated, of {', '.join(PARTS)}")
    parser.add_argument("--sources", default=",".join(d.sources), help="GI sources of the scenes part")
    parser.add_argument("--voxels", type=int, default=d.voxels)
    parser.add_argument("--probes", type=int, default=d.probes)
    parser.add_argument("--directions", type=int, default=d.directions)
    parser.add_argument("--resident", action="store_true",
                        help="read resident memory as it is (default: after free heap memory is handed back)")
    add_write(parser, "put the table into docs/STABILITY.md")
    args = parser.parse_args(argv)
    parts = [p for p in args.parts.split(",") if p]
    unknown = set(parts) - set(PARTS)
    if unknown or args.steps < 1:
        print(f"error: unknown part(s) {', '.join(sorted(unknown))}" if unknown else "error: --steps must be >= 1",
              file=sys.stderr)
        return 2
    settings = SoakSettings(steps=args.steps, warmup=min(args.warmup, args.steps),
                            sources=tuple(gi_sources.renamed(s) for s in args.sources.split(",") if s), voxels=args.voxels,
                            probes=args.probes, directions=args.directions, held=not args.resident)
    soak = Soak(settings)
    print(f"soak: {settings}; load average {os.getloadavg()[0]:.1f}", flush=True)
    for part in parts:
        if part == "scenes":
            for source in settings.sources:
                soak_scenes(soak, source)
        else:
            {"solves": soak_solves, "lamp": soak_lamp, "drops": soak_drops}[part](soak)
    text = table(summary(soak))
    print(text)
    if args.write:
        command = "python -m viewer.bench.soak " + " ".join(sys.argv[1:] if argv is None else argv)
        memory = "memory held" if settings.held else "resident memory as it is"
        block = (f"Generated by `{command.strip()}` ({settings.voxels}^3 voxels, {settings.probes}^3 probes, "
                 f"{settings.directions} directions; {memory}).\n\n" + text)
        replace_block(ROOT / "docs" / "STABILITY.md", MARKER, block, "# Stability")
        print("wrote docs/STABILITY.md")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

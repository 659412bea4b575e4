"""From a scene file dropped on the viewer to its GI on screen, moment by moment, with the memory at each:
the figure for scenes past the box's size (the scanned-mesh rooms of viewer/bench/scans.py).

    python -m viewer.bench.open_times [SCENE ...] [--sources compute neural] [--repeats 3] [--write]

The viewer runs headless as viewer/bench/edits.py runs it (the window's pieces stepped a frame at a time,
at the window's pace, the lightmap's weights and rays on their worker). Each scene is dropped on the
viewer while it shows another one (`--before`, the paper's test room: so the Cornell box is a new scene
too), `repeats` times after one untimed warm-up, and timed from the drop to:

- probes: the file is read and the GI source's final probes are in;
- first frame: the first full-resolution frame drawn with them (with the probes read per fragment
  while the lightmap's gather rays and weights are made);
- settled: the lightmap gathered from them and drawn.

At each moment, the process's resident memory (VmRSS); and at the end, its peak over the source's run
(getrusage: every scene opened in that process counts). Each source runs in a process of its own. The median of the repeats is shown, and each
scene's settled time over the first scene's (the box, by default). `--write` puts the table into
docs/PERFORMANCE.md.
"""

from __future__ import annotations

import multiprocessing
import os
import resource
import statistics
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

from viewer import sources as gi_sources
from viewer.evaluation.report import show_table
from viewer.memory import resident_mb

MARKER = "<!-- bench-open-times -->"
MOMENTS = ("probes", "first frame", "settled")


def open_once(viewer, path: Path) -> dict[str, tuple[float, float]]:
    """Drop `path` on the viewer and step it until settled: moment -> (seconds from the drop, MiB resident
    then)."""
    start = time.perf_counter()
    viewer.edited()
    viewer.session.load_file(path)
    loads, errors, seen = viewer.session.loads, viewer.session.load_errors, {}
    viewer.step()
    while "settled" not in seen:
        now = time.perf_counter()
        session = viewer.session
        if session.load_errors > errors:
            raise RuntimeError(f"{path}: the viewer could not open it: {viewer.log[-1] if viewer.log else ''}")
        if session.loads > loads and not session.busy:
            for moment, done in (("probes", True), ("first frame", viewer.viewport.drawn),
                                 ("settled", viewer.settled)):
                if done and moment not in seen:
                    seen[moment] = (now - start, resident_mb(os.getpid()))
        if now - start > viewer.timeout:
            raise TimeoutError(f"{path}: not settled after {viewer.timeout:.0f} s")
        if "settled" not in seen:
            viewer.step()
    return seen


def time_opens(source: str, scenes: list[Path], before: Path, repeats: int) -> dict:
    """scene -> moment -> [(seconds, MiB), ...] for one GI source, and "peak" -> MiB."""
    from viewer.bench.headless import HeadlessViewer
    from viewer.physical.gi import GISettings

    viewer = HeadlessViewer(source, GISettings(), before)
    viewer.renderer.background_bake = True
    results: dict = {}
    try:
        viewer.settle()
        for step in range(repeats + 1):
            for scene in scenes:
                viewer.load(before)          # the scene shown when the file is dropped
                times = open_once(viewer, scene)
                if step:                     # the first round is a warm-up (compiles, caches)
                    for moment, value in times.items():
                        results.setdefault(str(scene), {}).setdefault(moment, []).append(value)
        for scene, moments in results.items():
            cells = ", ".join(f"{m} {1000 * statistics.median(t for t, _ in v):.0f} ms" for m, v in moments.items())
            print(f"{source:7s} {Path(scene).stem:20s} {cells}", flush=True)
    finally:
        viewer.release()
    results["peak"] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
    return results


def table(results: dict[str, dict], scenes: list[Path], repeats: int, command: str) -> str:
    from viewer.scene import load

    load_average = os.getloadavg()[0]
    lines = [f"`{command}`, {time.strftime('%Y-%m-%d')}, {os.cpu_count()} cores, 1-minute load {load_average:.1f} "
             f"when written; median of {repeats} opens, milliseconds from the drop (MiB resident then); the "
             "last column: settled over the first scene's settled, in the same run; peak: the process's "
             "resident peak over the source's whole run:", "",
             "| GI source | scene | triangles | probes | first frame | settled | settled / first scene's |",
             "|---|---|---|---|---|---|---|"]
    triangles = {str(s): len(load(s).faces) for s in scenes}
    for source, runs in results.items():
        first = statistics.median(t for t, _ in runs[str(scenes[0])]["settled"])
        for scene in scenes:
            moments = runs[str(scene)]
            cells = [f"{1000 * statistics.median(t for t, _ in moments[m]):.0f} "
                     f"({statistics.median(mb for _, mb in moments[m]):.0f})" for m in MOMENTS]
            ratio = statistics.median(t for t, _ in moments["settled"]) / first
            lines.append(f"| {source} | {scene.stem} | {triangles[str(scene)]:,} | " + " | ".join(cells)
                         + f" | {ratio:.1f}x |")
        lines.append(f"| {source} | peak | | | | {runs['peak']:.0f} MiB | |")
    return "\n".join(lines)


def main(argv=None) -> int:
    from viewer.cli_parsing import add_repeats, add_scenes, add_write, tool_parser
    from viewer.scene import scene_file

    parser = tool_parser(__doc__, prog="python -m viewer.bench.open_times")
    add_scenes(parser, default=("cornell",), help="scene names or files; the first is what the others are "
                                                  "compared with")
    parser.add_argument("--before", default="paper-test", help="the scene shown when each file is dropped")
    parser.add_argument("--sources", nargs="+", default=[gi_sources.COMPUTE.name, gi_sources.NEURAL.name],
                        choices=gi_sources.solving())
    add_repeats(parser, 3)
    add_write(parser, "put the table into docs/PERFORMANCE.md")
    args = parser.parse_args(argv)
    scenes = [scene_file(name) for name in args.scenes]
    results = {}
    for source in args.sources:   # each in a process of its own: its memory is its own
        with ProcessPoolExecutor(1, mp_context=multiprocessing.get_context("spawn")) as pool:
            results[source] = pool.submit(time_opens, source, scenes, scene_file(args.before), args.repeats).result()
    command = "python -m viewer.bench.open_times " + " ".join(args.scenes) + f" --repeats {args.repeats} --write"
    text = table(results, scenes, args.repeats, command)
    show_table(text, MARKER, args.write)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

"""Edit to converged GI on screen, through the viewer itself: the number the product is judged by.

    python -m viewer.bench.edits [SCENE] [--sources compute neural] [--repeats 5] [--write]

The viewer runs headless (viewer/bench/headless.py: Session, GIController, Renderer and Viewport stepped
a frame at a time as the window steps them, with the window's rests between frames, each frame finished
as the window's buffer swap finishes it, the renderer's lightmap weights on their background worker as in
the window). For each GI source, each edit is made the way the panels make it (SceneEdits) and
timed until the viewer has settled: the GI source's probes are in, the renderer's indirect lightmap
(its probe weights and final gather) is baked from them and the full-resolution frame is drawn; and
until the first full-resolution frame with the source's final probes, which on new geometry shows them
per fragment (a new scene) or gathered with the old geometry's rays (a lamp moved) while the renderer
makes the new geometry's weights and rays on its worker. Edits:

- `albedo`: the largest material group's colour (between two colours, so every edit changes it);
- `light colour`: the lamp's colour;
- `lamp move`: the lamp moved by 5% of the scene's size (back and forth);
- `object move`: the panel's object (at first the largest group that does not emit: a scan, a box) moved
  as far (back and forth);
- `new scene`: another scene file opened (voxelizing and everything after it).

Medians of `repeats` edits after one untimed warm-up of each. `--write` puts the table into
docs/PERFORMANCE.md.
"""

from __future__ import annotations

import os
import statistics
import time
from pathlib import Path

import numpy as np

from viewer import sources as gi_sources
from viewer.evaluation.report import show_table

MARKER = "<!-- bench-edits -->"
EDITS = ("albedo", "light colour", "lamp move", "object move", "new scene")


def largest_group(viewer) -> str:
    scene = viewer.session.scene
    groups = viewer.session.edits.material_groups
    area = np.bincount(scene.face_group, weights=scene.face_areas, minlength=len(scene.groups))
    return max(groups, key=lambda g: area[scene.group_index(g)])


def make_edit(viewer, edit: str, step: int, other_scene: Path) -> None:
    """Make edit number `step` of its kind (alternating between two states, so each one changes the scene)."""
    viewer.edited()
    session = viewer.session
    if edit == "albedo":
        session.edits.set_albedo(largest_group(viewer), (0.8, 0.5, 0.3) if step % 2 else (0.5, 0.7, 0.8))
    elif edit == "light colour":
        session.edits.set_light(colour=(1.0, 0.8, 0.6) if step % 2 else (0.7, 0.85, 1.0))
    elif edit == "lamp move":
        session.edits.set_light(offset=_back_and_forth(session.scene, 2, -1.0, step))
    elif edit == "object move":
        session.edits.set_offset(session.edits.selected, _back_and_forth(session.scene, 0, 1.0, step))
    elif edit == "new scene":
        session.load_file(other_scene if step % 2 else viewer.scene_path)
    else:
        raise ValueError(edit)


def _back_and_forth(scene, axis: int, sign: float, step: int) -> np.ndarray:
    """An offset of 5% of the scene's size along `axis` (times `sign`) on odd steps, none on even ones."""
    lo, hi = scene.bounds
    offset = np.zeros(3)
    offset[axis] = sign * 0.05 * float(np.max(hi - lo)) * (step % 2)
    return offset


def settle(viewer, start: float) -> tuple[float, float]:
    """Frames until the viewer has settled: (seconds to the first full-resolution frame with the GI
    source done, seconds to settled), both from `start`."""
    first = None
    viewer.step()
    while True:
        now = time.perf_counter()
        if first is None and not viewer.session.busy and viewer.viewport.drawn:
            first = now - start
        if viewer.settled:
            return first, now - start
        if now - start > viewer.timeout:
            raise TimeoutError(f"not settled after {viewer.timeout:.0f} s")
        viewer.step()


def time_edits(source: str, scene: str, other: str, repeats: int, edits=EDITS) -> dict[str, list[tuple]]:
    from viewer.bench.headless import HeadlessViewer
    from viewer.physical.gi import GISettings
    from viewer.scene import scene_file

    viewer = HeadlessViewer(source, GISettings(), scene)
    viewer.renderer.background_bake = True
    viewer.scene_path = scene_file(scene)
    seconds: dict[str, list[tuple]] = {}
    try:
        viewer.settle()
        for edit in edits:
            times = []
            for step in range(repeats + 1):
                start = time.perf_counter()
                make_edit(viewer, edit, step + 1, scene_file(other))
                first, settled = settle(viewer, start)
                if step:   # the first is a warm-up (compiles, caches)
                    times.append((first, settled))
            if edit == "new scene" and repeats % 2 == 0:   # back to the scene the others edit
                viewer.load(viewer.scene_path)
            seconds[edit] = times
            print(f"{source:7s} {edit:12s} median first frame {1000 * statistics.median(t[0] for t in times):7.1f} ms, "
                  f"settled {1000 * statistics.median(t[1] for t in times):7.1f} ms  "
                  f"({', '.join(f'{1000 * t[1]:.0f}' for t in times)})", flush=True)
    finally:
        viewer.release()
    return seconds


def table(results: dict[str, dict[str, list[float]]], scene: str, repeats: int) -> str:
    load = os.getloadavg()[0]
    lines = [f"`python -m viewer.bench.edits {scene} --repeats {repeats} --write`, {time.strftime('%Y-%m-%d')}, "
             f"{os.cpu_count()} cores, 1-minute load {load:.1f} when written; median of {repeats} edits, "
             "milliseconds from the edit to the first full-resolution frame with the GI source's final probes / "
             "to the settled frame (the renderer's indirect lightmap baked from them, the new geometry's "
             "weights and gather rays made):",
             "", "| GI source | " + " | ".join(EDITS) + " |", "|---" * (len(EDITS) + 1) + "|"]
    for source, seconds in results.items():
        cells = [f"{1000 * statistics.median(t[0] for t in seconds[e]):.0f} / "
                 f"{1000 * statistics.median(t[1] for t in seconds[e]):.0f}" if e in seconds else "" for e in EDITS]
        lines.append(f"| {source} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def main(argv=None) -> int:
    from viewer.cli_parsing import add_repeats, add_write, tool_parser

    parser = tool_parser(__doc__, prog="python -m viewer.bench.edits")
    parser.add_argument("scene", nargs="?", default="cornell")
    parser.add_argument("--other", default="paper-test", help="the scene `new scene` opens (by turns with SCENE)")
    parser.add_argument("--sources", nargs="+", default=[gi_sources.COMPUTE.name, gi_sources.NEURAL.name],
                        choices=gi_sources.solving())
    parser.add_argument("--edits", nargs="+", default=list(EDITS), choices=EDITS)
    add_repeats(parser, 5)
    add_write(parser, "put the table into docs/PERFORMANCE.md")
    args = parser.parse_args(argv)
    results = {source: time_edits(source, args.scene, args.other, args.repeats, args.edits)
               for source in args.sources}
    text = table(results, args.scene, args.repeats)
    show_table(text, MARKER, args.write)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

"""`python -m viewer bench [SCENES...]`: every method's time and error against Mitsuba, as CSV, charts
and docs/BENCHMARK.md.

For every scene and every method of `viewer.bench.method_table.registry()`: the milliseconds to produce the GI
from the loaded scene (median of 3 runs; one run for methods over SLOW_SECONDS), the relative RMSE of its
incident-radiance SH against a high-sample Mitsuba reference at free-space points, and the memory the
renderer keeps (probe textures, model). One CSV row per (scene, method, setting), appended as soon as it
is measured: an interrupted run starts again where it stopped. Then the charts (viewer.bench.pareto) and
the generated parts of the report.

    python -m viewer bench                      the built-in scenes and the public Cornell box (~an hour)
    python -m viewer bench assets/ my.glb       the scene files of a folder, a file
    python -m viewer bench --quick              one scene, a handful of methods (CI, under a minute)
    python -m viewer bench --charts-only        charts and report from the CSV as it stands
"""

from __future__ import annotations

import argparse
import csv
import fnmatch
import os
import statistics
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from viewer.errors import ArgumentParser, InputError, exit_status
from viewer.progress import bar

ROOT = Path(__file__).resolve().parents[2]
SLOW_SECONDS = 10.0
"""A method whose first run takes longer than this runs once; faster ones run three times (median). On an
idle machine a 10 s solve varies by a few percent between runs, little beside the four decades of the
chart's time axis, and the full benchmark fits in an hour; load on the machine moves it far more (each
row records it)."""
REPEATS = 3
POINTS, POINTS_SEED, MARGIN, REFERENCE_DIRECTIONS = 500, 1, 0.06, 4096
"""The evaluation points and reference of docs/ACCURACY.md (so the cached Mitsuba results are shared)."""
COLUMNS = ("scene", "method", "setting", "field", "ms", "cpu_ms", "repeats", "relative_rmse", "texture_bytes",
           "model_bytes", "memory_bytes", "load_average", "measured")
"""CSV columns. ms: wall clock, what a user waits. cpu_ms: CPU time of every thread of the process over
the same runs (median): it does not grow when other jobs share the cores or stop this one, so where the
two disagree by more than the method's threads (llvmpipe and Mitsuba use every core, numpy mostly one)
the machine was busy. load_average: the 1-minute load when the row was measured."""
QUICK_SCENES = ("cornell",)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("scenes", nargs="*", metavar="SCENE",
                        help="built-in names, scene files or folders of them (default: the built-ins and "
                             "the public CornellBox-Original)")
    parser.add_argument("--quick", action="store_true",
                        help="one scene, a handful of methods (CI); writes under out/bench-quick unless --out")
    parser.add_argument("--out", type=Path,
                        help="folder for data/benchmark.csv, images/ and BENCHMARK.md (default: docs/)")
    parser.add_argument("--only", action="append", metavar="PATTERN",
                        help="methods whose name (family:setting) matches this glob, e.g. 'compute:*' (repeatable)")
    parser.add_argument("--list", action="store_true", help="list the methods and exit")
    parser.add_argument("--charts-only", dest="charts_only", action="store_true",
                        help="measure nothing: charts and report from the CSV")
    parser.add_argument("--again", action="store_true",
                        help="measure the selected methods on these scenes again (their rows are replaced)")
    parser.add_argument("--stability", action="store_true",
                        help="run the stability suite first (python -m viewer.bench.stability: an hour or "
                             "more), so that one command regenerates docs/BENCHMARK.md and docs/STABILITY.md")


@dataclass(frozen=True)
class Paths:
    csv: Path
    images: Path
    report: Path

    @staticmethod
    def under(folder: Path) -> "Paths":
        return Paths(folder / "data" / "benchmark.csv", folder / "images", folder / "BENCHMARK.md")


def scene_sources(names: list[str], quick: bool) -> list[str]:
    """Scene arguments -> sources for viewer.scene.load (a folder gives its scene files, sorted)."""
    from viewer.evaluation.error import benchmark_scenes
    from viewer.scene import SUPPORTED_SUFFIXES, builtin_names

    if not names:
        if quick:
            return list(QUICK_SCENES)
        first = benchmark_scenes()
        return first + [n for n in builtin_names() if n not in first]
    sources = []
    for name in names:
        path = Path(name)
        if path.is_dir():
            found = sorted(str(p) for p in path.iterdir() if p.suffix.lower() in SUPPORTED_SUFFIXES)
            if not found:
                raise InputError(f"{name}: no scene files ({', '.join(SUPPORTED_SUFFIXES)}) in this folder")
            sources += found
        else:
            sources.append(name)
    return sources


# ---- the CSV ----------------------------------------------------------------------------------------

def read_rows(path: Path) -> list[dict]:
    """The CSV's rows, a method named before the GI sources had one name each under its name now (the CPU
    solver's `numpy` rows read as `solver`): a run finds them measured, the charts draw them as one."""
    from viewer.sources import renamed

    if not path.exists():
        return []
    with open(path, newline="") as fh:
        return [{**row, "method": renamed(row["method"])} for row in csv.DictReader(fh)]


def upgrade(path: Path) -> None:
    """Rewrite a CSV written with fewer columns under today's header (missing values empty)."""
    if not path.exists():
        return
    with open(path, newline="") as fh:
        header = next(csv.reader(fh), [])
    if tuple(header) == COLUMNS:
        return
    write_rows(path, read_rows(path))


def write_rows(path: Path, rows: list[dict]) -> None:
    """The whole CSV anew under today's header (values a row lacks stay empty)."""
    with open(path, "w", newline="") as fh:
        writer = csv.DictWriter(fh, COLUMNS, extrasaction="ignore")
        writer.writeheader()
        writer.writerows({c: r.get(c, "") for c in COLUMNS} for r in rows)


def append_row(path: Path, row: dict) -> None:
    """One row, written and flushed at once (an interrupted run keeps everything it measured)."""
    new = not path.exists()
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "a", newline="") as fh:
        writer = csv.DictWriter(fh, COLUMNS)
        if new:
            writer.writeheader()
        writer.writerow(row)


def key(row: dict) -> tuple[str, str, str]:
    return row["scene"], row["method"], row["setting"]


def forget(path: Path, scenes: list[str], methods: dict) -> int:
    """Drop the rows of these methods on these scenes (for --again); returns how many went."""
    names = {(m.family, m.setting) for m in methods.values()}
    rows = read_rows(path)
    kept = [r for r in rows if not (r["scene"] in scenes and (r["method"], r["setting"]) in names)]
    write_rows(path, kept)
    return len(rows) - len(kept)


# ---- measuring ----------------------------------------------------------------------------------------

def measure(produce, scene, points, truth) -> tuple[float, float, int, float]:
    """Median wall and CPU milliseconds, repeats, and mean relative RMSE (Mitsuba's estimates differ from
    run to run)."""
    from viewer.bench.accuracy import relative_rmse
    from viewer.probes.grid import ProbeGrid

    seconds, cpu, errors = [], [], []
    before = getattr(produce, "before", None)   # untimed set-up before each run (an edit's other side)
    while len(seconds) < (1 if seconds and seconds[0] > SLOW_SECONDS else REPEATS):
        if before is not None:
            before(scene)
        clock, cpu_clock = time.perf_counter(), time.process_time()
        result = produce(scene, points)
        seconds.append(time.perf_counter() - clock)
        cpu.append(time.process_time() - cpu_clock)
        estimate = result.interpolate(points) if isinstance(result, ProbeGrid) else result
        errors.append(relative_rmse(np.asarray(estimate, np.float64), truth))
    return (1000.0 * statistics.median(seconds), 1000.0 * statistics.median(cpu), len(seconds),
            float(np.mean(errors)))


def run_benchmark(sources: list[str], methods: dict, paths: Paths) -> list[str]:
    """Measure every (scene, method) not yet in the CSV; returns notes (skipped methods)."""
    from viewer.reference import mitsuba as reference
    from viewer import scene as scenes
    from viewer.bench.methods import MethodUnavailable
    from viewer.evaluation.points import free_space_points

    upgrade(paths.csv)
    done = {key(r) for r in read_rows(paths.csv)}
    loaded = [scenes.load(s) for s in sources]
    todo = [(scene, m) for scene in loaded for m in methods.values() if (scene.name, m.family, m.setting) not in done]
    print(f"bench: {len(loaded)} scenes x {len(methods)} methods, {len(todo)} to measure "
          f"({len(loaded) * len(methods) - len(todo)} already in {paths.csv})", file=sys.stderr, flush=True)
    progress = bar(len(todo), "measurement", "bench")
    producers, notes = {}, []
    for scene in loaded:
        pending = [m for s, m in todo if s is scene]
        if not pending:
            continue
        points = free_space_points(scene, POINTS, margin=MARGIN, seed=POINTS_SEED)
        truth = reference.probe_sh(scene, points, directions=REFERENCE_DIRECTIONS).astype(np.float64)
        for method in pending:
            if method.name not in producers:
                try:
                    producers[method.name] = method.prepare()
                except MethodUnavailable as exc:
                    producers[method.name] = None
                    notes.append(f"`{method.name}` skipped: {exc}")
            if producers[method.name] is None:
                progress.write(f"{scene.name} {method.name}: skipped")
                progress.update(1)
                continue
            ms, cpu_ms, repeats, error = measure(producers[method.name], scene, points, truth)
            append_row(paths.csv, {
                "scene": scene.name, "method": method.family, "setting": method.setting, "field": int(method.field),
                "ms": f"{ms:.1f}", "cpu_ms": f"{cpu_ms:.1f}", "repeats": repeats, "relative_rmse": f"{error:.5f}",
                "texture_bytes": method.texture_bytes, "model_bytes": method.model_bytes,
                "memory_bytes": method.memory_bytes, "load_average": f"{os.getloadavg()[0]:.2f}",
                "measured": time.strftime("%Y-%m-%d %H:%M:%S")})
            progress.write(f"{scene.name} {method.name}: {ms:.0f} ms (CPU {cpu_ms:.0f}, x{repeats}), "
                           f"rel. RMSE {error:.3f}")
            progress.update(1)
    progress.close()
    return notes


def select(methods: dict, patterns: list[str] | None) -> dict:
    """The methods whose name matches one of the globs; a glob may name a source by its old name
    (`numpy:*` is `solver:*`)."""
    from viewer.sources import renamed

    if not patterns:
        return methods
    patterns = [renamed(p) for p in patterns]
    return {n: m for n, m in methods.items() if any(fnmatch.fnmatchcase(n, p) for p in patterns)}


def run(args) -> int:
    from viewer import scene as scenes
    from viewer.bench import method_table as registry
    from viewer.bench import pareto
    from viewer.bench.paper_families import paper_family_methods

    registry.register_provider(paper_family_methods)
    methods = select(registry.registry(args.quick), args.only)
    if args.list:
        for name, m in methods.items():
            print(f"{name:40s} {m.memory_bytes / 1024:10.1f} KiB  {m.about}")
        return 0
    if args.stability and (args.quick or args.out):
        raise InputError("--stability writes docs/STABILITY.md: not with --quick or --out")
    out = args.out or (ROOT / "out" / "bench-quick" if args.quick else ROOT / "docs")
    paths = Paths.under(Path(out))
    sources = scene_sources(args.scenes, args.quick)
    names = [scenes.load(s).name for s in sources]
    start = time.perf_counter()
    if args.stability:
        from viewer.bench.stability.__main__ import main as stability

        stability([])
    if args.again and paths.csv.exists() and not args.charts_only:
        upgrade(paths.csv)
        print(f"bench: {forget(paths.csv, names, methods)} rows to measure again", file=sys.stderr)
    notes = [] if args.charts_only else run_benchmark(sources, methods, paths)
    rows = [r for r in read_rows(paths.csv) if r["scene"] in names]
    if not rows:
        print(f"bench: no rows for these scenes in {paths.csv}", file=sys.stderr)
        return 0
    summary = pareto.publish(rows, names, paths, notes, args.quick)
    if paths.report.resolve() == (ROOT / "docs" / "BENCHMARK.md").resolve():
        from viewer.bench.stability.report import digest

        pareto.replace_block(paths.report, "<!-- bench-stability -->", digest(), pareto.TITLE)
    print(summary, file=sys.stderr)
    print(f"bench: {time.perf_counter() - start:.0f} s; wrote {paths.csv}, {paths.images}, {paths.report}",
          file=sys.stderr)
    return 0


def main(argv=None) -> int:
    """`python -m viewer.bench.run ...` is `python -m viewer bench ...`: the same flags (add_arguments) and
    exit statuses (viewer.errors)."""
    parser = ArgumentParser(prog="python -m viewer bench")
    add_arguments(parser)
    return exit_status(lambda: run(parser.parse_args(sys.argv[1:] if argv is None else argv)))


if __name__ == "__main__":
    raise SystemExit(main())

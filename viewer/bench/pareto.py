"""The benchmark's rows -> the Pareto front of error against time (and against memory), the charts, and
the generated tables of BENCHMARK.md.

An entry (method, setting) is on the front when no other entry is both faster and more accurate. Fronts
are taken over the methods that produce a field (a probe grid the renderer can sample anywhere); Mitsuba
traced straight at the evaluation points answers only there, so it is drawn as its own curve and kept
off every front. Two fronts: over every field method (a Mitsuba bake of the probes included), and over
the viewer's own GI sources (the solvers and the network), which is what a user of the viewer chooses
from. Aggregated over scenes: the mean milliseconds and mean relative RMSE of the entries measured on
every scene.
"""

from __future__ import annotations

import platform
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from viewer.evaluation.report import replace_block

GOAL = 0.05
"""The product's accuracy goal (relative RMSE against Mitsuba, docs/ACCURACY.md)."""
STYLES = {
    "ambient": ("o", "#7f7f7f"), "compute": ("s", "#1f77b4"), "compute-paper": ("s", "#9ecae1"),
    "solver": ("D", "#2ca02c"), "solver-paper": ("D", "#98df8a"), "neural": ("^", "#d62728"),
    "paper-family": ("v", "#ff9896"), "mitsuba-probes": ("P", "#9467bd"), "mitsuba": ("x", "#8c564b"),
    "compute-edit": ("*", "#08306b"), "solver-edit": ("*", "#00441b"), "screen-edit": ("X", "#ff7f0e"),
}
"""Marker and colour per method family (the viewer's sources by their names in viewer.sources; rows read
from an older CSV carry them too, viewer.bench.run.read_rows); a family not listed here gets the next of
EXTRA_STYLES."""
EXTRA_STYLES = [("*", "#e377c2"), ("h", "#bcbd22"), ("p", "#17becf")]
SAME = 0.01
"""Errors within 1% of each other count as the same accuracy when saying what beats a default."""
VIEWER_FAMILIES = ("compute", "compute-paper", "solver", "solver-paper", "neural")
"""The GI sources the viewer itself offers (its panel and `sample --method`)."""
EDIT_FAMILIES = ("compute-edit", "solver-edit", "screen-edit")
"""Time from an edit to converged probes on a scene whose geometry is already traced (`screen-edit`: to
the settled frame in the viewer, the renderer's lightmap included): drawn on the charts, kept off the
fronts (they are not a way to light a scene from nothing), and set against the Mitsuba bake of the same
error in their own table."""
DEFAULTS = {"compute": "N32 M24 conv", "solver": "N32 M24 conv", "neural": "models/probenet.onnx"}
"""The product's GI sources at their shipped defaults (viewer.physical.gi.GISettings, the shipped model)."""


@dataclass(frozen=True)
class Entry:
    family: str
    setting: str
    field: bool
    ms: float
    error: float
    memory: int
    errors: dict
    """scene -> relative RMSE."""
    cpu_ms: float = float("nan")
    """Mean CPU milliseconds (all threads), NaN where a row predates that column."""

    @property
    def short_setting(self) -> str:
        """A model's file name without its folders; other settings as they are."""
        return Path(self.setting).stem if self.family == "neural" else self.setting

    @property
    def label(self) -> str:
        return f"{self.family} {self.short_setting}"


COMPLETE = 0.9
"""A scene joins the mean when the entries measured on it and on every scene before it are at least this
share of the most complete scene's: a scene still being measured waits, rather than thinning the chart."""


def complete_scenes(rows: list[dict], scenes: list[str]) -> list[str]:
    """The scenes (in the given order) that the aggregate is taken over, see COMPLETE."""
    measured = {s: {(r["method"], r["setting"]) for r in rows if r["scene"] == s} for s in scenes}
    ranked = sorted((s for s in scenes if measured[s]), key=lambda s: -len(measured[s]))
    if not ranked:
        return []
    chosen, common = [ranked[0]], measured[ranked[0]]
    for s in ranked[1:]:
        if len(common & measured[s]) >= COMPLETE * len(measured[ranked[0]]):
            chosen.append(s)
            common = common & measured[s]
    return [s for s in scenes if s in chosen]


def aggregate(rows: list[dict], scenes: list[str]) -> tuple[list[Entry], list[str]]:
    """Entries measured on every complete scene (means over those scenes), and those scenes."""
    present = complete_scenes(rows, scenes)
    groups: dict[tuple[str, str], dict[str, dict]] = {}
    for r in rows:
        groups.setdefault((r["method"], r["setting"]), {})[r["scene"]] = r
    entries = []
    for (family, setting), by_scene in groups.items():
        if not all(s in by_scene for s in present):
            continue
        chosen = [by_scene[s] for s in present]
        entries.append(Entry(family, setting, chosen[0]["field"] == "1",
                             float(np.mean([float(r["ms"]) for r in chosen])),
                             float(np.mean([float(r["relative_rmse"]) for r in chosen])),
                             int(chosen[0]["memory_bytes"]),
                             {s: float(by_scene[s]["relative_rmse"]) for s in present},
                             float(np.mean([float(r.get("cpu_ms") or "nan") for r in chosen]))))
    return entries, present


def per_scene(rows: list[dict], scene: str) -> list[Entry]:
    return aggregate([r for r in rows if r["scene"] == scene], [scene])[0]


def front(entries: list[Entry], cost=lambda e: e.ms, families: tuple[str, ...] | None = None) -> list[Entry]:
    """The field entries (of `families`, or all) that no other such entry beats in both cost and error,
    cheapest first."""
    best, out = np.inf, []
    chosen = (e for e in entries if e.field and (e.family in families if families is not None
                                                  else e.family not in EDIT_FAMILIES))
    for e in sorted(chosen, key=lambda e: (cost(e), e.error)):
        if e.error < best:
            out.append(e)
            best = e.error
    return out


def dominated_by(entry: Entry, entries: list[Entry], families: tuple[str, ...] | None = None) -> Entry | None:
    """The fastest field entry (of `families`, or any) faster and as accurate (within SAME); None: none is."""
    better = [e for e in entries if e.field and e is not entry and e.ms < entry.ms
              and e.error <= entry.error * (1.0 + SAME) and e.family not in EDIT_FAMILIES
              and (families is None or e.family in families)]
    return min(better, key=lambda e: e.ms) if better else None


# ---- charts -----------------------------------------------------------------------------------------

def _style(family: str, extra: dict) -> tuple[str, str]:
    if family in STYLES:
        return STYLES[family]
    if family not in extra:
        extra[family] = EXTRA_STYLES[len(extra) % len(EXTRA_STYLES)]
    return extra[family]


def _plot(ax, entries: list[Entry], cost, xlabel: str, unit=None) -> None:
    """Every entry as a marker of its family, the two fronts as step lines. With `unit` (a formatter of the
    cost) the front points get keys (1, 2, ... on the front of every method, a, b, ... on the viewer's)
    listed beside the axes: labels written next to the points overlap where the front is dense."""
    extra: dict = {}
    for family in dict.fromkeys(e.family for e in entries):
        members = sorted((e for e in entries if e.family == family), key=cost)
        marker, colour = _style(family, extra)
        x, y = [cost(e) for e in members], [e.error for e in members]
        if family == "mitsuba":  # one curve of its own (a line where the cost varies along it)
            ax.plot(x, y, linestyle="--" if len(set(x)) > 1 else "none", marker=marker, color=colour, label="mitsuba at the points (no field)")
        else:
            ax.scatter(x, y, marker=marker, color=colour, s=36, label=family, zorder=3)
    right = ax.get_xlim()[1]
    keys: dict[int, list[str]] = {}
    for families, colour, style, label, names in (
            (None, "black", "-", "Pareto front, every field method", "123456789ABCDEFGHIJKLMNOPQRSTUVWXYZ"),
            (VIEWER_FAMILIES, "#1f77b4", "--", "front of the viewer's own sources", "abcdefghijklmnopqrstuvwxyz")):
        on_front = front(entries, cost, families)
        if not on_front:
            continue
        x, y = [cost(e) for e in on_front], [e.error for e in on_front]
        ax.step(x + [max(right, x[-1])], y + [y[-1]], where="post", color=colour, linestyle=style,
                linewidth=1.0, alpha=0.8, label=label, zorder=2)
        for e, name in zip(on_front, names):
            keys.setdefault(id(e), [e]).append(name)
    if unit is not None:
        listed = sorted(keys.values(), key=lambda k: cost(k[0]))
        for k, (e, *names) in enumerate(listed):
            ax.annotate("/".join(names), (cost(e), e.error), textcoords="offset points", fontsize=8,
                        xytext=(4, 3) if k % 2 == 0 else (-4, -11), ha="left" if k % 2 == 0 else "right",
                        fontweight="bold", color="#1f77b4" if names[0].islower() else "black")
        lines = [f"{'/'.join(names):>4s} {e.label[:36]:36s} {unit(cost(e)):>8s} {e.error:6.1%}" for e, *names in listed]
        ax.text(1.02, 0.0, "front points\n" + "\n".join(lines), transform=ax.transAxes, fontsize=7,
                family="monospace", va="bottom")
    ax.axhline(GOAL, color="grey", linestyle=":", linewidth=0.8)
    ax.annotate(f"{GOAL:.0%} goal ", (1.0, GOAL), xycoords=("axes fraction", "data"), fontsize=7, ha="right",
                va="bottom", color="grey")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel(xlabel)
    ax.set_ylabel("relative RMSE vs Mitsuba")
    ax.grid(True, which="both", alpha=0.25)


def _memory(e: Entry) -> float:
    return e.memory / 1024.0


def _kib(kib: float) -> str:
    return f"{kib / 1024:.1f} MiB" if kib >= 1024 else f"{kib:.1f} KiB"


def charts(rows: list[dict], scenes: list[str], folder: Path) -> list[Path]:
    """benchmark_time.png and benchmark_memory.png (aggregated), benchmark_scenes.png (one panel a scene)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    folder.mkdir(parents=True, exist_ok=True)
    entries, present = aggregate(rows, scenes)
    title = f"mean over {len(present)} scene{'s' * (len(present) != 1)}: {', '.join(present)}"
    written = []
    for name, cost, xlabel, unit in (
            ("benchmark_time.png", lambda e: e.ms, "milliseconds to produce the GI (median)", _ms),
            ("benchmark_memory.png", _memory, "memory kept for rendering, KiB (textures + model)", _kib)):
        fig, ax = plt.subplots(figsize=(14, 7))
        _plot(ax, entries, cost, xlabel, unit)
        ax.margins(x=0.12)
        ax.set_title(title, fontsize=9)
        ax.legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.01, 1.0))
        fig.tight_layout()
        fig.savefig(folder / name, dpi=120)
        plt.close(fig)
        written.append(folder / name)
    columns = min(3, len(present))
    rows_of_panels = -(-len(present) // columns)
    fig, axes = plt.subplots(rows_of_panels, columns, figsize=(5 * columns, 3.8 * rows_of_panels), squeeze=False)
    for ax, scene in zip(axes.flat, present):
        _plot(ax, per_scene(rows, scene), lambda e: e.ms, "ms")
        ax.set_title(scene, fontsize=9)
    for ax in list(axes.flat)[len(present):]:
        ax.axis("off")
    handles, names = axes.flat[0].get_legend_handles_labels()
    fig.legend(handles, names, loc="lower center", ncol=6, fontsize=8)
    fig.tight_layout(rect=(0, 0.12 / rows_of_panels, 1, 1))
    fig.savefig(folder / "benchmark_scenes.png", dpi=100)
    plt.close(fig)
    return written + [folder / "benchmark_scenes.png"]


# ---- report -----------------------------------------------------------------------------------------

def _ms(ms: float) -> str:
    return f"{ms / 1000:.1f} s" if ms >= 1000 else f"{ms:.0f} ms"


def budget_sentences(entries: list[Entry], families: tuple[str, ...] | None = None) -> list[str]:
    """Which field method (of `families`, or any) to choose at which time budget, from the front."""
    on_front = front(entries, families=families)
    lines = [f"Under {_ms(on_front[0].ms)}: none of them gives a field."] if on_front else []
    for k, e in enumerate(on_front):
        upto = f"to {_ms(on_front[k + 1].ms)}" if k + 1 < len(on_front) else "and more"
        lines.append(f"{_ms(e.ms)} {upto}: **{e.label}** ({e.error:.1%} relative RMSE).")
    return lines


def defaults_sentences(entries: list[Entry]) -> list[str]:
    """Where the viewer's shipped defaults stand: on which front, or what beats them."""
    lines = []
    for family, setting in DEFAULTS.items():
        entry = next((e for e in entries if e.family == family and e.setting == setting), None)
        if entry is None:
            continue
        own, any_ = dominated_by(entry, entries, VIEWER_FAMILIES), dominated_by(entry, entries)
        where = ("on both fronts" if any_ is None else
                 f"off the viewer's front: {own.label} is as accurate ({own.error:.1%}) in {_ms(own.ms)}"
                 if own is not None else
                 f"on the viewer's front; a Mitsuba bake, {any_.label}, is as accurate ({any_.error:.1%}) in "
                 f"{_ms(any_.ms)} on this machine")
        lines.append(f"Shipped default **{entry.label}**: {_ms(entry.ms)}, {entry.error:.1%}, {where}.")
    return lines


def _front_table(on_front: list[Entry]) -> str:
    lines = ["| method | setting | ms (mean) | rel. RMSE (mean) | memory KiB |", "|---|---|---|---|---|"]
    lines += [f"| {e.family} | {e.short_setting} | {e.ms:.0f} | {e.error:.3f} | {e.memory / 1024:.1f} |"
              for e in on_front]
    return "\n".join(lines)


def tables(rows: list[dict], scenes: list[str]) -> tuple[str, str]:
    """Markdown: the two fronts with their budget sentences; every entry (per-scene errors)."""
    entries, present = aggregate(rows, scenes)
    on_front, own_front = front(entries), front(entries, families=VIEWER_FAMILIES)
    fronts = "\n".join([
        "The viewer's own GI sources (" + ", ".join(VIEWER_FAMILIES) + "):", "", _front_table(own_front), "",
        *(f"- {line}" for line in budget_sentences(entries, VIEWER_FAMILIES)), "",
        "Every method that produces a field (a Mitsuba bake of the probes included):", "", _front_table(on_front), "",
        *(f"- {line}" for line in budget_sentences(entries)), "",
        *(f"- {line}" for line in defaults_sentences(entries))])
    left_out = [s for s in scenes if s not in present and any(r["scene"] == s for r in rows)]
    every = [f"Means over {', '.join(present)}" + (f"; not complete yet, left out: {', '.join(left_out)}"
                                                    if left_out else "") + ".", "",
             "| method | setting | ms (mean) | CPU ms | rel. RMSE (mean) | " + " | ".join(present)
             + " | memory KiB | front |", "|" + "---|" * (len(present) + 7)]
    for e in sorted(entries, key=lambda e: (e.family, e.ms)):
        errors = " | ".join(f"{e.errors[s]:.3f}" for s in present)
        mark = "all" if e in on_front else ("viewer" if e in own_front else "")
        cpu = "" if np.isnan(e.cpu_ms) else f"{e.cpu_ms:.0f}"
        every.append(f"| {e.family} | {e.short_setting} | {e.ms:.0f} | {cpu} | {e.error:.3f} | {errors} | "
                     f"{e.memory / 1024:.1f} | {mark} |")
    return fronts, "\n".join(every)


def machine(rows: list[dict]) -> str:
    """Where and when the rows were measured: CPU, cores, GL, Mitsuba variant, the load while measuring."""
    from viewer.bench.methods import gl_renderer

    cpu = platform.processor() or platform.machine()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    try:
        from viewer.reference import mitsuba as reference

        variant = f"Mitsuba 3 `{reference.variant()}`"
    except Exception as exc:  # noqa: BLE001 - the report says what is missing instead of failing
        variant = f"no Mitsuba ({exc})"
    import os

    loads = [float(r["load_average"]) for r in rows]
    when = sorted(r["measured"] for r in rows)
    cores = os.cpu_count() or 1
    busy = np.median(loads) > cores
    return (f"{cpu}, {cores} cores; GL: {gl_renderer()}; {variant}. Measured {when[0]} to {when[-1]}"
            + (" while other jobs shared the machine" if busy else "")
            + f": 1-minute load average {min(loads):.1f} to {max(loads):.1f} (median {np.median(loads):.1f}) on "
            f"{cores} cores" + (", so times are slower than on an idle machine by up to the load over the core "
                                "count (each row's load is in the CSV)." if busy else "."))


TITLE = "# Benchmark: every GI method, time and memory against error"


def against_mitsuba(rows: list[dict], scenes: list[str]) -> str:
    """Markdown: per scene, the physical GI's time from a new scene and from an edit to converged probes
    (relit on the CPU, `solver`, and in compute shaders, `compute`),
    next to the Mitsuba bake of the probes whose error is equal or larger (the slowest such bake: the
    one closest to our accuracy), measured in the same run, and how many times faster ours is."""
    ours = [(f, DEFAULTS[f], "new scene") for f in ("solver", "compute")]
    ours += [(f, f"{DEFAULTS['compute']} {kind}", kind + " edit") for f in ("compute-edit", "solver-edit")
             for kind in ("colour", "lamp")]
    ours += [("screen-edit", f"{source} {kind}", f"{kind} edit on screen, {source} source")
             for source in ("compute", "neural") for kind in ("colour", "lamp")]
    lines = ["| scene | GI source | what | ms | rel. RMSE | Mitsuba bake of equal or larger error | its ms | "
             "ours faster by |", "|---|---|---|---|---|---|---|---|"]
    ratios: dict[str, list[float]] = {}
    for scene in scenes:
        here = {(r["method"], r["setting"]): r for r in rows if r["scene"] == scene}
        bakes = [r for (family, _), r in here.items() if family == "mitsuba-probes"]
        for family, setting, what in ours:
            row = here.get((family, setting))
            if row is None:
                continue
            ms, error = float(row["ms"]), float(row["relative_rmse"])
            worse = [b for b in bakes if float(b["relative_rmse"]) >= error]
            if worse:
                bake = max(worse, key=lambda b: float(b["ms"]))
                ratio = float(bake["ms"]) / ms
                ratios.setdefault(f"{family} {what}", []).append(ratio)
                lines.append(f"| {scene} | {family} | {what} | {ms:.0f} | {error:.3f} | {bake['setting']} "
                             f"({float(bake['relative_rmse']):.3f}) | {float(bake['ms']):.0f} | {ratio:.0f}x |")
            else:
                lines.append(f"| {scene} | {family} | {what} | {ms:.0f} | {error:.3f} | none as coarse: every "
                             "bake measured is more accurate | | |")
    summary = [f"- {name}: {min(v):.0f}x to {max(v):.0f}x faster (median {np.median(v):.0f}x) over "
               f"{len(v)} scenes." for name, v in ratios.items()]
    return "\n".join(lines + [""] + summary)


def publish(rows: list[dict], scenes: list[str], paths, notes: list[str], quick: bool) -> str:
    """Charts and the generated blocks of the report; returns the front as text for the terminal."""
    charts(rows, scenes, paths.images)
    fronts, every = tables(rows, scenes)
    replace_block(paths.report, "<!-- bench-machine -->", machine(rows) + ("\n\nQuick mode." if quick else ""), TITLE)
    replace_block(paths.report, "<!-- bench-front -->", fronts, TITLE)
    replace_block(paths.report, "<!-- bench-table -->", every + "".join(f"\n\n- {n}" for n in notes), TITLE)
    replace_block(paths.report, "<!-- bench-edits -->", against_mitsuba(rows, scenes), TITLE)
    return fronts

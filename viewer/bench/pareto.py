"""The benchmark's rows -> the Pareto front of error against time (and against memory), the charts, and
the generated tables of BENCHMARK.md.

An entry (method, setting) is on the front when no other entry is both faster and more accurate. The
front is taken over the methods that produce a field (a probe grid the renderer can sample anywhere);
Mitsuba traced straight at the evaluation points answers only there, so it is drawn as its own curve
and kept off the front. Aggregated over scenes: the mean milliseconds and the mean relative RMSE of
the entries measured on every scene.
"""

from __future__ import annotations

import platform
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from viewer.bench.report import replace_block

GOAL = 0.05
"""The product's accuracy goal (relative RMSE against Mitsuba, docs/ACCURACY.md)."""
STYLES = {
    "ambient": ("o", "#7f7f7f"), "compute": ("s", "#1f77b4"), "compute-paper": ("s", "#9ecae1"),
    "numpy": ("D", "#2ca02c"), "numpy-paper": ("D", "#98df8a"), "neural": ("^", "#d62728"),
    "paper-family": ("v", "#ff9896"), "mitsuba-probes": ("P", "#9467bd"), "mitsuba": ("x", "#8c564b"),
}
"""Marker and colour per method family; a family not listed here gets the next of EXTRA_STYLES."""
EXTRA_STYLES = [("*", "#e377c2"), ("h", "#bcbd22"), ("p", "#17becf")]
DEFAULTS = {"compute": "N32 M24 conv", "numpy": "N32 M24 conv", "neural": "models/probenet.onnx"}
"""The product's GI sources at their shipped defaults (viewer.gi.GISettings, the shipped model)."""


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

    @property
    def label(self) -> str:
        setting = Path(self.setting).stem if self.family == "neural" else self.setting
        return f"{self.family} {setting}"


def aggregate(rows: list[dict], scenes: list[str]) -> tuple[list[Entry], list[str]]:
    """Entries measured on every scene that has rows (means over those scenes), and those scenes."""
    present = [s for s in scenes if any(r["scene"] == s for r in rows)]
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
                             {s: float(by_scene[s]["relative_rmse"]) for s in present}))
    return entries, present


def per_scene(rows: list[dict], scene: str) -> list[Entry]:
    return aggregate([r for r in rows if r["scene"] == scene], [scene])[0]


def front(entries: list[Entry], cost=lambda e: e.ms) -> list[Entry]:
    """The field entries that no other field entry beats in both cost and error, cheapest first."""
    best, out = np.inf, []
    for e in sorted((e for e in entries if e.field), key=lambda e: (cost(e), e.error)):
        if e.error < best:
            out.append(e)
            best = e.error
    return out


def dominated_by(entry: Entry, entries: list[Entry]) -> Entry | None:
    """The fastest field entry at least as accurate and faster (None: the entry is on the front)."""
    better = [e for e in entries if e.field and e is not entry and e.ms < entry.ms and e.error <= entry.error]
    return min(better, key=lambda e: e.ms) if better else None


# ---- charts -----------------------------------------------------------------------------------------

def _style(family: str, extra: dict) -> tuple[str, str]:
    if family in STYLES:
        return STYLES[family]
    if family not in extra:
        extra[family] = EXTRA_STYLES[len(extra) % len(EXTRA_STYLES)]
    return extra[family]


def _plot(ax, entries: list[Entry], cost, xlabel: str, labels: bool) -> None:
    extra: dict = {}
    for family in dict.fromkeys(e.family for e in entries):
        members = sorted((e for e in entries if e.family == family), key=cost)
        marker, colour = _style(family, extra)
        x, y = [cost(e) for e in members], [e.error for e in members]
        if family == "mitsuba":
            ax.plot(x, y, linestyle="--", marker=marker, color=colour, label="mitsuba at the points (no field)")
        else:
            ax.scatter(x, y, marker=marker, color=colour, s=36, label=family, zorder=3)
    on_front = front(entries, cost)
    if on_front:
        x = [cost(e) for e in on_front]
        y = [e.error for e in on_front]
        right = ax.get_xlim()[1] if len(on_front) > 0 else x[-1]
        ax.step(x + [max(right, x[-1])], y + [y[-1]], where="post", color="black", linewidth=1.0,
                alpha=0.7, label="Pareto front", zorder=2)
        if labels:
            for k, e in enumerate(on_front):
                ax.annotate(e.label, (cost(e), e.error), textcoords="offset points", fontsize=7,
                            xytext=(6, 4 if k % 2 == 0 else -10))
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


def charts(rows: list[dict], scenes: list[str], folder: Path) -> list[Path]:
    """benchmark_time.png and benchmark_memory.png (aggregated), benchmark_scenes.png (one panel a scene)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    folder.mkdir(parents=True, exist_ok=True)
    entries, present = aggregate(rows, scenes)
    title = f"mean over {len(present)} scene{'s' * (len(present) != 1)}: {', '.join(present)}"
    written = []
    for name, cost, xlabel in (("benchmark_time.png", lambda e: e.ms, "milliseconds to produce the GI (median)"),
                               ("benchmark_memory.png", _memory, "memory kept for rendering, KiB (textures + model)")):
        fig, ax = plt.subplots(figsize=(12, 6.5))
        _plot(ax, entries, cost, xlabel, labels=True)
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
        _plot(ax, per_scene(rows, scene), lambda e: e.ms, "ms", labels=False)
        ax.set_title(scene, fontsize=9)
    for ax in list(axes.flat)[len(present):]:
        ax.axis("off")
    axes.flat[0].legend(fontsize=6, loc="lower left")
    fig.tight_layout()
    fig.savefig(folder / "benchmark_scenes.png", dpi=100)
    plt.close(fig)
    return written + [folder / "benchmark_scenes.png"]


# ---- report -----------------------------------------------------------------------------------------

def _ms(ms: float) -> str:
    return f"{ms / 1000:.1f} s" if ms >= 1000 else f"{ms:.0f} ms"


def budget_sentences(entries: list[Entry]) -> list[str]:
    """Which field method to choose at which time budget, from the front; then the shipped defaults."""
    on_front = front(entries)
    lines = []
    if on_front:
        lines.append(f"Under {_ms(on_front[0].ms)} no method here produces a field.")
    for k, e in enumerate(on_front):
        upto = f"up to {_ms(on_front[k + 1].ms)}" if k + 1 < len(on_front) else "and more"
        lines.append(f"From {_ms(e.ms)} {upto}: **{e.label}** ({e.error:.1%} relative RMSE).")
    for family, setting in DEFAULTS.items():
        entry = next((e for e in entries if e.family == family and e.setting == setting), None)
        if entry is None:
            continue
        beaten = dominated_by(entry, entries)
        where = ("on the front" if beaten is None else
                 f"off the front: {beaten.label} is as accurate or better ({beaten.error:.1%}) in {_ms(beaten.ms)}")
        lines.append(f"The shipped default {entry.label}: {_ms(entry.ms)}, {entry.error:.1%}, {where}.")
    return lines


def tables(rows: list[dict], scenes: list[str]) -> tuple[str, str, str]:
    """Markdown: the front, the budget sentences, every entry (per-scene errors)."""
    entries, present = aggregate(rows, scenes)
    on_front = front(entries)
    front_lines = ["| method | setting | ms (mean) | rel. RMSE (mean) | memory KiB |", "|---|---|---|---|---|"]
    front_lines += [f"| {e.family} | {e.setting} | {e.ms:.0f} | {e.error:.3f} | {e.memory / 1024:.1f} |"
                    for e in on_front]
    budget = "\n".join(f"- {line}" for line in budget_sentences(entries))
    head = "| method | setting | ms (mean) | rel. RMSE (mean) | " + " | ".join(present) + " | memory KiB | front |"
    every = [head, "|" + "---|" * (len(present) + 6)]
    for e in sorted(entries, key=lambda e: (e.family, e.ms)):
        errors = " | ".join(f"{e.errors[s]:.3f}" for s in present)
        every.append(f"| {e.family} | {e.setting} | {e.ms:.0f} | {e.error:.3f} | {errors} | "
                     f"{e.memory / 1024:.1f} | {'yes' if e in on_front else ''} |")
    return "\n".join(front_lines), budget, "\n".join(every)


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
        from viewer import reference

        variant = f"Mitsuba 3 `{reference.variant()}`"
    except Exception as exc:  # noqa: BLE001 - the report says what is missing instead of failing
        variant = f"no Mitsuba ({exc})"
    import os

    loads = [float(r["load_average"]) for r in rows]
    when = sorted(r["measured"] for r in rows)
    return (f"{cpu}, {os.cpu_count()} cores; GL: {gl_renderer()}; {variant}. Measured {when[0]} to {when[-1]} "
            f"while other jobs shared the machine: 1-minute load average {min(loads):.1f} to {max(loads):.1f} "
            f"(median {np.median(loads):.1f}) on {os.cpu_count()} cores, so times are slower than on an idle "
            "machine by up to the load over the core count.")


def publish(rows: list[dict], scenes: list[str], paths, notes: list[str], quick: bool) -> str:
    """Charts and the generated blocks of the report; returns the front as text for the terminal."""
    charts(rows, scenes, paths.images)
    front_table, budget, every = tables(rows, scenes)
    title = "# Benchmark: every GI method, time and memory against error"
    replace_block(paths.report, "<!-- bench-machine -->", machine(rows) + ("\n\nQuick mode." if quick else ""), title)
    replace_block(paths.report, "<!-- bench-front -->", front_table + "\n\n" + budget, title)
    replace_block(paths.report, "<!-- bench-table -->", every + "".join(f"\n\n- {n}" for n in notes), title)
    return front_table + "\n" + budget

"""docs/STABILITY.md: one section per study, its table, chart and numbers between two marker lines (the
prose around them is written by hand and stays), plus a CSV per study for other tools."""

from __future__ import annotations

import csv
import json
import math
import re
from pathlib import Path

import numpy as np

from viewer.evaluation.report import replace_block
from viewer.bench.stability.common import StudyResult, format_table

ROOT = Path(__file__).resolve().parents[3]
DOCUMENT = ROOT / "docs" / "STABILITY.md"
IMAGES = ROOT / "docs" / "images" / "stability"
DATA = ROOT / "docs" / "data" / "stability"
TITLES = {
    "leaking": "Light leaking through a thin wall",
    "energy": "Energy: albedo up to 0.99",
    "ringing": "SH ringing near a small bright emitter",
    "precision": "Precision: very bright emitters in RGBA16F textures",
    "temporal": "Temporal stability: a moving light",
    "resolution": "Resolution: which scenes need which grid",
    "ood": "Out of distribution (neural model)",
    "sun": "Sunlight through a window",
    "inputs": "Where the network's inputs fail",
}
TITLE = "# Stability"


def marker(name: str) -> str:
    return f"<!-- stability-{name} -->"


def skeleton() -> str:
    """A new document: every section with its heading and an empty block."""
    parts = [TITLE, "", "Regenerate: `.venv/bin/python -m viewer.bench.stability` (`--quick`, `--only NAME`).", "",
             "## Methods", "", marker("methods"), marker("methods"), ""]
    for name, title in TITLES.items():
        parts += [f"## {title}", "", marker(name), marker(name), ""]
    return "\n".join(parts)


def block(result: StudyResult, chart_file: Path | None) -> str:
    lines = []
    if result.rows:
        lines += [format_table(result), ""]
    lines += [f"- {note}" for note in result.notes]
    if result.summary:
        lines += ["", "Measured:", ""] + [f"- {s}" for s in result.summary]
    if chart_file is not None:
        lines += ["", f"![{result.name}]({chart_file.relative_to(DOCUMENT.parent).as_posix()})"]
    if result.rows:
        lines += ["", f"Data: [{(DATA / f'{result.name}.csv').relative_to(DOCUMENT.parent).as_posix()}]"
                      f"({(DATA / f'{result.name}.csv').relative_to(DOCUMENT.parent).as_posix()})"]
    return "\n".join(lines)


def write_csv(result: StudyResult) -> Path:
    DATA.mkdir(parents=True, exist_ok=True)
    path = DATA / f"{result.name}.csv"
    keys = [key for key, _, _ in result.columns]
    with open(path, "w", newline="") as fh:
        writer = csv.writer(fh)
        writer.writerow(keys)
        for row in result.rows:
            writer.writerow(["" if isinstance(row.get(k), float) and math.isnan(row[k]) else row.get(k, "")
                             for k in keys])
    return path


def save(result: StudyResult) -> None:
    """Everything the chart and the block need, as JSON (`load` reads it back for --charts-only)."""
    DATA.mkdir(parents=True, exist_ok=True)
    plain = lambda x: x.tolist() if isinstance(x, np.ndarray) else float(x) if isinstance(x, np.floating) else x
    record = dict(name=result.name, columns=result.columns, rows=[{k: plain(v) for k, v in r.items()} for r in result.rows],
                  notes=result.notes, summary=result.summary,
                  series={k: {n: [float(x) for x in v] for n, v in d.items()} for k, d in result.series.items()})
    (DATA / f"{result.name}.json").write_text(json.dumps(record, allow_nan=True))


def load(name: str) -> StudyResult | None:
    path = DATA / f"{name}.json"
    if not path.exists():
        return None
    from viewer.sources import renamed

    record = json.loads(path.read_text())
    # Results saved when the CPU solver was `physical` here draw under its name now (viewer.sources): in a
    # row's method, in the columns named after a method (`physical all`) and in the curves' labels.
    columns = [(renamed(key), renamed(header), form) for key, header, form in record["columns"]]
    rows = [{renamed(k): renamed(v) if k == "method" and isinstance(v, str) else v for k, v in row.items()}
            for row in record["rows"]]
    series = {renamed(label): curves for label, curves in record["series"].items()}
    return StudyResult(record["name"], columns, rows, record["notes"], record["summary"], series)


def write(result: StudyResult, chart) -> None:
    """The study's CSV and JSON, chart (PNG, when it has rows) and block in docs/STABILITY.md."""
    import matplotlib

    matplotlib.use("Agg")
    chart_file = None
    if result.rows:
        write_csv(result)
        save(result)
        IMAGES.mkdir(parents=True, exist_ok=True)
        chart_file = IMAGES / f"{result.name}.png"
        chart(result, chart_file)
    if not DOCUMENT.exists():
        DOCUMENT.parent.mkdir(parents=True, exist_ok=True)
        DOCUMENT.write_text(skeleton())
    replace_block(DOCUMENT, marker(result.name), block(result, chart_file), TITLE)


def digest() -> str:
    """Every study's findings (its summary sentences, from the saved results) under its title, linked to
    its section of STABILITY.md: the stability part of docs/BENCHMARK.md."""
    parts = []
    for name, title in TITLES.items():
        result = load(name)
        anchor = re.sub(r"[^a-z0-9 -]", "", title.lower()).replace(" ", "-")  # GitHub's heading anchors
        lines = result.summary if result is not None and result.summary else ["not measured yet"]
        parts.append(f"**[{title}](STABILITY.md#{anchor})**\n\n" + "\n".join(f"- {line}" for line in lines))
    return "\n\n".join(parts) + "\n\nRegenerate: `python -m viewer.bench.stability` (or `python -m viewer bench --stability`)."


def write_methods(methods: dict) -> None:
    """The list of compared methods (viewer.bench.stability.methods.METHODS) with one line each."""
    if not DOCUMENT.exists():
        DOCUMENT.parent.mkdir(parents=True, exist_ok=True)
        DOCUMENT.write_text(skeleton())
    lines = [f"- `{name}`: {method.about}" for name, method in methods.items()]
    replace_block(DOCUMENT, marker("methods"), "\n".join(lines), TITLE)

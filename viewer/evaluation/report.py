"""Benchmarks write their tables into docs/*.md between two marker lines; the prose around stays."""

from __future__ import annotations

from pathlib import Path


PERFORMANCE = Path(__file__).resolve().parents[2] / "docs" / "PERFORMANCE.md"


def show_table(text: str, marker: str, write: bool) -> None:
    """Print a benchmark's table and, with `write`, put it between `marker`'s lines of docs/PERFORMANCE.md."""
    print(text)
    if write:
        replace_block(PERFORMANCE, marker, text, "# Performance")


def replace_block(path: Path, marker: str, block: str, title: str) -> None:
    """Put `block` between the two `marker` lines of `path` (a new file gets `title` and the markers)."""
    path = Path(path)
    text = path.read_text() if path.exists() else f"{title}\n\n{marker}\n{marker}\n"
    if text.count(marker) < 2:
        text = text.rstrip("\n") + f"\n\n{marker}\n{marker}\n"
    before, _, rest = text.partition(marker)
    _, _, after = rest.partition(marker)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(before + marker + "\n" + block.rstrip("\n") + "\n" + marker + after)

"""Benchmarks write their tables into docs/*.md between two marker lines; the prose around stays."""

from __future__ import annotations

from pathlib import Path


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

"""What every study shares: its result record, the settings of a run, and a few measurements."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from viewer.probes import sh
from viewer.bench.stability.methods import METHODS, MethodUnavailable, MethodSettings, run
from viewer.probes.grid import ProbeGrid
from viewer.scene import Scene
from viewer.rays.voxels import FACINGS

DC_TO_RADIANCE = 1.0 / (0.282095 * 4.0 * np.pi)
"""Mean radiance over the sphere from the SH DC coefficient."""
AXES = FACINGS
"""The six axis normals at which irradiance is evaluated."""


@dataclass(frozen=True)
class RunConfig:
    quick: bool = False
    """Fewer scenes, steps and resolutions: a few minutes instead of an hour."""
    methods: tuple[str, ...] = tuple(METHODS)
    """Which registered methods the studies run (viewer.bench.stability.methods.METHODS)."""


@dataclass
class StudyResult:
    name: str
    """The study's command-line name (--only NAME)."""
    columns: list[tuple[str, str, str]]
    """(key, header, format) of the table, in order; format as for str.format, e.g. '{:.3f}'."""
    rows: list[dict] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)
    """Settings, skipped methods and their reasons: printed under the table."""
    summary: list[str] = field(default_factory=list)
    """The findings in numbers, one sentence each (computed from the rows)."""
    series: dict = field(default_factory=dict)
    """Curves for the chart that the table does not hold (label -> values)."""


STYLES = {"solver": dict(color="C0", marker="o"), "paper": dict(color="C1", marker="s"),
          "compute": dict(color="C2", marker="x", ls="--"), "ambient": dict(color="C3", marker="^"),
          "mitsuba-probes": dict(color="C4", marker="d", ls=":"), "neural": dict(color="C5", marker="*"),
          "Mitsuba (truth)": dict(color="k", marker=".")}


def style(method: str) -> dict:
    """Matplotlib keywords of a method, the same in every chart (compute dashed: it lies on solver)."""
    return STYLES.get(method.split(" ")[0] if method not in STYLES else method, dict(marker="o"))


def radiance(coefficients: np.ndarray) -> np.ndarray:
    """(P,) mean incident radiance over the sphere and RGB from SH (P, 9, 3)."""
    return coefficients[:, 0].mean(axis=-1) * DC_TO_RADIANCE


def axis_irradiance(coefficients: np.ndarray) -> np.ndarray:
    """(P, 6, 3) irradiance for the six axis normals from SH (P, 9, 3)."""
    return sh.irradiance(np.asarray(coefficients, np.float64)[:, None], AXES[None])


def try_method(name: str, scene: Scene, settings: MethodSettings, result: StudyResult) -> ProbeGrid | None:
    """Run one method; None (and a note, once per method) when it cannot run here."""
    try:
        return run(name, scene, settings)
    except MethodUnavailable as exc:
        note = f"`{name}` skipped: {exc}"
        if note not in result.notes:
            result.notes.append(note)
        return None


def neural_study(name: str, config: RunConfig, here, columns) -> tuple[list[str], StudyResult, bool]:
    """For a study of the network: the methods of `here` that the run asks for, the study's empty result
    (`columns(methods)`), and whether `neural` is among them (if not, a note says it was not run)."""
    methods = [m for m in here if m in config.methods]
    result = StudyResult(name, columns(methods))
    if "neural" not in methods:
        result.notes.append("Not run: the study measures `neural`, which was not asked for.")
    return methods, result, "neural" in methods


def format_table(result: StudyResult) -> str:
    """The rows as a Markdown table."""
    lines = ["| " + " | ".join(h for _, h, _ in result.columns) + " |",
             "|" + "---|" * len(result.columns)]
    for row in result.rows:
        cells = []
        for key, _, fmt in result.columns:
            value = row.get(key, "")
            number = isinstance(value, (int, float, np.floating, np.integer)) and not isinstance(value, bool)
            cells.append("-" if number and np.isnan(value) else fmt.format(value) if number else str(value))
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)

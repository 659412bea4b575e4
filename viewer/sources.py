"""Every source of indirect light the viewer offers, in one registry: name -> Source.

A source is off (direct light only), the compute-shader solver, the CPU (numpy) solver, the neural
field, or a baked grid read from a file. Everything that names a source reads it from here: the
command line's `--gi` and `--method` choices, the panel's list and labels, what `sample`, `capture` and
`bake` run, the viewer's GIController, and the benchmark's method names.

    spec = lookup("solver")                      # old names ("numpy", "physical") find it too
    grid, timings = spec.solve(scene, settings, SolveOptions(include_emitted=True))

Cheap to import: no GL, onnxruntime, imgui or viewer.ui; each source imports what it runs when it runs.
A new source is its own module, one `register(Source(...))` line, and its tests (docs/ARCHITECTURE.md).
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, Callable

from viewer.physical.gi import GISettings, Timings

if TYPE_CHECKING:  # types only: importing them here would pull in GL and the viewer's UI
    from viewer.probes.grid import ProbeGrid
    from viewer.scene import Scene


class SourceError(ValueError):
    """A source cannot solve with what it was given (e.g. a missing or broken model file): one line,
    which the command line prefixes with the flag that chose the source."""


class UnknownSource(KeyError):
    """No source of that name (or old name)."""

    def __str__(self) -> str:
        return str(self.args[0]) if self.args else "unknown GI source"


@dataclass(frozen=True)
class SolveOptions:
    """What a batch solve needs besides the scene and the GI settings."""

    include_emitted: bool = True
    """All the light, emitted included, as Mitsuba sees it (`sample`), or only the indirect part that the
    renderer shades from the probes (`capture`, the viewer)."""
    ctx: Any = None
    """A GL context to run on (capture passes its own, so that solver and renderer share it); None: a
    source that needs GL makes one and releases it."""
    model: Path | str | None = None
    """The neural source's .onnx file; None: the shipped model."""
    timings: Timings | None = None
    """Stage timings to add to (the command line's already hold the scene's load); None: new ones."""


BatchSolve = Callable[["Scene", GISettings, SolveOptions], "tuple[ProbeGrid | None, Timings]"]
"""(scene, settings, options) -> (the probes, seconds per stage)."""


@dataclass(frozen=True)
class Needs:
    """What a source needs from the machine; the panel and the command line say so when it is missing."""

    gl: bool = False
    """A GL 4.3 context (compute shaders)."""
    model: bool = False
    """A trained model file (models/probenet.onnx, or `--model`)."""
    mitsuba: bool = False
    """Mitsuba 3 (`pip install ".[reference]"`)."""


@dataclass(frozen=True)
class Source:
    """One source of indirect light."""

    name: str
    """What the command line calls it (`--gi NAME`, `sample --method NAME`) and the panel keys it by."""
    label: str
    """The panel's text for it."""
    needs: Needs = Needs()
    """What it needs from the machine."""
    solve: BatchSolve | None = None
    """The blocking solve of `sample`, `capture` and the benchmark; None where it solves nothing itself
    (off: no indirect light; baked: its probes come from the file that was opened)."""
    live: Callable[[Any], Any] | None = None
    """GIController -> the viewer's adapter for it (viewer.ui.live_sources.LiveSource): what it does when
    the scene or the settings change and in every frame. None: the blocking `solve` on a worker thread."""
    unavailable: Callable[[], str | None] = lambda: None
    """Why it cannot be chosen in this build (None: it can); shown on the panel's disabled button."""
    from_file: bool = False
    """Its probes come from a file the viewer opened (`gi-viewer GRID.npz`), so the command line does not
    offer it by name and a new scene drops it."""
    steps_on_render_thread: bool = False
    """It works a slice of every frame on the render thread and shows its probes as they converge: the
    window draws previews while it is busy."""
    aliases: tuple[str, ...] = ()
    """Older names that still find it, for what users and files wrote before (the benchmark called the
    CPU solver `numpy`, its stability suite `physical`)."""

    def indirect(self, scene: "Scene", settings: GISettings, model: Path | str | None = None) -> "ProbeGrid | None":
        """The blocking solve of the indirect light only, as the renderer shades it from the probes (the
        viewer's worker thread runs this for a source without an adapter of its own)."""
        return self.solve(scene, settings, SolveOptions(include_emitted=False, model=model))[0]


SOURCES: dict[str, Source] = {}
"""Name -> Source, in the panel's order."""
ALIASES: dict[str, str] = {}
"""Old name -> name."""


def register(source: Source) -> Source:
    """Add (or replace) a source; its aliases find it from now on."""
    SOURCES[source.name] = source
    ALIASES.update({alias: source.name for alias in source.aliases})
    return source


def unregister(name: str) -> None:
    source = SOURCES.pop(name, None)
    if source is not None:
        for alias in source.aliases:
            ALIASES.pop(alias, None)


def canonical(name: str) -> str:
    """The registered name for `name` or one of its old names; UnknownSource otherwise."""
    if name in SOURCES:
        return name
    if name in ALIASES:
        return ALIASES[name]
    raise UnknownSource(f"{name!r}: expected one of {', '.join(SOURCES)}")


def lookup(name: str) -> Source:
    return SOURCES[canonical(name)]


def renamed(identifier: str) -> str:
    """A name written before the sources had one name each, as it reads now: a leading old source name
    (`numpy`, `numpy-edit`, `numpy:N32 M24 conv`, `numpy:*`, `physical, indirect`) becomes the source's,
    anything else stays. The benchmark reads its CSV rows, `--only` patterns and saved stability results
    through this."""
    if not ALIASES:
        return identifier
    pattern = "|".join(re.escape(a) for a in sorted(ALIASES, key=len, reverse=True))
    return re.sub(rf"^({pattern})(?=$|[-:, *?\[])", lambda m: ALIASES[m.group(1)], identifier)


def chosen_by_name() -> tuple[str, ...]:
    """The sources `capture --gi` and the window's `--gi` offer."""
    return tuple(name for name, s in SOURCES.items() if not s.from_file)


def solving() -> tuple[str, ...]:
    """The sources that solve on their own (`sample --method`, the benchmark)."""
    return tuple(name for name, s in SOURCES.items() if s.solve is not None)


def sample_choices() -> tuple[str, ...]:
    """`sample --method`'s choices: its default, the CPU solver, first (as `--help` has always listed it)."""
    names = solving()
    return tuple(sorted(names, key=lambda n: n != SOLVER.name))


# ---- the built-in sources ---------------------------------------------------------------------------

def _timings(options: SolveOptions) -> Timings:
    return options.timings if options.timings is not None else Timings()


def _solve_cpu(scene, settings: GISettings, options: SolveOptions):
    from viewer.physical import gi

    timings = _timings(options)
    return gi.solve(scene, settings, include_emitted=options.include_emitted, timings=timings), timings


def _solve_compute(scene, settings: GISettings, options: SolveOptions):
    from viewer.gpu.compute_relight import solve_probes

    timings = _timings(options)
    if options.ctx is not None:
        return solve_probes(options.ctx, scene, settings, include_emitted=options.include_emitted,
                            timings=timings), timings
    from viewer.gpu.context import create_context

    ctx = create_context()
    try:
        return solve_probes(ctx, scene, settings, include_emitted=options.include_emitted, timings=timings), timings
    finally:
        ctx.release()


def _solve_neural(scene, settings: GISettings, options: SolveOptions):
    """The network at the voxels and probes its card names (the settings' resolution does not reach it);
    a scene unlike its training rooms gets a one-line warning on stderr."""
    from viewer.neural.domain import print_warning
    from viewer.neural.field import DEFAULT_MODEL, ModelError, NeuralField

    try:
        field = NeuralField(options.model or DEFAULT_MODEL)
    except ModelError as exc:
        raise SourceError(str(exc)) from None
    timings = _timings(options)
    grid = field.solve(scene, include_emitted=options.include_emitted, timings=timings.stages)
    print_warning(scene, field.card.domain)
    return grid, timings


def _live(name: str):
    """The factory of viewer.ui.live_sources' adapter `name`, imported when the viewer first asks."""
    def make(controller):
        from viewer.ui import live_sources

        return getattr(live_sources, name)(controller)
    return make


def _compute_unavailable() -> str | None:
    import importlib.util

    if importlib.util.find_spec("viewer.gpu.compute_solver") is None:
        return "The compute-shader solver (viewer/gpu/compute_solver.py) is not part of this build yet."
    return None


def _neural_unavailable() -> str | None:
    from viewer.resources import MODELS

    if not (MODELS / "probenet.onnx").is_file():
        return "No trained model: the neural field needs models/probenet.onnx (docs/TRAINING.md)."
    return None


NO_BAKED_GRID = "No baked grid: open one with `gi-viewer FILE.npz` (write it with `gi-viewer bake`)."

OFF = register(Source("off", "Off (direct only)", live=_live("OffLive")))
COMPUTE = register(Source(
    "compute", "Compute solver", Needs(gl=True), _solve_compute, _live("ComputeLive"), _compute_unavailable,
    steps_on_render_thread=True))
SOLVER = register(Source(
    "solver", "CPU solver (numpy)", Needs(), _solve_cpu, _live("SolverLive"),
    aliases=("numpy", "physical")))
NEURAL = register(Source(
    "neural", "Neural (ONNX)", Needs(model=True), _solve_neural, _live("NeuralLive"), _neural_unavailable))
BAKED = register(Source(
    "baked", "Baked (.npz file)", live=_live("BakedLive"), unavailable=lambda: NO_BAKED_GRID, from_file=True))

DEFAULT = COMPUTE.name
"""The window's source at start, and where it goes when its source cannot go on (a broken model, a
baked grid whose scene was left)."""

"""The benchmark's methods: every way it can produce a scene's light field (the table of them, name ->
Method, is viewer.bench.method_table).

A method answers the question `python -m viewer sample` answers: the incident-radiance SH (all the light,
emitted included, as Mitsuba sees it) wherever the renderer could ask. Most produce a `ProbeGrid`
(the whole field); Mitsuba traced straight at the evaluation points produces SH at those points only,
which is its own time-error curve but not a field a renderer could sample (`Method.field` says which).

    Method.prepare()           -> produce      untimed, once: a GL context, an onnxruntime session
    produce(scene, points)     -> ProbeGrid | (P, 9, 3) SH      timed by the benchmark

Memory is what the renderer keeps for the result: the probe textures (M^3 probes x 7 RGBA16F texels,
`ProbeGrid.texture_data`) plus, for a network, its .onnx file. A method that cannot run here (no GL
context, a broken model) raises `MethodUnavailable` from `prepare`; the benchmark notes it and goes on.

The viewer's own GI sources are named as viewer.sources names them (`compute`, `solver`, `neural`);
rows written when the CPU solver was called `numpy` read as `solver` (viewer.bench.run). The edits' time
to converged probes and to the settled frame are in viewer.bench.edit_methods.

The neural entries scan for model files (models/, runs/sweep/); the paper's model families
(runs/table1/, viewer.bench.paper_families) are registered with the table by the benchmark's command.
"""

from __future__ import annotations

import atexit
import sys
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Callable, Iterable

import numpy as np

from viewer import sources
from viewer.reference import mitsuba as reference
from viewer.evaluation.points import free_space_points
from viewer.physical.gi import GISettings
from viewer.probes.grid import ProbeGrid
from viewer.scene import Scene

ROOT = Path(__file__).resolve().parents[2]
TEXELS_PER_PROBE = 7
"""The renderer's probe textures: 27 SH numbers + validity in seven RGBA texels per probe."""
TEXEL_BYTES = 4 * 2
"""RGBA16F."""

Produce = Callable[[Scene, np.ndarray], "ProbeGrid | np.ndarray"]


class MethodUnavailable(RuntimeError):
    """The method cannot run on this machine; the message says why."""


@dataclass(frozen=True)
class Method:
    family: str
    """Marker and colour in the charts: `compute`, `solver`, `neural`, `ambient`, `mitsuba`, ..."""
    setting: str
    """What distinguishes it within its family, e.g. `N32 M24 conv` (voxels, probes, bounces)."""
    prepare: Callable[[], Produce]
    """Untimed set-up, once per run; returns the timed producer."""
    texture_bytes: int
    """Probe textures the renderer holds (or, for SH at points only, those float32 numbers)."""
    model_bytes: int = 0
    """A network's weights (its .onnx file)."""
    field: bool = True
    """Produces a field over the whole scene (a ProbeGrid). False: SH at the evaluation points only."""
    about: str = ""
    """One line for the report."""

    @property
    def name(self) -> str:
        return f"{self.family}:{self.setting}"

    @property
    def memory_bytes(self) -> int:
        return self.texture_bytes + self.model_bytes


def texture_bytes(probes: int) -> int:
    """M^3 probes x 7 RGBA16F texels."""
    return probes ** 3 * TEXELS_PER_PROBE * TEXEL_BYTES


def grid_label(settings: GISettings) -> str:
    """`N32 M24 conv`: voxels, probes, bounces (`conv`: to convergence)."""
    bounces = "conv" if settings.bounces == GISettings().bounces else f"b{settings.bounces}"
    return f"N{settings.voxels} M{settings.probes} {bounces}"


# ---- the solvers -----------------------------------------------------------------------------------

DEFAULT = GISettings()
"""The product defaults (32^3 voxels, 24^3 probes, physical kernel, bounces to convergence)."""


def solver_grid(defaults: GISettings = DEFAULT) -> list[GISettings]:
    """Bounces 1, 2, 4 and converged at the default resolution; then voxels and probes varied, converged."""
    return ([replace(defaults, bounces=b) for b in (1, 2, 4)] + [defaults]
            + [replace(defaults, voxels=n) for n in (16, 64)]
            + [replace(defaults, probes=m) for m in (8, 16, 32)])


def family(source: sources.Source, settings: GISettings) -> str:
    """The source's name, with the kernel where it is not the physical one: `solver`, `compute-paper`."""
    return source.name if settings.kernel == "physical" else f"{source.name}-{settings.kernel}"


def solver_method(settings: GISettings) -> Method:
    def produce(scene: Scene, points) -> ProbeGrid:
        return sources.SOLVER.solve(scene, settings, sources.SolveOptions(include_emitted=True))[0]

    return Method(family(sources.SOLVER, settings), grid_label(settings), lambda: produce,
                  texture_bytes(settings.probes), about=f"numpy solver, {settings.kernel} kernel (viewer.physical.gi.solve)")


_context = None
_programs = None


def shared_gl():
    """One headless GL context and one program library for the whole run: the viewer compiles its
    shaders once, so the solver's time here does not include compiling them either."""
    global _context, _programs
    if _context is None:
        from viewer.gpu.context import GLUnavailable, create_context
        from viewer.gpu.programs import ProgramLibrary

        try:
            _context = create_context()
        except GLUnavailable as exc:
            raise MethodUnavailable(str(exc)) from None
        _programs = ProgramLibrary(_context)
        atexit.register(_context.release)
    return _context, _programs


def gl_renderer() -> str:
    """The GL implementation the compute solver ran on (for the report), or why there is none."""
    from viewer.gpu.context import describe

    try:
        return describe(shared_gl()[0])
    except MethodUnavailable as exc:
        return f"no GL context ({exc})"


def compute_method(settings: GISettings) -> Method:
    def prepare() -> Produce:
        from viewer.gpu.compute_relight import solve_probes

        ctx, programs = shared_gl()   # the shared programs: compiling shaders is not the solve's time
        return lambda scene, points: solve_probes(ctx, scene, settings, programs=programs)

    return Method(family(sources.COMPUTE, settings), grid_label(settings), prepare, texture_bytes(settings.probes),
                  about=f"compute-shader solver, {settings.kernel} kernel, blocking run to convergence")


# ---- baselines and Mitsuba -------------------------------------------------------------------------

AMBIENT_POINTS = 64
AMBIENT_DIRECTIONS = 64


def _ambient(scene: Scene, points) -> ProbeGrid:
    """A constant ambient light: one probe whose only SH term is the scene's mean incident radiance,
    estimated by Mitsuba at a few free-space points of its own (not the evaluation points) with few
    directions. The constant needs the answer, so its cost is that estimate's."""
    own = free_space_points(scene, AMBIENT_POINTS, margin=0.06, seed=11)
    dc = reference.probe_sh(scene, own, directions=AMBIENT_DIRECTIONS, seed=11, cache=False)[:, 0].mean(axis=0)
    coefficients = np.zeros((1, 1, 1, 9, 3), np.float32)
    coefficients[0, 0, 0, 0] = dc
    lo, hi = scene.bounds
    return ProbeGrid(lo, hi, coefficients, np.ones((1, 1, 1), bool))


def ambient_method() -> Method:
    return Method("ambient", f"{AMBIENT_POINTS}x{AMBIENT_DIRECTIONS}", lambda: _ambient, texture_bytes(1),
                  about=f"one constant SH DC term: Mitsuba's mean at {AMBIENT_POINTS} points x "
                        f"{AMBIENT_DIRECTIONS} directions")


class _Seeds:
    """A new seed for every Mitsuba run, none equal to the reference's (0): each repeat is an
    independent estimate, not a replay of the reference's own noise."""

    def __init__(self):
        self.next = 1000

    def __call__(self) -> int:
        self.next += 1
        return self.next


def mitsuba_points_method(directions: int, points_count: int = 500) -> Method:
    seeds = _Seeds()

    def prepare() -> Produce:
        return lambda scene, points: reference.probe_sh(scene, points, directions=directions, seed=seeds(),
                                                        cache=False)
    return Method("mitsuba", f"d{directions}", prepare, points_count * 9 * 3 * 4, field=False,
                  about=f"Mitsuba traced at the evaluation points themselves, {directions} directions each: "
                        "no field, the path tracer's own time-error curve")


def mitsuba_probes_method(probes: int, directions: int) -> Method:
    seeds = _Seeds()

    def produce(scene: Scene, points) -> ProbeGrid:
        lo, hi = scene.bounds
        centres = ProbeGrid.positions_for(lo, hi, probes).reshape(-1, 3)
        sh = reference.probe_sh(scene, centres, directions=directions, seed=seeds(), cache=False)
        return ProbeGrid(lo, hi, sh.reshape(probes, probes, probes, 9, 3), np.ones((probes,) * 3, bool))
    return Method("mitsuba-probes", f"M{probes} d{directions}", lambda: produce, texture_bytes(probes),
                  about="Mitsuba at every probe centre (an offline bake), interpolated like any probe grid")


# ---- neural models ----------------------------------------------------------------------------------

def model_files(root: Path = ROOT) -> list[Path]:
    """The shipped model and every model of the size sweep (runs/sweep/*/*.onnx) that exists, the sweep's
    copy of the shipped model left out (one model, one row)."""
    shipped = root / "models" / "probenet.onnx"
    files = [shipped] + sorted((root / "runs" / "sweep").glob("*/*.onnx"))
    files = [f for f in files if f.is_file()]
    if shipped.is_file():
        same = shipped.read_bytes()
        files = [shipped] + [f for f in files[1:] if f.stat().st_size != len(same) or f.read_bytes() != same]
    return files


def neural_method(path: Path, root: Path = ROOT) -> Method:
    from viewer.neural.field import ModelCard, ModelError, NeuralField

    card = ModelCard.read(path)  # ModelError for a model without a readable card: the caller skips it

    def prepare() -> Produce:
        try:
            field = NeuralField(path)
        except ModelError as exc:
            raise MethodUnavailable(str(exc)) from None
        def produce(scene, points):
            field.forget()   # a loaded scene's cost: the kept encoder would find a repeat unchanged
            return field.solve(scene, include_emitted=True)

        return produce

    try:
        label = str(path.resolve().relative_to(root))
    except ValueError:
        label = str(path)
    return Method(sources.NEURAL.name, label, prepare, texture_bytes(card.probes), path.stat().st_size,
                  about=f"ONNX network, {card.data.get('parameters', '?')} parameters, {card.probes}^3 probes")


def neural_methods(quick: bool = False) -> Iterable[Method]:
    from viewer.neural.field import ModelError

    for path in model_files()[:1] if quick else model_files():
        try:
            yield neural_method(path)
        except ModelError as exc:
            print(f"bench: skipping {path}: {exc}", file=sys.stderr, flush=True)

"""Every way the benchmark can produce a scene's light field, in one registry: name -> Method.

A method answers the question `python -m viewer sample` answers: the incident-radiance SH (all the light,
emitted included, as Mitsuba sees it) wherever the renderer could ask. Most produce a `ProbeGrid`
(the whole field); Mitsuba traced straight at the evaluation points produces SH at those points only,
which is its own time-error curve but not a field a renderer could sample (`Method.field` says which).

    Method.prepare()           -> produce      untimed, once: a GL context, an onnxruntime session
    produce(scene, points)     -> ProbeGrid | (P, 9, 3) SH      timed by the benchmark

Memory is what the renderer keeps for the result: the probe textures (M^3 probes x 7 RGBA16F texels,
`ProbeGrid.texture_data`) plus, for a network, its .onnx file. A method that cannot run here (no GL
context, a broken model) raises `MethodUnavailable` from `prepare`; the benchmark notes it and goes on.

More entries come from providers (`register_provider`), each scanning for model files: the neural
entries (models/, runs/sweep/) and the paper's model families (runs/table1/, `paper_families`, registered
by the benchmark's command).
"""

from __future__ import annotations

import atexit
import sys
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Callable, Iterable

import numpy as np

from viewer.reference import mitsuba as reference
from viewer.evaluation.points import free_space_points
from viewer.physical.gi import GISettings, solve
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
    """Marker and colour in the charts: `compute`, `numpy`, `neural`, `ambient`, `mitsuba`, ..."""
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


def _grid_label(settings: GISettings) -> str:
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


def numpy_method(settings: GISettings) -> Method:
    family = "numpy" if settings.kernel == "physical" else f"numpy-{settings.kernel}"
    return Method(family, _grid_label(settings), lambda: lambda scene, points: solve(scene, settings),
                  texture_bytes(settings.probes), about=f"numpy solver, {settings.kernel} kernel (viewer.physical.gi.solve)")


_context = None
_programs = None


def _gl():
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
        return describe(_gl()[0])
    except MethodUnavailable as exc:
        return f"no GL context ({exc})"


def compute_method(settings: GISettings) -> Method:
    def prepare() -> Produce:
        from viewer.gpu.compute_relight import solve_probes

        ctx, programs = _gl()
        return lambda scene, points: solve_probes(ctx, scene, settings, programs=programs)

    family = "compute" if settings.kernel == "physical" else f"compute-{settings.kernel}"
    return Method(family, _grid_label(settings), prepare, texture_bytes(settings.probes),
                  about=f"compute-shader solver, {settings.kernel} kernel, blocking run to convergence")


class Edit:
    """An edit's time to converged probes: untimed (`before`), the scene is edited away and relit; timed,
    the edit comes back to the scene itself (so the error is the scene's own) and the probes are
    projected, as the viewer does after the edit. `kind`: `colour` (the largest group's albedo: the
    relight only) or `lamp` (the brightest emitter moved by a tenth of the scene: new lamp paths on the
    unchanged geometry, then the relight, as the viewer answers a lamp drag)."""

    def __init__(self, settings: GISettings, kind: str, relighter_factory=None):
        self.settings, self.kind, self.relighter_factory = settings, kind, relighter_factory
        self.solvers: dict = {}

    def edited(self, scene: Scene) -> Scene:
        if self.kind == "colour":
            group = scene.largest_group()
            return scene.with_albedo(group, scene.group_albedo(group)[::-1] * 0.5)
        from viewer.ui.scene_edits import emitter_group

        group = emitter_group(scene)
        if group is None:
            return scene.with_sun(None)
        lo, hi = scene.bounds
        move = np.eye(4)
        move[0, 3] = 0.1 * float(hi[0] - lo[0])
        return scene.transformed_group(group, move)

    def before(self, scene: Scene) -> None:
        from viewer.physical.gi import PhysicalGI

        if scene.name not in self.solvers:
            relighter = self.relighter_factory() if self.relighter_factory else None
            solver = PhysicalGI(self.settings, relighter) if relighter else PhysicalGI(self.settings)
            solver.update(scene)
            self.solvers[scene.name] = solver
        self.solvers[scene.name].update(self.edited(scene), stale_geometry=True)

    def __call__(self, scene: Scene, points) -> ProbeGrid:
        solver = self.solvers[scene.name]
        solver.update(scene, stale_geometry=True)
        return solver.probe_grid(include_emitted=True)


def edit_method(settings: GISettings, kind: str, backend: str) -> Method:
    def prepare() -> Produce:
        if backend == "numpy":
            return Edit(settings, kind)
        from viewer.gpu.compute_relight import ComputeRelight

        ctx, programs = _gl()
        return Edit(settings, kind, lambda: ComputeRelight(ctx, programs))

    what = {"colour": "a colour edit (the relight)", "lamp": "a lamp move (lamp paths + relight)"}[kind]
    return Method(f"{backend}-edit", f"{_grid_label(settings)} {kind}", prepare, texture_bytes(settings.probes),
                  about=f"{backend} solver, time from {what} to converged probes")


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
        return lambda scene, points: field.solve(scene, include_emitted=True)

    try:
        label = str(path.resolve().relative_to(root))
    except ValueError:
        label = str(path)
    return Method("neural", label, prepare, texture_bytes(card.probes), path.stat().st_size,
                  about=f"ONNX network, {card.data.get('parameters', '?')} parameters, {card.probes}^3 probes")


def neural_methods(quick: bool = False) -> Iterable[Method]:
    from viewer.neural.field import ModelError

    for path in model_files()[:1] if quick else model_files():
        try:
            yield neural_method(path)
        except ModelError as exc:
            print(f"bench: skipping {path}: {exc}", file=sys.stderr, flush=True)


# ---- the registry -----------------------------------------------------------------------------------

PROVIDERS: list[Callable[[bool], Iterable[Method]]] = [neural_methods]
"""Functions quick -> methods, asked each time the registry is built: the shipped and swept ProbeNets,
and what others register, such as the paper's families (Table 1) where `python -m viewer.training.table1`
has exported them (viewer/bench/run.py registers `paper_families.paper_family_methods`: that module builds
on this one)."""


def register_provider(provider: Callable[[bool], Iterable[Method]]) -> None:
    if provider not in PROVIDERS:
        PROVIDERS.append(provider)


class _ScreenEdit:
    """An edit's time to converged GI on screen: the viewer itself, headless (viewer/bench/headless.py, the
    renderer's lightmap weights on their worker as in the window), from the edit made as the panels make
    it (SceneEdits) to the settled full-resolution frame: the GI source's probes in, the indirect lightmap
    baked and gathered from them (viewer/bench/edits.py times the same, with the first frame beside).
    Untimed (`before`), the scene is edited away and settled; timed, the edit comes back. The error is the
    source's field of the scene itself, computed once untimed: the compute source's is the physical GI's
    (the two relights agree to 1e-3), the neural source's the network's. `kind`: `colour` (the largest
    group's albedo) or `lamp` (the lamp moved by a twentieth of the scene: new geometry for the renderer)."""

    def __init__(self, source: str, kind: str):
        self.source, self.kind = source, kind
        self.viewer = None
        self.scene_name = None
        self.field: ProbeGrid | None = None
        atexit.register(self.release)

    def release(self) -> None:
        if self.viewer is not None:
            self.viewer.release()
            self.viewer = None

    def _open(self, scene: Scene) -> None:
        from viewer.bench.headless import HeadlessViewer

        self.release()
        self.viewer = HeadlessViewer(self.source, DEFAULT, scene)
        self.viewer.renderer.background_bake = True
        self.viewer.settle()
        self.scene_name = scene.name
        if self.viewer.session.edits.light.group is None and self.kind == "lamp":
            raise MethodUnavailable("the scene has no lamp to move")
        if self.source == "neural":
            from viewer.neural.field import NeuralField

            self.field = NeuralField().solve(scene, include_emitted=True)
        else:
            self.field = solve(scene, DEFAULT, include_emitted=True)

    def _edit(self, away: bool) -> None:
        edits = self.viewer.session.edits
        if self.kind == "colour":
            base = edits.base
            group = base.largest_group()
            rgb = base.group_albedo(group)
            edits.set_albedo(group, rgb[::-1] * 0.5 if away else rgb)
        else:
            lo, hi = edits.base.bounds
            offset = np.zeros(3)
            offset[0] = 0.05 * float(hi[0] - lo[0]) if away else 0.0
            edits.set_light(offset=offset)
        self.viewer.settle()

    def before(self, scene: Scene) -> None:
        if self.scene_name != scene.name:
            self._open(scene)
        self._edit(away=True)

    def __call__(self, scene: Scene, points) -> ProbeGrid:
        self._edit(away=False)
        return self.field


def screen_edit_method(source: str, kind: str) -> Method:
    def prepare() -> Produce:
        if source == "neural":
            from viewer.neural.field import DEFAULT_MODEL

            if not DEFAULT_MODEL.exists():
                raise MethodUnavailable(f"no model at {DEFAULT_MODEL}")
        _gl()   # a GL context can be made here
        return _ScreenEdit(source, kind)

    what = {"colour": "a colour edit", "lamp": "a lamp move"}[kind]
    return Method("screen-edit", f"{source} {kind}", prepare, texture_bytes(DEFAULT.probes),
                  about=f"the viewer with the {source} GI source, time from {what} to the settled frame on screen")


def registry(quick: bool = False) -> dict[str, Method]:
    """Every method, in report order. Quick: a handful that together take well under a minute."""
    if quick:
        small = GISettings(voxels=16, probes=8)
        methods = [ambient_method(), *(mitsuba_points_method(d) for d in (16, 64, 256)),
                   numpy_method(GISettings(voxels=8, probes=8)), compute_method(small),
                   edit_method(small, "colour", "compute"), mitsuba_probes_method(8, 64)]
    else:
        # The numpy solver at 64^3 voxels would hold a 27730^2 transition matrix (6 GB) and take hours:
        # 64^3 runs on the compute solver only. At 32^3 its bounces cost little beside the transition
        # matrix and the probe projection, so its bounce sweep would repeat one time four times.
        methods = [ambient_method()]
        methods += [compute_method(s) for s in solver_grid()]
        methods += [compute_method(replace(DEFAULT, kernel="paper"))]
        methods += [numpy_method(replace(DEFAULT, voxels=16)), numpy_method(DEFAULT),
                    numpy_method(replace(DEFAULT, voxels=16, kernel="paper"))]
        methods += [edit_method(DEFAULT, kind, backend) for backend in ("compute", "numpy")
                    for kind in ("colour", "lamp")]
        methods += [screen_edit_method(source, kind) for source in ("compute", "neural") for kind in ("colour", "lamp")]
        methods += [mitsuba_points_method(d) for d in (16, 64, 256, 1024)]
        methods += [mitsuba_probes_method(m, d) for m, d in ((8, 64), (16, 64), (16, 256), (24, 256), (32, 256))]
    for provider in PROVIDERS:
        methods += list(provider(quick))
    return {m.name: m for m in methods}

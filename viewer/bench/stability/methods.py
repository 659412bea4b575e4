"""The methods the stability suite compares, in one registry: name -> callable(scene, settings) -> ProbeGrid.

Every method answers the same question as `python -m viewer sample`: the incident-radiance SH field over
the scene (`include_emitted=True`, as compared with Mitsuba) or its indirect part only (False, what the
renderer shades from probes). A new method is one entry, as the neural field's:

    METHODS["neural"] = Method(_neural, "the shipped network ...", leak_reduction=False, resolution=False)

A method that cannot run here (no GL context, no model file) raises `MethodUnavailable`; the studies
record it as skipped, with its reason, and go on.
"""

from __future__ import annotations

import atexit
from dataclasses import dataclass, replace
from typing import Callable

import numpy as np

from viewer.physical import gi
from viewer.evaluation.points import free_space_points
from viewer.evaluation.truth import truth_sh
from viewer.probes.grid import ProbeGrid
from viewer.scene import Scene


class MethodUnavailable(RuntimeError):
    """The method cannot run on this machine; the message says why."""


@dataclass(frozen=True)
class MethodSettings:
    gi: gi.GISettings = gi.GISettings(voxels=16, probes=16, directions=256)
    """Resolution and options (a method ignores what does not apply to it, e.g. the kernel)."""
    include_emitted: bool = True
    """With the light straight from emitters and sun (as `sample`), or the indirect light only."""


@dataclass(frozen=True)
class Method:
    solve: Callable[[Scene, MethodSettings], ProbeGrid]
    about: str
    """One line for the report."""
    leak_reduction: bool = True
    """Whether `gi.invalid_backface_fraction` (probe validity and fill) means anything to it."""
    resolution: bool = True
    """Whether `GISettings.voxels` and `probes` reach it: a study that varies them runs it once."""


def _numpy(kernel: str):
    def solve(scene: Scene, settings: MethodSettings) -> ProbeGrid:
        return gi.solve(scene, replace(settings.gi, kernel=kernel), include_emitted=settings.include_emitted)
    return solve


_shared: dict[str, object] = {}


def _once(name: str, make, unavailable: type[Exception]):
    """What `make()` builds, built once for the whole run; MethodUnavailable (its message) when `make`
    raises `unavailable`."""
    if name not in _shared:
        try:
            _shared[name] = make()
        except unavailable as exc:
            raise MethodUnavailable(str(exc)) from None
    return _shared[name]


def gl_context():
    """One headless GL context for the whole run (MethodUnavailable without EGL/GL 4.3)."""
    from viewer.gpu.context import GLUnavailable, create_context

    def make():
        context = create_context()
        atexit.register(context.release)
        return context
    return _once("gl", make, GLUnavailable)


def _compute(scene: Scene, settings: MethodSettings) -> ProbeGrid:
    from viewer.gpu.compute_relight import solve_probes

    return solve_probes(gl_context(), scene, replace(settings.gi, kernel="physical"),
                        include_emitted=settings.include_emitted)


AMBIENT_POINTS = 128
AMBIENT_DIRECTIONS = 512


def mean_incident_radiance(scene: Scene, include_emitted: bool = True) -> np.ndarray:
    """(3,) the SH DC coefficient of the incident radiance (or of its indirect part) averaged over
    free-space points, from Mitsuba."""
    points = free_space_points(scene, AMBIENT_POINTS, margin=0.06, seed=11)
    return truth_sh(scene, points, AMBIENT_DIRECTIONS, include_emitted)[:, 0].mean(axis=0)


def _ambient(scene: Scene, settings: MethodSettings) -> ProbeGrid:
    """A constant ambient light: one probe whose only SH term is the scene's mean (DC) radiance."""
    coefficients = np.zeros((1, 1, 1, 9, 3), np.float32)
    coefficients[0, 0, 0, 0] = mean_incident_radiance(scene, settings.include_emitted)
    lo, hi = scene.bounds
    return ProbeGrid(lo, hi, coefficients, np.ones((1, 1, 1), bool))


def _path_traced_probes(scene: Scene, settings: MethodSettings) -> ProbeGrid:
    """Mitsuba at every probe centre: perfect probes, so what is left is the grid's own interpolation."""
    lo, hi = scene.bounds
    m = settings.gi.probes
    points = ProbeGrid.positions_for(lo, hi, m).reshape(-1, 3)
    coefficients = truth_sh(scene, points, PROBE_DIRECTIONS, settings.include_emitted)
    return ProbeGrid(lo, hi, coefficients.reshape(m, m, m, 9, 3), np.ones((m, m, m), bool))


PROBE_DIRECTIONS = 1024
def _neural(scene: Scene, settings: MethodSettings) -> ProbeGrid:
    """The shipped network (models/probenet.onnx) at the voxel and probe resolution it was trained at
    (its card's), whatever the settings say: one loaded model for the whole run."""
    from viewer.neural.field import ModelError, NeuralField

    return _once("neural", NeuralField, ModelError).solve(scene, include_emitted=settings.include_emitted)


METHODS: dict[str, Method] = {
    "solver": Method(_numpy("physical"), "numpy solver, form factor with visibility (the reference solver)"),
    "paper": Method(_numpy("paper"), "numpy solver, the paper's eq. 25 kernel (receiver cosine, no visibility)"),
    "compute": Method(_compute, "compute-shader solver (GLSL, physical kernel), as the viewer runs it"),
    "ambient": Method(_ambient, "constant ambient: Mitsuba's mean incident radiance as one SH DC term",
                      leak_reduction=False, resolution=False),
    "mitsuba-probes": Method(_path_traced_probes, "oracle: Mitsuba at the probe centres, interpolated like any "
                             "grid (the floor that the probe resolution sets)", leak_reduction=False),
    "neural": Method(_neural, "the shipped network (models/probenet.onnx, ONNX on the CPU), one shot at the "
                     "voxels and probes its card names (24^3 and 24^3 since 2026-11-25)", leak_reduction=False,
                     resolution=False),
}
"""Every method the studies run, in report order; the viewer's GI sources under their names in viewer.sources
(the CPU solver was `physical` here before: `method_names` and report.load still read that)."""


def method_names(names) -> list[str]:
    """Method names as a user or a saved result wrote them, under their names now (`physical` is `solver`)."""
    from viewer.sources import renamed

    return [renamed(name) for name in names]


def size_label(name: str, voxels: int, probes: int) -> str:
    """`voxels / probes` as a method ran them: the settings', or the model card's for the network (which
    ignores the settings), `-` for the constant."""
    if name == "ambient":
        return "-"
    if name == "neural":
        from viewer.neural.field import DEFAULT_MODEL, ModelCard

        try:
            card = ModelCard.read(DEFAULT_MODEL)
            return f"{card.voxels} / {card.probes}"
        except Exception:  # noqa: BLE001 - no model: the method is skipped anyway
            pass
    return f"{voxels} / {probes}"


def run(name: str, scene: Scene, settings: MethodSettings = MethodSettings()) -> ProbeGrid:
    return METHODS[name].solve(scene, settings)


def without_leak_reduction(settings: MethodSettings) -> MethodSettings:
    """Every probe valid: no probe is found inside a solid and filled from its neighbours."""
    return replace(settings, gi=replace(settings.gi, invalid_backface_fraction=1.0))

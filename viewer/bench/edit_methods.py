"""The benchmark's edit methods: the time from an edit to converged probes (`compute-edit`,
`solver-edit`: the physical GI relit on a scene whose geometry is already traced) and to the settled frame
on screen (`screen-edit`: the viewer itself, headless). The method table is viewer.bench.methods.
"""

from __future__ import annotations

import atexit

import numpy as np

from viewer import sources
from viewer.bench.methods import DEFAULT, Method, MethodUnavailable, Produce, grid_label, shared_gl, texture_bytes
from viewer.physical.gi import GISettings, solve
from viewer.probes.grid import ProbeGrid
from viewer.scene import Scene


def moved_a_tenth(scene: Scene, group: str) -> Scene:
    """`scene` with `group` moved by a tenth of the scene's width (along x) as a user drags it: along the
    floor, a wall or the ceiling it rests on, towards the scene's centre, so that it stays in the room. The
    first of x and z along which the group is not flat and the move keeps it within the scene's bounds;
    else x towards the centre. (Along +x alone, a lamp on a room's +x wall left the room.)"""
    lo, hi = scene.bounds
    step = 0.1 * float(hi[0] - lo[0])
    corners = scene.triangles[scene.face_group == scene.group_index(group)].reshape(-1, 3)
    low, high = corners.min(axis=0), corners.max(axis=0)
    centre = 0.5 * (lo + hi) - 0.5 * (low + high)
    move = np.eye(4)
    for axis in (0, 2):
        shift = step if centre[axis] >= 0 else -step
        if high[axis] - low[axis] > 1e-9 * step and lo[axis] <= low[axis] + shift and high[axis] + shift <= hi[axis]:
            move[axis, 3] = shift
            return scene.transformed_group(group, move)
    move[0, 3] = step if centre[0] >= 0 else -step
    return scene.transformed_group(group, move)


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
        return moved_a_tenth(scene, group)

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
    """`backend`: the source that relights, `solver` (on the CPU) or `compute` (in compute shaders)."""
    source = sources.lookup(backend)

    def prepare() -> Produce:
        if not source.needs.gl:
            return Edit(settings, kind)
        from viewer.gpu.compute_relight import ComputeRelight

        ctx, programs = shared_gl()
        return Edit(settings, kind, lambda: ComputeRelight(ctx, programs))

    what = {"colour": "a colour edit (the relight)", "lamp": "a lamp move (lamp paths + relight)"}[kind]
    return Method(f"{source.name}-edit", f"{grid_label(settings)} {kind}", prepare, texture_bytes(settings.probes),
                  about=f"{source.label}, time from {what} to converged probes")


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
        if self.source == sources.NEURAL.name:
            from viewer.neural.field import NeuralField

            self.field = NeuralField().solve(scene, include_emitted=True)
        else:
            self.field = solve(scene, DEFAULT, include_emitted=True)

    def _edit(self, away: bool) -> None:
        self.viewer.edited()
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
        self.viewer.settle(paced=True)

    def before(self, scene: Scene) -> None:
        if self.scene_name != scene.name:
            self._open(scene)
        self._edit(away=True)

    def __call__(self, scene: Scene, points) -> ProbeGrid:
        self._edit(away=False)
        return self.field


def screen_edit_method(source: str, kind: str) -> Method:
    """`source`: the viewer's GI source, `compute` or `neural`."""
    source = sources.canonical(source)

    def prepare() -> Produce:
        if source == sources.NEURAL.name:
            from viewer.neural.field import DEFAULT_MODEL

            if not DEFAULT_MODEL.exists():
                raise MethodUnavailable(f"no model at {DEFAULT_MODEL}")
        shared_gl()   # a GL context can be made here
        return _ScreenEdit(source, kind)

    what = {"colour": "a colour edit", "lamp": "a lamp move"}[kind]
    return Method("screen-edit", f"{source} {kind}", prepare, texture_bytes(DEFAULT.probes),
                  about=f"the viewer with the {source} GI source, time from {what} to the settled frame on screen")

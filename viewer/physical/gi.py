"""One call from a Scene to its probe grid with the physical solver, and the cached pipeline behind it.

The `physical` kernel runs in two stages (viewer.physical.geometry traces the scene once; viewer.physical.relight lights
it in milliseconds), kept by `PhysicalGI` across edits: a colour or intensity edit re-runs the relight
only, a lamp move the lamp paths and the relight, a geometry change everything. The paper's kernel
(eq. 25, no visibility) stays on the all-pairs transition matrix of viewer.physical.transport, as the comparison
it is.

The settings here are the product defaults; `python -m viewer sample` and the viewer's "CPU solver" GI
source both come through `solve`.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from viewer.physical import geometry
from viewer.physical import lightpaths
from viewer.physical import projection
from viewer.probes import grid as probes
from viewer.physical import relight
from viewer.physical import retrace
from viewer.physical import transport
from viewer.rays import voxels
from viewer.rays.raymarch import Tracer
from viewer.scene import Scene
from viewer.rays.voxel_faces import FaceVoxels


@dataclass(frozen=True)
class GISettings:
    voxels: int = 32
    """N: voxels per axis."""
    probes: int = 24
    """M: probes per axis over the scene bounds. Measured against Mitsuba (docs/ACCURACY.md): 16 gives
    about 6% relative RMSE on the Cornell boxes, 24 about 4%, within the product goal of 5%."""
    kernel: str = "physical"
    """Light transition kernel: `physical` or `paper` (see viewer.physical.transport)."""
    bounces: int = 100
    """Most bounces summed (the solver stops earlier once converged)."""
    directions: int = 256
    """Directions gathered per probe for the reflected light. Physical kernel, against Mitsuba at
    free-space points on the eight benchmark scenes: 128, 256 and 512 give 4.2%, 4.1% and 4.1% (mean),
    and the relight's probe projection costs in proportion."""
    gather_rays: int = 64
    """Physical kernel: cosine-weighted rays gathered per voxel (the transport matrix's row length).
    32, 64 and 128 give the same error at free-space points (4.1%, the benchmark scenes)."""
    dering: float = 0.0
    """SH deringing strength (0 = off)."""
    invalid_backface_fraction: float = 0.25
    """Probes that see the back of surfaces in more than this fraction of directions are inside solid
    geometry: invalid, and filled from their valid neighbours (leak reduction, viewer.probes.grid). 1 turns it
    off (every probe valid); docs/STABILITY.md measures both."""
    normal_mode: str = "area"
    """Voxel normals: `area` (area-weighted) or `paper` (eq. 3)."""


@dataclass
class Timings:
    """Seconds spent in each stage."""

    stages: dict[str, float] = field(default_factory=dict)

    def __str__(self):
        parts = [f"{name} {seconds:.3f}s" for name, seconds in self.stages.items()]
        return ", ".join(parts + [f"total {sum(self.stages.values()):.3f}s"])


def solve(scene: Scene, settings: GISettings = GISettings(), include_emitted: bool = True,
          timings: Timings | None = None) -> probes.ProbeGrid:
    return solve_parts(scene, settings, (include_emitted,), timings)[0]


def solve_parts(scene: Scene, settings: GISettings = GISettings(), parts: tuple[bool, ...] = (True, False),
                timings: Timings | None = None) -> list[probes.ProbeGrid]:
    """One transport solve projected once per entry of `parts`: with the emitted light (True, what
    `sample` returns) or without it (False, the indirect light the renderer shades from the probes)."""
    timings = timings if timings is not None else Timings()
    if settings.kernel == "physical":
        gi = PhysicalGI(settings)
        gi.update(scene, timings)
        return [gi.probe_grid(include_emitted, timings) for include_emitted in parts]
    clock = time.perf_counter()

    def lap(name):
        nonlocal clock
        now = time.perf_counter()
        timings.stages[name] = timings.stages.get(name, 0.0) + now - clock
        clock = now

    grid = voxels.voxelize(scene, settings.voxels, settings.normal_mode)
    tracer = Tracer.build(grid)
    lap("voxelize")
    g = transport.transition_matrix(grid, settings.kernel, tracer)
    lap("transition")
    light = transport.solve(grid, scene.sun, transport.TransportSettings(settings.kernel, settings.bounces),
                            transition=g, tracer=tracer)
    lap("bounces")
    results = []
    for include_emitted in parts:
        probe_settings = projection.ProbeSettings(resolution=settings.probes, directions=settings.directions,
                                              include_emitted=include_emitted, dering=settings.dering,
                                              invalid_backface_fraction=settings.invalid_backface_fraction)
        results.append(projection.project(grid, light, scene.sun, scene.bounds, probe_settings, tracer))
    lap("probes")
    return results


def geometry_settings(settings: GISettings) -> geometry.GeometrySettings:
    return geometry.GeometrySettings(voxels=settings.voxels, probes=settings.probes,
                                     gather_rays=settings.gather_rays, directions=settings.directions,
                                     normal_mode=settings.normal_mode,
                                     invalid_backface_fraction=settings.invalid_backface_fraction)


class PhysicalGI:
    """The physical GI of a scene and its edits: each stage's result is kept while what it depends on
    stays the same, and the last solution warm-starts the next relight.

    `update(scene)` brings everything up to date and returns the stages it ran; `probe_grid` then
    projects. `relighter` does the sweeps and the projection (viewer.physical.relight on the CPU by default;
    viewer.gpu.compute_relight runs them in compute shaders)."""

    def __init__(self, settings: GISettings = GISettings(), relighter=relight):
        self.settings = settings
        self.relighter = relighter
        self.geometry: geometry.Geometry | None = None
        self.face_voxels: FaceVoxels | None = None
        """The geometry's voxels per (voxel, face) pair: a move of some faces is voxelized from them alone."""
        self.lights: lightpaths.LightPaths | None = None
        self.sun: geometry.SunPaths | None = None
        self.materials: relight.Materials | None = None
        self._albedo: voxels.VoxelAlbedo | None = None
        self._last_emission: tuple | None = None
        self.lighting: relight.Lighting | None = None

    def update(self, scene: Scene, timings: Timings | None = None, stale_geometry: bool = False,
               bounces: int | None = None) -> list[str]:
        """Bring the solution up to date with `scene`; returns the stages that ran ("geometry",
        "lights", "sun": what was traced; "relight" always). With `stale_geometry` a changed geometry is
        not traced again when only the lamps moved: the viewer's quick answer to a lamp drag, with the
        lamp's own occlusion where it was before. `bounces` truncates this relight (the viewer shows
        a new scene's first bounce before the rest)."""
        timings = timings if timings is not None else Timings()
        prepared = self.prepare(scene, stale_geometry, timings)
        self.install(prepared)
        self.relight(scene, timings, bounces)
        return prepared.ran + ["relight"]

    def prepare(self, scene: Scene, stale_geometry: bool = False, timings: Timings | None = None) -> "Prepared":
        """The tracing `scene` needs (geometry, lamp paths, sun paths), without changing this object:
        it can run on a worker thread (the traces are compiled code that releases the GIL) while the
        render thread keeps relighting with what is installed."""
        timings = timings if timings is not None else Timings()
        clock = time.perf_counter()
        wanted = geometry_settings(self.settings)
        found, lights, sun, ran = self.geometry, self.lights, self.sun, []
        face_voxels, retraced = self.face_voxels, None
        if not self.geometry_fits(scene, stale_geometry):
            found, face_voxels, retraced = self._traced(scene, wanted, timings)
            lights, sun = None, None
            clock = time.perf_counter()
            ran.append("geometry")
        if lights is None or lights.key != lightpaths.lights_key(scene, found):
            lights = lightpaths.build(scene, found)
            ran.append("lights")
        if sun is None or not _same_direction(sun.direction, None if scene.sun is None else scene.sun.direction):
            sun = geometry.sun_paths(found, scene.sun)
            ran.append("sun")
        if ran:
            timings.stages["geometry"] = timings.stages.get("geometry", 0.0) + time.perf_counter() - clock
        return Prepared(found, lights, sun, ran, face_voxels, retraced)

    def _traced(self, scene: Scene, wanted: geometry.GeometrySettings,
                timings: Timings) -> tuple[geometry.Geometry, FaceVoxels | None, dict | None]:
        """(the geometry of `scene`, its voxels per face, what viewer.physical.retrace traced again or None): when
        only some faces moved since the installed geometry (a lamp dragged), voxelized from the moved
        faces and traced again only where they can change a ray (the same hits); else voxelized and
        traced afresh."""
        clock = time.perf_counter()
        before, moved = self.geometry, None
        if before is not None and before.settings == wanted and self.face_voxels is not None:
            moved = self.face_voxels.moved(scene)
        if wanted.normal_mode == "area":
            face_voxels = moved or FaceVoxels.of(scene, wanted.voxels)
            voxelization = face_voxels.voxelization(scene)
        else:
            face_voxels, voxelization = None, voxels.voxelize_with_faces(scene, wanted.voxels, wanted.normal_mode)
        now = time.perf_counter()
        timings.stages["voxelize"] = timings.stages.get("voxelize", 0.0) + now - clock
        stats: dict | None = {}
        found = retrace.after_moving(before, scene, voxelization, stats) if moved is not None else None
        if found is None:
            found, stats = geometry.trace(scene, voxelization, wanted), None
        timings.stages["geometry"] = timings.stages.get("geometry", 0.0) + time.perf_counter() - now
        return found, face_voxels, stats

    def needs_tracing(self, scene: Scene, stale_geometry: bool = False) -> bool:
        """Whether `scene` needs more than a relight (cheap to ask: it hashes the triangles)."""
        if self.lights is None or self.sun is None or not self.geometry_fits(scene, stale_geometry):
            return True
        return (self.lights.key != lightpaths.lights_key(scene, self.geometry)
                or not _same_direction(self.sun.direction, None if scene.sun is None else scene.sun.direction))

    def geometry_fits(self, scene: Scene, stale_geometry: bool = False) -> bool:
        """Whether the traced geometry serves `scene`: it is the scene's own, or (with `stale_geometry`)
        the scene differs only where faces moved, as when a lamp is dragged."""
        g = self.geometry
        if g is None:
            return False
        if g.key == geometry.scene_key(scene, geometry_settings(self.settings)):
            return True
        return stale_geometry and g.faces.shape[1] == len(scene.faces)

    def install(self, prepared: "Prepared") -> None:
        if prepared.geometry is not self.geometry:
            self.lighting = None
        self.geometry, self.lights, self.sun = prepared.geometry, prepared.lights, prepared.sun
        self.face_voxels = prepared.face_voxels

    def relight(self, scene: Scene, timings: Timings | None = None, bounces: int | None = None) -> relight.Lighting:
        """The relight stage: the scene's colours and lights on the installed geometry."""
        clock = time.perf_counter()
        g = self.geometry
        if self._albedo is None or self._albedo.faces is not g.faces:   # kept while the geometry is
            self._albedo = voxels.VoxelAlbedo(g.faces, g.tint, scene, voxels.voxel_albedo(g.faces, g.tint, scene))
        last = self._last_emission   # (the scene's emission, geometry, lamp paths) of the last materials
        same = last is not None and self.materials is not None and last[1] is g and last[2] is self.lights
        self.materials = relight.materials(scene, g, self.lights, self._albedo,
                                           (last[0], self.materials) if same else None)
        self._last_emission = (scene.emission, g, self.lights)
        settings = relight.RelightSettings(bounces=bounces or self._bounces())
        self.lighting = self.relighter.solve(self.geometry, self.lights, self.sun, self.materials, settings,
                                             self.lighting)
        if timings is not None:
            timings.stages["relight"] = timings.stages.get("relight", 0.0) + time.perf_counter() - clock
        return self.lighting

    def _bounces(self) -> int | None:
        """The paper's truncated chain when fewer bounces are asked for than convergence needs."""
        return self.settings.bounces if self.settings.bounces < GISettings().bounces else None

    def probe_grid(self, include_emitted: bool = True, timings: Timings | None = None) -> probes.ProbeGrid:
        """The probes of the current solution (the projection is part of the relight: its time goes to
        `timings`' "relight")."""
        clock = time.perf_counter()
        c = self.relighter.probe_coefficients(self.geometry, self.lights, self.sun, self.materials,
                                              self.lighting, include_emitted)
        grid = relight.probe_grid(self.geometry, c, self.settings.dering)
        if timings is not None:
            timings.stages["relight"] = timings.stages.get("relight", 0.0) + time.perf_counter() - clock
        return grid


@dataclass(frozen=True)
class Prepared:
    """What PhysicalGI.prepare traced."""

    geometry: geometry.Geometry
    lights: lightpaths.LightPaths
    sun: geometry.SunPaths
    ran: list[str]
    face_voxels: FaceVoxels | None = None
    retraced: dict | None = None
    """viewer.physical.retrace's counts when the geometry came from the one before (faces moved), else None."""


def _same_direction(a, b) -> bool:
    if a is None or b is None:
        return a is None and b is None
    return bool(np.allclose(a, b, rtol=0, atol=1e-12))

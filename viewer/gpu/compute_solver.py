"""The compute-shader bounce solver: viewer.physical.transport + viewer.probes.grid on the GPU, a slice at a time.

The same light transport as the numpy solver (eq. 23-30), with the same quadrature, so that the two
agree to float precision (tests/gpu/test_compute_solver.py):

    B1 = albedo / pi * E_direct                          (fine light samples + sun, compute_direct)
    B_k+1 = albedo / pi * s_i * sum_j G_ij B_k,j          (one dispatch over receivers, compute_bounce)
    reflected = B1 + B2 + ...  until a bounce adds less than `tolerance` of it

with G the `physical` or `paper` kernel and s_i the row clamp to pi. The physical kernel's visibility
is traced once into a bitset of facing-and-visible pairs (K^2 / 16 bytes, the upper triangle of a
symmetric matrix; at 32^3 voxels and above far pairs share their clusters' visibility, as in
transport._Visibility), after which a bounce is pure arithmetic over the set bits. After every bounce the
probes are projected again (cheap: their first hits are stored) and written into the renderer's
textures, so the picture brightens bounce by bounce.

Progressive: `step(budget_ms)` runs slices of the current pass (ranges of receivers, probes or bitset
rows, sized from the time per item of the last slice to fit the time left) until the budget is spent,
and leaves a slice that would not fit to the next step, so a viewer calling it once per frame keeps
its frame rate. `restart` starts over when the scene or a light
changes, keeping the visibility bitset and the probe hits while the geometry is the same. The passes
themselves live in compute_transport.py (voxels) and compute_probes.py (probes).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, replace

import moderngl
import numpy as np

from viewer.physical.gi import GISettings, Timings
from viewer.gpu.compute_probes import ComputeProbes
from viewer.gpu.compute_scene import ComputeScene, same_geometry
from viewer.gpu.compute_transport import MAX_GROUPS, RECEIVERS, VISIBILITY_MODES, ComputeTransport, rows_per_dispatch
from viewer.gpu.programs import ProgramLibrary, shared_library
from viewer.physical.projection import ProbeSettings
from viewer.probes.grid import ProbeGrid
from viewer.scene import DirectionalLight, Scene
from viewer.physical.transport import KERNELS, TransportSettings
from viewer.rays.voxels import VoxelGrid, voxelize

_KEEP = object()
SLICE_SHARE = 0.7
"""While stepping, a slice is sized to take this share of the step's time left (the time per item varies
along a pass: the visibility table's rows shorten, receivers differ in their senders)."""


@dataclass(frozen=True)
class ComputeSettings:
    """How the GPU solver works; what it computes comes from GISettings."""

    visibility: str = "auto"
    """Physical kernel: `bitset` traces V_ij once into a table that every bounce reads; `on-the-fly`
    traces it again in every bounce (no table, but each bounce then costs what building it does);
    `auto`: the bitset when it fits in one shader storage block."""
    tolerance: float = TransportSettings().tolerance
    """Stop once a bounce adds less than this fraction of the light gathered so far (as numpy)."""
    extrapolate: bool = TransportSettings().extrapolate
    """If the bounces run out first, add the geometric tail of the remaining ones (as numpy)."""
    probe_update_share: float = 0.5
    """While stepping, update the probe textures after a bounce once the bounces since the last update
    took at least (1 - share) / share times as long as an update: at most about this share of the GPU
    time goes to updates (they cost more than a bounce on small grids with many probes). `run` updates
    them once, at the end."""
    texture_dtype: str = "f2"
    """Probe textures: `f2` (RGBA16F, as the renderer's ProbeTextures) or `f4` (RGBA32F)."""
    textures_include_emitted: bool = False
    """Textures with the light straight from emitters and sun (False: indirect only, for rendering)."""

    def __post_init__(self):
        if self.visibility not in VISIBILITY_MODES:
            raise ValueError(f"visibility must be one of {VISIBILITY_MODES}, not {self.visibility!r}")
        if self.texture_dtype not in ("f2", "f4"):
            raise ValueError(f"texture_dtype must be 'f2' or 'f4', not {self.texture_dtype!r}")
        if not 0.0 < self.probe_update_share <= 1.0:
            raise ValueError(f"probe_update_share must be in (0, 1], not {self.probe_update_share}")


class ComputeSolver:
    """Progressive GPU light transport for one VoxelGrid; its probes in `textures` (indirect light)."""

    def __init__(self, ctx: moderngl.Context, voxels: VoxelGrid, sun: DirectionalLight | None = None,
                 settings: GISettings = GISettings(), bounds=None, options: ComputeSettings = ComputeSettings(),
                 programs: ProgramLibrary | None = None):
        self.ctx = ctx
        # compiled once per context, not per solver: a solver per solve must not compile them again
        self.programs = programs if programs is not None else shared_library(ctx)
        self.options = options
        self.scene: ComputeScene | None = None
        self.transport: ComputeTransport | None = None
        self.probes: ComputeProbes | None = None
        self.sun, self.settings = sun, settings
        self._probes_ready = False
        self._item_seconds: dict[str, float] = {}   # per pass: seconds per item of its last slice
        self.restart(voxels, sun, settings, bounds)

    # ---- control -------------------------------------------------------------------------------------
    def restart(self, voxels: VoxelGrid | None = None, sun=_KEEP, settings: GISettings | None = None,
                bounds=None) -> None:
        """Start over with a changed scene, lights or settings (None / left out: unchanged). While the
        geometry (and which voxels emit) is the same, the visibility bitset and the probes' first hits
        are kept."""
        voxels = voxels if voxels is not None else self.scene.voxels
        sun = self.sun if sun is _KEEP else sun
        settings = settings or self.settings
        if settings.kernel not in KERNELS:
            raise ValueError(f"kernel must be one of {KERNELS}, not {settings.kernel!r}")
        lo, hi = bounds if bounds is not None else (
            (self.probes.lo, self.probes.hi) if self.probes is not None else (voxels.lo, voxels.hi))
        geometry_kept = self.scene is not None and same_geometry(self.scene.voxels, voxels)
        if not geometry_kept:
            self._release_scene()
            self.scene = ComputeScene(self.ctx, voxels)
            self.transport = ComputeTransport(self.ctx, self.programs, self.scene)
        self.scene.set_lights(voxels, sun)
        self.transport.configure(settings.kernel, self.options.visibility)
        probe_settings = ProbeSettings(resolution=settings.probes, directions=settings.directions,
                                       dering=settings.dering,
                                       invalid_backface_fraction=settings.invalid_backface_fraction)
        probes_kept = (geometry_kept and self.probes is not None and np.array_equal(self.probes.lo, lo)
                       and np.array_equal(self.probes.hi, hi)
                       and replace(self.probes.settings, dering=settings.dering) == probe_settings)
        if probes_kept:
            self.probes.settings = probe_settings
        else:
            if self.probes is not None:
                self.probes.release()
            self.probes = ComputeProbes(self.ctx, self.programs, self.scene, lo, hi, probe_settings,
                                        self.options.texture_dtype, self.options.textures_include_emitted)
        self.probes.compile()
        self.sun, self.settings = sun, settings
        self._probes_ready = probes_kept and self._probes_ready
        self._emitted_ready = False
        self._work = self._schedule()
        self._budget: float | None = None
        self.converged = False
        self.bounces = 0
        """Bounces summed so far (as transport.Radiosity.bounces)."""
        self.phase = "starting"
        """What the solver is doing now, for the UI."""
        self.version = 0
        """Counts the updates of the probe textures."""
        self.seconds: dict[str, float] = {}
        """GPU seconds per pass since the restart (glFinish-timed)."""
        self.bounce_seconds: list[float] = []
        """Seconds of each bounce from the second on."""
        self.update_seconds: list[float] = []
        """Seconds of each update of the probes (projection, fill, textures)."""

    def step(self, budget_ms: float = 8.0) -> bool:
        """Work for at most about `budget_ms` (at least one slice); True if the probe textures changed.
        Slices are sized from the time per item of the pass's last slice to fit the time left, and a
        slice that would not fit waits for the next step, so a viewer calling this once a frame keeps
        its frame rate."""
        if self.converged:
            return False
        self._budget = budget_ms / 1000.0
        self._deadline = time.perf_counter() + self._budget
        self._slices_run, self._out_of_time = 0, False
        version = self.version
        while not self.converged and not self._out_of_time and time.perf_counter() < self._deadline:
            self._advance()
        return self.version != version

    def run(self) -> "ComputeSolver":
        """Work until converged, in whole passes."""
        self._budget = None
        while not self.converged:
            self._advance()
        return self

    def _advance(self) -> None:
        try:
            next(self._work)
        except StopIteration:
            self.converged = True
            self.phase = "converged"

    # ---- results -------------------------------------------------------------------------------------
    @property
    def textures(self):
        """The probe grid's seven RGBA 3D textures (viewer.gpu.probe_textures.ProbeTextures)."""
        return self.probes.textures

    @property
    def valid(self) -> np.ndarray:
        """(M, M, M) bool: probes outside solid geometry (see viewer.probes.grid.ProbeGrid.valid)."""
        return self.probes.valid

    @property
    def visibility_bytes(self) -> int:
        """GPU memory held by the visibility bitset (0 without one)."""
        return self.transport.bitset_bytes

    def probe_grid(self, include_emitted: bool = True) -> ProbeGrid:
        """The probe grid as last projected (read back; while stepping, call it between updates, i.e.
        when step() returned True); include_emitted as in viewer.probes.grid."""
        if include_emitted and not self._emitted_ready:
            raise RuntimeError("the emitted light is not projected yet; step() further first")
        return self.probes.grid(include_emitted)

    def reflected(self) -> np.ndarray:
        """(K, 3) reflected radiance of every voxel: the bounces summed so far."""
        return self.transport.read("reflected")

    def radiance(self) -> np.ndarray:
        """(K, 3) outgoing radiance B = Le + reflected (transport.Radiosity.radiance)."""
        return self.scene.voxels.emission + self.reflected()

    def direct_irradiance(self) -> np.ndarray:
        """(K, 3) irradiance straight from the emitters and the sun."""
        return self.transport.read("direct")

    def release(self) -> None:
        if self.probes is not None:
            self.probes.release()
        self._release_scene()

    def _release_scene(self) -> None:
        for part in (self.transport, self.scene):
            if part is not None:
                part.release()
        self.transport = self.scene = None

    # ---- the work, in order --------------------------------------------------------------------------
    def _schedule(self):
        scene, transport, probes = self.scene, self.transport, self.probes
        self.phase = "direct light"
        transport.clear_stats()
        yield from self._sliced("direct light", scene.count, 64, transport.direct)
        self.bounces = 1
        converged = transport.converged(self.options.tolerance)
        if not self._probes_ready:
            self.phase = "probe rays"
            probes.clear_backfaces()
            yield from self._sliced("probe rays", probes.count, 1, probes.rays, MAX_GROUPS)
            probes.classify()
            self._probes_ready = True
        self.phase = "emitted light"
        yield from self._sliced("emitted light", probes.count, 64, probes.emitted)
        probes.fill("emitted")
        self._emitted_ready = True
        total = max(self.settings.bounces, 1)
        if self._budget is not None:
            yield from self._update_probes()
        if not converged and total > 1 and self.settings.kernel == "physical":
            if scene.clustered and not transport.clusters_ready:
                self.phase = "visibility"
                yield from self._sliced("cluster visibility", scene.clusters.count, 1, transport.cluster_rows,
                                        rows_per_dispatch(scene.clusters.count))
                transport.clusters_ready = True
            if transport.uses_bitset and not transport.bitset_ready:
                self.phase = "visibility"
                yield from self._sliced("visibility", scene.count, 1, transport.visibility_rows,
                                        rows_per_dispatch(scene.count))
                transport.bitset_ready = True
        since_update = 0.0
        while not converged and self.bounces < total:
            self.phase = f"bounce {self.bounces + 1}"
            transport.clear_stats()
            before = self.seconds.get("bounce", 0.0)
            yield from self._sliced("bounce", scene.count, RECEIVERS * 64, transport.bounce)
            self.bounce_seconds.append(self.seconds["bounce"] - before)
            since_update += self.bounce_seconds[-1]
            self.bounces += 1
            transport.end_bounce()
            converged = transport.converged(self.options.tolerance)
            if not converged and self._update_due(since_update):
                yield from self._update_probes()
                since_update = 0.0
        if not converged and self.options.extrapolate and self.bounces > 1:
            transport.add_tail()
        yield from self._update_probes()

    def _update_due(self, since_update: float) -> bool:
        """While stepping: the bounces since the last update took long enough (probe_update_share)."""
        if self._budget is None:
            return False
        share = self.options.probe_update_share
        last = self.update_seconds[-1] if self.update_seconds else 0.0
        return since_update * share >= last * (1.0 - share)

    def _sliced(self, name: str, total: int, unit: int, run, most: int | None = None):
        """Run `run(first, end)` over 0..total in slices: whole passes (up to `most` items) when blocking,
        else multiples of `unit` items sized to take SLICE_SHARE of the step's time left (one unit
        the first time a pass runs, when its cost is not known yet)."""
        start = 0
        while start < total:
            size = most or total
            if self._budget is not None:
                left = self._deadline - time.perf_counter()
                per_item = self._item_seconds.get(name)
                if per_item is not None and self._slices_run and per_item * unit > left:
                    self._out_of_time = True   # not even one unit fits: the next step goes on from here
                    yield
                    continue
                fits = unit if per_item is None else int(SLICE_SHARE * left / max(per_item, 1e-9))
                size = max(unit, min(fits // unit * unit, most or total))
            end = min(total, start + size)
            clock = time.perf_counter()
            run(start, end)
            self.ctx.finish()
            elapsed = time.perf_counter() - clock
            self.seconds[name] = self.seconds.get(name, 0.0) + elapsed
            if self._budget is not None:
                self._item_seconds[name] = elapsed / (end - start)
                self._slices_run += 1
            start = end
            yield

    def _update_probes(self):
        """Project the reflected light onto the probes (sliced), fill, and write the textures."""
        before = self.seconds.get("probe gather", 0.0)
        yield from self._sliced("probe gather", self.probes.count, 64, self._gather)
        clock = time.perf_counter()
        self.probes.fill("indirect")
        self.probes.store()
        self.ctx.finish()
        elapsed = time.perf_counter() - clock
        self.seconds["probe store"] = self.seconds.get("probe store", 0.0) + elapsed
        self.update_seconds.append(self.seconds["probe gather"] - before + elapsed)
        self.version += 1
        yield

    def _gather(self, first: int, end: int) -> None:
        self.probes.gather(self.transport.buffers["reflected"], first, end)


def solve_probes(ctx: moderngl.Context, scene: Scene, settings: GISettings = GISettings(),
                 include_emitted: bool = True, timings: Timings | None = None,
                 options: ComputeSettings = ComputeSettings()) -> ProbeGrid:
    """gi.solve on the GPU: voxelize, light, bounce and project in one blocking call."""
    timings = timings if timings is not None else Timings()
    clock = time.perf_counter()
    grid = voxelize(scene, settings.voxels, settings.normal_mode)
    timings.stages["voxelize"] = timings.stages.get("voxelize", 0.0) + time.perf_counter() - clock
    clock = time.perf_counter()
    solver = ComputeSolver(ctx, grid, scene.sun, settings, scene.bounds, options)
    try:
        solver.run()
        result = solver.probe_grid(include_emitted)
    finally:
        solver.release()
    timings.stages["compute"] = timings.stages.get("compute", 0.0) + time.perf_counter() - clock
    return result

"""The relight stage (viewer.physical.relight) in compute shaders: the relighter of gi.PhysicalGI on the GPU.

The geometry stage's results go to the GPU once per geometry: the transport matrix in CSR form and the
probes' hit lists, the same arrays the CPU relight reads. A relight then runs one dispatch per sweep
(shaders/relight_sweep.glsl: the paper's bounce, eq. 30) and one for the probe projection
(shaders/relight_probes.glsl). The convergence test and the Aitken tail stay on the CPU
(viewer.physical.relight.iterate), which reads each sweep back (K x 16 bytes): the GPU and the CPU relight then
take the same sweeps and agree to float rounding.
"""

from __future__ import annotations

import moderngl
import numpy as np

from viewer.physical import relight
from viewer.physical.geometry import Geometry, SunPaths
from viewer.gpu.programs import ProgramLibrary, set_uniforms, shared_library
from viewer.physical.lightpaths import LightPaths


def _vec4(rows: np.ndarray, extra_zero_row: bool = False) -> bytes:
    out = np.zeros((len(rows) + int(extra_zero_row), 4), np.float32)
    out[:len(rows), :3] = rows
    return out.tobytes()


class ComputeRelight:
    def __init__(self, ctx: moderngl.Context, programs: ProgramLibrary | None = None):
        self.ctx = ctx
        self.programs = programs or shared_library(ctx)   # compiled once per context, not per solver
        self.geometry: Geometry | None = None
        self.buffers: dict[str, moderngl.Buffer] = {}
        self._current = "ping"

    # ---- the geometry's arrays, once per geometry --------------------------------------------------------
    def _upload(self, geometry: Geometry) -> None:
        if self.geometry is geometry:
            return
        self.release()
        t = geometry.transport
        k, p = geometry.voxels.count, len(geometry.probe_hits)
        ctx = self.ctx
        self.buffers = {
            "row_start": ctx.buffer(t.indptr.astype(np.int32).tobytes()),
            "column": ctx.buffer(t.indices.astype(np.int32).tobytes() or bytes(4)),
            "weight": ctx.buffer(t.data.astype(np.float32).tobytes() or bytes(4)),
            "hits": ctx.buffer(geometry.probe_hits.astype(np.int32).tobytes()),
            "basis": ctx.buffer(geometry.probe_basis.astype(np.float32).tobytes()),
            "first": ctx.buffer(reserve=16 * k),
            "albedo": ctx.buffer(reserve=16 * k),
            "ping": ctx.buffer(reserve=16 * (k + 1)),
            "pong": ctx.buffer(reserve=16 * (k + 1)),
            "emission": ctx.buffer(reserve=16 * (k + 1)),
            "direct": ctx.buffer(reserve=4 * 27 * p),
            "indirect": ctx.buffer(reserve=4 * 27 * p),
            "emitted": ctx.buffer(reserve=4 * 27 * p),
        }
        for name in ("ping", "pong"):       # row K, what a probe direction that sees nothing finds, stays 0
            self.buffers[name].clear()
        self.geometry = geometry
        self.programs.get("relight_sweep")
        self.programs.get("relight_probes")

    def _dispatch(self, name: str, count: int, buffers: dict[int, str], **uniforms) -> None:
        program = self.programs.get(name)
        for binding, buffer in buffers.items():
            self.buffers[buffer].bind_to_storage_buffer(binding)
        set_uniforms(program, **uniforms)
        program.run(-(-count // 64), 1, 1)
        self.ctx.memory_barrier()

    # ---- the relighter ------------------------------------------------------------------------------------
    def solve(self, geometry: Geometry, lights: LightPaths, sun: SunPaths, mat: relight.Materials,
              settings: relight.RelightSettings = relight.RelightSettings(),
              previous: relight.Lighting | None = None) -> relight.Lighting:
        self._upload(geometry)
        first, direct = relight.first_bounce(geometry, lights, sun, mat)
        k = geometry.voxels.count
        self.buffers["first"].write(_vec4(first))
        self.buffers["albedo"].write(_vec4(mat.albedo))

        def correct(reflected: np.ndarray) -> None:
            self.buffers[self._current].write(_vec4(reflected))

        def sweep(_reflected: np.ndarray) -> np.ndarray:
            other = "pong" if self._current == "ping" else "ping"
            self._dispatch("relight_sweep", k, {0: "row_start", 1: "column", 2: "weight", 3: "first", 4: "albedo",
                                                5: self._current, 6: other}, voxel_count=k)
            self._current = other
            return np.frombuffer(self.buffers[other].read(size=16 * k), np.float32).reshape(k, 4)[:, :3].copy()

        reflected, sweeps = relight.iterate(first, sweep, settings, previous, correct)
        return relight.Lighting(reflected, direct, sweeps)

    def probe_coefficients(self, geometry: Geometry, lights: LightPaths, sun: SunPaths, mat: relight.Materials,
                           lighting: relight.Lighting, include_emitted: bool = True) -> np.ndarray:
        """(P, 9, 3) as viewer.physical.relight.probe_coefficients, projected on the GPU and read back."""
        self._upload(geometry)
        p, d = geometry.probe_hits.shape
        self.buffers[self._current].write(_vec4(lighting.reflected))
        gathered = bool(np.any(mat.emission > 0))
        if gathered:
            self.buffers["emission"].write(_vec4(mat.emission, extra_zero_row=True))
        if include_emitted:
            self.buffers["direct"].write(relight.direct_sh(geometry, lights, sun, mat).tobytes())
        else:
            self.buffers["direct"].clear()
        self._dispatch("relight_probes", p, {7: "hits", 8: "basis", 9: self._current, 10: "emission",
                                            11: "direct", 12: "emitted", 15: "indirect"},
                       probe_count=p, direction_count=d, with_emission=gathered)
        out = np.frombuffer(self.buffers["indirect"].read(), np.float32).reshape(p, 9, 3).copy()
        if include_emitted:
            out += np.frombuffer(self.buffers["emitted"].read(), np.float32).reshape(p, 9, 3)
        return out

    def release(self) -> None:
        for buffer in self.buffers.values():
            buffer.release()
        self.buffers = {}
        self.geometry = None


def solve_probes(ctx: moderngl.Context, scene, settings=None, include_emitted: bool = True, timings=None,
                 programs: ProgramLibrary | None = None):
    """gi.solve on the GPU, in one blocking call: the physical kernel through gi.PhysicalGI with this
    relighter (the geometry stage on the CPU), the paper's kernel through the all-pairs ComputeSolver."""
    from viewer.physical.gi import GISettings, PhysicalGI, Timings

    settings = settings or GISettings()
    timings = timings if timings is not None else Timings()
    if settings.kernel != "physical":
        from viewer.gpu.compute_solver import ComputeSolver
        from viewer.rays.voxels import voxelize

        solver = ComputeSolver(ctx, voxelize(scene, settings.voxels, settings.normal_mode), scene.sun, settings,
                               scene.bounds, programs=programs)
        try:
            return solver.run().probe_grid(include_emitted)
        finally:
            solver.release()
    relighter = ComputeRelight(ctx, programs)
    try:
        gi = PhysicalGI(settings, relighter)
        gi.update(scene, timings)
        return gi.probe_grid(include_emitted, timings)
    finally:
        relighter.release()

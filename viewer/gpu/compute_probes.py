"""Probe projection for the compute solver: viewer/probes/grid.py `project` as four GPU passes.

1. rays (geometry only, once per scene): the voxel each probe sees first along each direction of the
   same Fibonacci set as the numpy solver (viewer.probes.sh.sphere_directions with ProbeSettings' seed), and the
   fraction of directions that meet a surface's back (probes inside solids are invalid);
2. emitted (once per lighting): the SH of the light straight from the fine light samples and the sun;
3. gather (after every bounce): the SH of the reflected radiance along the stored first hits;
4. fill + store: invalid probes take their valid neighbours' mean (`fill_invalid`, one dispatch per
   wave of growth), then the deringing window, into seven RGBA 3D textures (ProbeTextures) for the
   renderer, without the emitted light (the renderer shades emitters and sun itself).

`grid()` reads the coefficients back as a ProbeGrid (float32, before the textures' half floats).
"""

from __future__ import annotations

import moderngl
import numpy as np

from viewer.probes import sh
from viewer.gpu.compute_scene import ComputeScene, even_ranges, vec4s
from viewer.gpu.probe_textures import ProbeTextures
from viewer.gpu.programs import ProgramLibrary
from viewer.physical.projection import ProbeSettings
from viewer.probes.grid import INVALID_WEIGHT, ProbeGrid, fill_waves

HIT_MEMORY_LIMIT = 64 << 20
"""Bytes of stored first hits (4 per probe and direction) above which the gather pass marches again."""


class ComputeProbes:
    def __init__(self, ctx: moderngl.Context, programs: ProgramLibrary, scene: ComputeScene, lo, hi,
                 settings: ProbeSettings, texture_dtype: str = "f2", textures_include_emitted: bool = False):
        self.ctx, self.programs, self.scene = ctx, programs, scene
        self.settings = settings
        self.lo, self.hi = np.asarray(lo, np.float64), np.asarray(hi, np.float64)
        m = settings.resolution
        self.count = m ** 3
        directions, weights = sh.sphere_directions(settings.directions, seed=settings.seed)
        self.direction_count = len(directions)
        self.stored_hits = 4 * self.count * self.direction_count <= HIT_MEMORY_LIMIT
        positions = ProbeGrid.positions_for(self.lo, self.hi, m).reshape(-1, 3)
        self.buffers = {
            "positions": ctx.buffer(vec4s(positions)),
            "directions": ctx.buffer(vec4s(directions, weights)),
            "hits": ctx.buffer(reserve=4 * self.count * self.direction_count if self.stored_hits else 4),
            "backface": ctx.buffer(reserve=4 * self.count),
            "waves": ctx.buffer(reserve=4 * self.count),
            "indirect": ctx.buffer(reserve=4 * 27 * self.count),
            "emitted": ctx.buffer(reserve=4 * 27 * self.count),
        }
        self.valid = np.ones((m, m, m), bool)
        self.waves = np.zeros(self.count, np.int32)
        self.texture_dtype = texture_dtype
        self.textures_include_emitted = textures_include_emitted
        self.textures = ProbeTextures(ctx, ProbeGrid(self.lo, self.hi, np.zeros((m, m, m, 9, 3), np.float32),
                                                     self.valid), dtype=texture_dtype)

    def _gather_defines(self) -> dict:
        return {"STORED_HITS": int(self.stored_hits)}

    def _store_defines(self) -> dict:
        return {"PROBE_FORMAT": "rgba16f" if self.texture_dtype == "f2" else "rgba32f",
                "INCLUDE_EMITTED": int(self.textures_include_emitted)}

    def compile(self) -> None:
        for name in ("compute_probe_rays", "compute_probe_emitted", "compute_probe_fill"):
            self.programs.get(name)
        self.programs.get("compute_probe_gather", **self._gather_defines())
        self.programs.get("compute_probe_store", **self._store_defines())

    def _dispatch(self, name: str, groups: tuple[int, int], buffers: dict[int, moderngl.Buffer],
                  defines: dict | None = None, **uniforms) -> None:
        self.scene.dispatch(self.programs.get(name, **(defines or {})), groups, buffers, probe_count=self.count,
                            direction_count=self.direction_count, **uniforms)

    # ---- geometry: once per scene ---------------------------------------------------------------------
    def clear_backfaces(self) -> None:
        self.buffers["backface"].clear()

    def rays(self, first: int, end: int) -> None:
        """First hits of probes first..end-1."""
        b = self.buffers
        self._dispatch("compute_probe_rays", (-(-self.direction_count // 64), end - first),
                       {7: b["positions"], 8: b["directions"], 11: b["hits"], 12: b["backface"]},
                       first_probe=first, store_hits=self.stored_hits)

    def classify(self) -> None:
        """Validity from the backface counts, and the wave in which fill_invalid reaches each invalid
        probe (0: valid; -1: never, when no probe is valid and the grid stays dark)."""
        m = self.settings.resolution
        backface = np.frombuffer(self.buffers["backface"].read(), np.uint32).astype(np.float64)
        valid = backface / self.direction_count <= self.settings.invalid_backface_fraction
        self.valid = valid.reshape(m, m, m)
        self.waves = fill_waves(self.valid).reshape(-1)
        self.buffers["waves"].write(self.waves.astype(np.int32).tobytes())

    # ---- light ---------------------------------------------------------------------------------------
    def emitted(self, first: int, end: int) -> None:
        """SH of the light straight from emitters and sun at probes first..end-1."""
        b, s = self.buffers, self.scene
        for n, (e0, e1) in enumerate(s.emitter_chunks(2, 1)):
            self._dispatch("compute_probe_emitted", (-(-(end - first) // 64), 1),
                           {7: b["positions"], 9: s.light_samples, 10: s.emitters, 15: b["emitted"]},
                           first_probe=first, first_emitter=e0, end_emitter=e1, first_chunk=n == 0,
                           **s.light_uniforms())

    def gather(self, reflected: moderngl.Buffer, first: int = 0, end: int | None = None) -> None:
        """SH of the reflected radiance (K vec4) at probes first..end-1."""
        b = self.buffers
        end = self.count if end is None else end
        per_direction = 12 + (0 if self.stored_hits else self.scene.march_iterations)
        for n, (k0, k1) in enumerate(even_ranges(self.direction_count, per_direction)):
            self._dispatch("compute_probe_gather", (-(-(end - first) // 64), 1),
                           {7: b["positions"], 8: b["directions"], 11: b["hits"], 13: reflected,
                            15: b["indirect"]}, self._gather_defines(),
                           first_probe=first, first_direction=k0, end_direction=k1, first_chunk=n == 0)

    def fill(self, which: str) -> None:
        """fill_invalid on the `indirect` or `emitted` coefficients, wave by wave."""
        groups = (-(-self.count // 64), 1)
        for wave in range(1, int(self.waves.max(initial=0)) + 1):
            self._dispatch("compute_probe_fill", groups, {14: self.buffers["waves"], 15: self.buffers[which]},
                           probe_resolution=self.settings.resolution, wave=wave)

    def store(self) -> None:
        """The filled coefficients, deringed, into the seven textures."""
        half = self.texture_dtype == "f2"
        for unit, texture in enumerate(self.textures.textures):
            texture.bind_to_image(unit, read=False, write=True)
        b = self.buffers
        factors = sh.window_factors(self.settings.dering) if self.settings.dering > 0 else np.ones(9)
        self._dispatch("compute_probe_store", (-(-self.count // 64), 1),
                       {12: b["emitted"], 14: b["waves"], 15: b["indirect"]}, self._store_defines(),
                       probe_resolution=self.settings.resolution, dering=tuple(float(f) for f in factors),
                       texel_limit=65504.0 if half else 3.0e38, invalid_weight=INVALID_WEIGHT)

    # ---- reading back --------------------------------------------------------------------------------
    def grid(self, include_emitted: bool = True) -> ProbeGrid:
        m = self.settings.resolution
        c = np.frombuffer(self.buffers["indirect"].read(), np.float32).reshape(self.count, 9, 3).astype(np.float64)
        if include_emitted:
            c = c + np.frombuffer(self.buffers["emitted"].read(), np.float32).reshape(self.count, 9, 3)
        c[self.waves < 0] = 0.0
        if self.settings.dering > 0:
            c = sh.dering(c, self.settings.dering)
        return ProbeGrid(self.lo, self.hi, c.reshape(m, m, m, 9, 3).astype(np.float32), self.valid)

    def release(self) -> None:
        for buffer in self.buffers.values():
            buffer.release()
        self.textures.release()

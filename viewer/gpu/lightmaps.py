"""The renderer's lightmaps kept up to date: the shadow maps of the emitter samples and the sun, the
direct light baked into the lightmap (viewer/gpu/direct_bake.py) and the probes' indirect light baked
per texel (viewer/gpu/indirect_bake.py), each made again only when what it depends on changed.

`LightmapUpkeep` is a part of `viewer.gpu.renderer.Renderer` (its base class, working on the renderer's
own state), apart from the passes that draw with these lightmaps.
"""

from __future__ import annotations

import threading
import time
from concurrent.futures import Future

import moderngl
import numpy as np

from viewer.gpu.direct_bake import BakedDirectLight, fitted_texel, same_atlas
from viewer.gpu.gather_cast import caster_of
from viewer.gpu.indirect_bake import BakedIndirectLight
from viewer.gpu.lights import emitter_samples
from viewer.gpu.programs import set_uniforms
from viewer.gpu.shadows import EmitterShadows, SunShadow

AWAIT_PROBES = 0.25
"""Seconds that the indirect lightmap waits, after a colour or light edit, for the probes the GI source is
computing for it (`Renderer.probes_pending`), before it is gathered again with the old ones: gathering
twice, once for the old probes and once for the new, cost a Cornell box's colour edit 70 of its 125 ms."""

PROBE_UNIT, ATLAS_UNIT, SUN_UNIT, HDR_UNIT, INTERLEAVE_UNIT, BAKED_UNIT, INDIRECT_UNIT = 0, 7, 8, 9, 10, 14, 15
"""Texture units: the lightmaps' and the surface pass's, which reads them all in one draw."""


def power_ratio(old: np.ndarray, new: np.ndarray) -> np.ndarray | None:
    """(3,) the factor a channel that makes every light sample's `old` power (N, 3) its `new` one, or None
    where there is none (the lamps changed apart, or a channel was dark)."""
    total = old.sum(axis=0)
    if len(old) == 0 or np.any(total <= 0.0):
        return None
    ratio = new.sum(axis=0) / total
    return ratio if np.allclose(new, old * ratio, rtol=1e-5, atol=1e-9 * float(new.max(initial=0.0))) else None


def max_texture_side(ctx: moderngl.Context) -> int:
    """The longest side of a texture the context can make and render into (llvmpipe: 16384)."""
    info = ctx.info
    viewport = info.get("GL_MAX_VIEWPORT_DIMS", (16384, 16384))
    return int(min(info.get("GL_MAX_TEXTURE_SIZE", 16384), info.get("GL_MAX_RENDERBUFFER_SIZE", 16384),
                   *viewport))


def started(function, *args) -> Future:
    """`function(*args)`, started now on a thread of its own; its result (or error) in the future."""
    future = Future()

    def run() -> None:
        try:
            future.set_result(function(*args))
        except BaseException as exc:  # noqa: BLE001 - handed to whoever asks for the result
            future.set_exception(exc)

    threading.Thread(target=run, name="caster", daemon=True).start()
    return future


class LightmapUpkeep:
    """Shadow maps and lightmaps, made again when the triangles, the lights, the settings or the probes
    change (mixed into Renderer, whose attributes it reads and sets)."""

    probes_pending = False
    """Set by the viewer each frame: the GI source is computing probes for the scene shown (its last edit)."""
    _awaiting: float | None = None
    """Until when (perf_counter) the indirect lightmap shows its last gather after a colour or light edit."""

    def _stale_indirect(self, awaiting: bool) -> None:
        """The indirect lightmap is to be gathered again: for new probes, or (`awaiting`) for new colours or
        lights, whose probes a busy GI source brings within AWAIT_PROBES."""
        self._indirect_fresh = False
        self._awaiting = time.perf_counter() + AWAIT_PROBES if awaiting else None

    def _ensure_shadows(self) -> None:
        """The emitter samples' shadow cubes and the sun's map: rendered again when the triangles or the
        shadow settings change, or when the lights move; a light's new colour or intensity only changes
        the samples' powers."""
        s = self.settings
        key = (self._geometry, s.light_samples, s.shadow_tile, s.sun_shadow_size)
        if key == self._shadow_key:
            if self._shadows_for == self._scene_version:
                return
            self._shadows_for = self._scene_version
            power, sun = self._emitter_shadows.samples.power, self._sun_shadow.sun
            if (self._emitter_shadows.repower(emitter_samples(self.scene, s.light_samples))
                    and self._sun_shadow.resun(self.scene.sun)):
                same_sun = sun is None or np.array_equal(sun.irradiance, self._sun_shadow.sun.irradiance)
                if not (same_sun and np.array_equal(power, self._emitter_shadows.samples.power)):
                    self._relight(power, sun)   # an albedo edit leaves the direct irradiance as it was
                return
        for shadow in (self._emitter_shadows, self._sun_shadow):
            if shadow is not None:
                shadow.release()
        lo, hi = self.bounds
        depth = self.programs.get("shadow_depth")
        self._emitter_shadows = EmitterShadows(self.ctx, emitter_samples(self.scene, s.light_samples), lo, hi,
                                               s.shadow_tile)
        self._emitter_shadows.render(depth, self.mesh.render)
        self._sun_shadow = SunShadow(self.ctx, self.scene.sun, lo, hi, s.sun_shadow_size)
        self._sun_shadow.render(depth, self.mesh.render)
        self._shadow_key, self._shadows_for = key, self._scene_version
        self._lights += 1

    def _relight(self, power: np.ndarray, sun) -> None:
        """The lights' powers (or the sun's) changed, not their places: the lightmap baked again, or, where
        the lamps light the scene alone and all their samples' powers changed by one factor a channel (a
        lamp's colour or intensity, which a bake took 130 ms of a Cornell box's colour edit for), its
        irradiance scaled where it is read."""
        ratio = power_ratio(power, self._emitter_shadows.samples.power)
        if sun is None and self._sun_shadow.sun is None and ratio is not None and self._baked is not None:
            self._baked.scale = (self._baked.scale * ratio).astype(np.float32)
            if self._indirect is not None:   # what its gather reflects
                self._indirect.relit(self._draw_scene, ratio)
                self._stale_indirect(awaiting=True)
        else:
            self._lights += 1

    def _ensure_baked(self) -> BakedDirectLight:
        """The lightmapped mesh and its baked direct irradiance: laid out again when the triangles or the
        texel size change, baked again when the lights do (its texels hold irradiance: an albedo edit
        changes only the surface pass's colours and what the indirect light's gather reflects)."""
        layout = (self._geometry, self.settings.lightmap_texel, self.settings.final_gather)
        if layout != self._layout_key:
            s, old, indirect = self.settings, self._baked, self._indirect
            moving = old is not None and indirect is not None and self._layout_key[1:] == layout[1:]
            gathers = self.background_bake and s.indirect and s.final_gather
            # a new geometry's caster, the gather's first need, built while the lightmap is laid out here
            caster = started(caster_of, self._draw_scene) if gathers and not moving else None
            texel = fitted_texel(self._draw_scene, self.settings.lightmap_texel * self._scene_size,
                                 max_texture_side(self.ctx))
            baked = BakedDirectLight(self.ctx, self._draw_scene, texel)
            if moving and same_atlas(old, baked):   # faces moved: the old rays, to trace only what changed
                self._indirect = None
                self._release_baked()
                indirect.moved(baked, self._draw_scene)
                self._indirect, self._indirect_fresh = indirect, False
                indirect.prefetch()   # the rays the move changes, traced while the GI source answers
            else:
                self._release_baked()
            self._baked, self._layout_key = baked, layout
            if gathers and self._indirect is None:
                self._indirect = self._new_indirect(caster)   # its rays traced while the GI source makes the probes
                self._indirect.prefetch()
        lit = (self._shadow_key, self._lights, self.settings.shadow_bias)
        if lit != self._lit_key:
            program = self.programs.get("direct_bake")
            self._emitter_shadows.use(ATLAS_UNIT)
            self._sun_shadow.use(SUN_UNIT)
            set_uniforms(program, shadow_bias=float(self.settings.shadow_bias),
                         **self._emitter_shadows.uniforms(ATLAS_UNIT), **self._sun_shadow.uniforms(SUN_UNIT))
            self._baked.bake(program, BAKED_UNIT)
            self.ctx.enable(moderngl.DEPTH_TEST)   # the bake is a full-screen pass without depth
            self._lit_key = lit
            if self._indirect is not None:    # what its gather reflects changed with the direct light
                self._indirect.relit(self._draw_scene)
                self._indirect.read_direct()
                self._stale_indirect(awaiting=True)
        return self._baked

    def _ensure_indirect(self) -> BakedIndirectLight | None:
        """The probe grid baked into the lightmap's texels, or None: while GI is off, or while a new
        lattice's weights are made in the background (the probes are then read per fragment)."""
        if self.probes is None or not self.settings.indirect:
            return None
        if self._indirect is None:
            self._indirect = self._new_indirect()
        if not self._indirect.ready_for(self.probes):
            return None
        if not self._indirect_fresh or self._indirect.installs != self._indirect_installs:
            waiting = self._awaiting is not None and self.probes_pending and time.perf_counter() < self._awaiting
            if waiting and self._indirect.installs == self._indirect_installs:
                return self._indirect   # its last gather, until the edit's probes come
            self._indirect.update(self.probes)   # new probes, lights or colours, or new weights installed
            self._indirect_fresh, self._indirect_installs = True, self._indirect.installs
        return self._indirect

    def _new_indirect(self, caster: Future | None = None) -> BakedIndirectLight:
        self._indirect_installs = -1
        return BakedIndirectLight(self.ctx, self._baked, self._draw_scene, self.background_bake,
                                  self.settings.final_gather, caster)

    def bake_version(self) -> tuple:
        """Changes when background work that changes the image has finished (a redraw key)."""
        if self._indirect is not None:
            self._indirect.poll()
        return (None,) if self._indirect is None else (self._indirect.installs, self._indirect.pending)

    @property
    def baking(self) -> bool:
        """The lightmap's probe weights (and final-gather rays) are being made on the background worker: the
        picture shows the probes per fragment until they land."""
        return self._indirect is not None and self._indirect.pending

    def _release_baked(self) -> None:
        for obj in (self._indirect, self._baked):
            if obj is not None:
                obj.release()
        self._indirect, self._baked, self._layout_key, self._lit_key = None, None, None, None

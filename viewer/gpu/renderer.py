"""The renderer: a Scene and a ProbeGrid -> linear HDR radiance -> a tone-mapped sRGB image.

Per fragment (shaders/surface.glsl): outgoing = albedo / pi * (E_direct + E_indirect) + emission. By
default (RenderSettings.baked) both irradiances are read from lightmaps, one fetch each: the direct light
baked once per scene and light setting (viewer/gpu/direct_bake.py: emitter samples and the sun, with
shadow maps, viewer/gpu/shadows.py), the probe grid's indirect light once per GI update
(viewer/gpu/indirect_bake.py, with DDGI-style per-texel probe weights and exact probe visibility,
viewer/probes/weights.py). The exact path (baked=False, for comparisons with the reference) sums the
emitter samples per fragment, interleaved over 2x2 pixel blocks without multisampling
(shaders/interleave_resolve.glsl), and interpolates the probes per fragment (shaders/probe_grid.glsl).
Exposure, a tone curve and the sRGB encoding are applied in the surface pass when drawing into a
DisplayTarget (the window's and the captures' path), or by `present` from an HdrTarget.

The renderer does not know where its pixels go: it draws into any HdrTarget or DisplayTarget and
presents into any framebuffer (the window's screen, or an offscreen image, see viewer/gpu/offscreen.py).
Keeping the shadow maps and the lightmaps up to date is viewer/gpu/lightmaps.py.
"""

from __future__ import annotations

from contextlib import nullcontext
from pathlib import Path

import moderngl
import numpy as np

from viewer.gpu.direct_bake import MIN_TILE, BakedDirectLight, lightmap_holds
from viewer.gpu.indirect_bake import BakedIndirectLight
from viewer.gpu.camera import gl_bytes, jittered, view_projection
from viewer.gpu.debug_views import DebugViews
from viewer.gpu.lightmaps import (ATLAS_UNIT, BAKED_UNIT, HDR_UNIT, INDIRECT_UNIT, INTERLEAVE_UNIT, PROBE_UNIT,
                                  SUN_UNIT, LightmapUpkeep, max_texture_side)
from viewer.gpu.mesh import SceneMesh, in_draw_order, same_faces, same_triangles
from viewer.gpu.probe_textures import ProbeTextures, empty_grid
from viewer.gpu.programs import SHADERS, ProgramLibrary, set_uniforms
from viewer.gpu.render_settings import TONEMAPS, VIEWS, VOXEL_COLORS, RenderSettings  # noqa: F401 (re-exported)
from viewer.gpu.shadows import EmitterShadows, SunShadow
from viewer.gpu.surface_textures import SurfaceTextures
from viewer.gpu.targets import DisplayTarget, HdrTarget, InterleaveBuffers, RefiningTarget, remade
from viewer.probes.grid import ProbeGrid
from viewer.scene import Camera, Scene
from viewer.scene.types import note
from viewer.rays.voxels import VoxelGrid

SURFACE_VIEWS = {"final": 0, "direct": 1, "indirect": 2, "albedo": 3, "normals": 4, "probes": 0}


class Renderer(LightmapUpkeep):
    """Draws a scene lit by its emitters, its sun and a probe grid, on a GL 4.3+ context.

        renderer = Renderer(ctx)                      # compiles the shaders (ShaderError if broken)
        renderer.set_scene(scene)                     # again whenever the scene changes
        renderer.set_probes(probes)                   # whenever the GI changes; None: GI off
        target = DisplayTarget(ctx, (width, height))  # 8-bit sRGB (+ depth), any size; or an HdrTarget
        renderer.draw(target, camera, view="final")   # for linear radiance
        renderer.present(target, window_framebuffer, view="final")

    `settings` (RenderSettings) may be changed between frames; shadow maps are rebuilt when a setting
    they depend on changes. `reload_shaders()` recompiles from the files and keeps the old programs
    when that fails.
    """

    def __init__(self, ctx: moderngl.Context, settings: RenderSettings | None = None,
                 shader_dir: Path | str = SHADERS):
        self.ctx = ctx
        self.settings = settings or RenderSettings()
        self._faces, self._fits = 0, True   # the scene's faces, and whether a lightmap holds them
        self.programs = ProgramLibrary(ctx, shader_dir)
        for name in ("surface", "shadow_depth", "present", "voxel_cubes", "probe_spheres", "interleave_resolve",
                     "direct_bake", "refine_background"):
            self.programs.get(name)  # compile everything now: a broken shader fails here, not mid-frame
        self.scene: Scene | None = None
        self._draw_scene, self._draw_order = None, None   # the scene in draw order, and `in_draw_order`'s answer
        self.bounds: tuple[np.ndarray, np.ndarray] | None = None
        self.mesh: SceneMesh | None = None
        self._textures = SurfaceTextures(ctx)
        self._emitter_shadows: EmitterShadows | None = None
        self._sun_shadow: SunShadow | None = None
        self._shadow_key = None
        self.probes: ProbeGrid | None = None
        self._probe_textures = ProbeTextures(ctx, empty_grid())
        self._debug = DebugViews(ctx, self.programs)
        self._present_arrays: dict[tuple, moderngl.VertexArray] = {}
        self._resolve_array = ctx.vertex_array(self.programs.get("interleave_resolve"), [])
        self._interleave: InterleaveBuffers | None = None
        self._indirect: BakedIndirectLight | None = None
        self._indirect_fresh = False
        self._indirect_installs = -1
        """BakedIndirectLight.installs when its lightmap was last updated."""
        self.background_bake = False
        """New texel weights on a worker, the probes read per fragment meanwhile (the viewer), instead of in
        the frame that needs them (captures and tests: the same image every time)."""
        self._baked: BakedDirectLight | None = None
        self._geometry = 0
        """Counts the scenes whose triangles differ from the one before (a colour edit keeps them)."""
        self._scene_size = 1.0
        """The longest side of the scene's box when its faces were set: lengths (the lightmap's texel) are
        fractions of it, so that a scene renders alike in any unit."""
        self._layout_key = None
        """What the lightmap's layout and the indirect light's weights and rays were made for."""
        self._lit_key = None
        """What the lightmap's direct light was baked for."""
        self._scene_version = 0
        """Counts set_scene calls: colours and lights may change with any."""
        self._shadows_for = None
        """The _scene_version the shadow maps' light samples are those of."""
        self._lights = 0
        """Counts the changes of the light sources (places, powers): the direct light to bake again."""
        self._scratch: HdrTarget | None = None
        self.timer = None
        """A viewer.gpu.pass_timer.PassTimer to time each pass with, or None."""

    def _timed(self, name: str):
        return self.timer(name) if self.timer is not None else nullcontext()

    # ---- inputs ------------------------------------------------------------------------------------
    def set_scene(self, scene: Scene) -> None:
        """Upload the scene's triangles; its shadow maps and lightmap are rendered on the next draw. A scene
        with the same triangles as the last (an edit of colours: albedo, emission) keeps the lightmap's
        layout and the indirect light's probe weights and final-gather rays, the seconds of work that
        depend on the geometry alone: its lightmap is baked again and the indirect light gathered again.
        The same faces moved (a lamp dragged) keep the old rays, for the worker to trace again only those
        the move can change (`_ensure_baked`). A scene past `lightmapped` is drawn per fragment, said once."""
        self._draw_order = in_draw_order(scene, self._draw_order)   # the same faces, the room's walls last
        draw_scene = self._draw_order[1]
        same = self.scene is not None and same_triangles(draw_scene, self._draw_scene)
        if not same:
            self._geometry += 1
            if self.scene is None or not same_faces(draw_scene, self._draw_scene):
                self._release_baked()
                self._faces = int(np.count_nonzero(scene.face_areas > 0))   # said once, not per edit
                self._fits = lightmap_holds(scene, max_texture_side(self.ctx))
                if self.settings.baked and not self.lightmapped:
                    most = (f"--lightmap-faces {self.settings.lightmap_faces}" if self._fits
                            else f"a lightmap's {MIN_TILE}x{MIN_TILE} tiles")
                    note(f"{scene.name}: {self._faces} faces are more than {most} take: drawn with the light "
                         f"per fragment")
                lo, hi = scene.bounds
                self._scene_size = float(np.max(hi - lo))   # kept while the same faces move
        self.scene, self.bounds = scene, scene.bounds   # (lo, hi); Scene.bounds scans the faces: not per frame
        previous, self._draw_scene = self._draw_scene, draw_scene
        self.mesh = SceneMesh.remade(self.mesh, self.ctx, draw_scene, previous)   # a colour edit keeps its arrays
        if same and self._baked is not None:   # the lightmap's vertices take the colours the mesh's just took
            self._baked.recolour(draw_scene, self.mesh.recoloured)
            if self._indirect is not None:
                self._indirect.recolour(draw_scene)
                self._stale_indirect(awaiting=True)
        self._textures.set_scene(self._draw_scene)
        self._scene_version += 1

    def set_probes(self, probes: ProbeGrid | None) -> None:
        """The indirect light (incident radiance without emitters and sun), or None for GI off."""
        self.probes = probes
        self._probe_textures.update(probes if probes is not None else empty_grid())
        self._stale_indirect(awaiting=False)
        self._debug.set_probes(probes)

    def set_voxels(self, voxels: VoxelGrid | None, radiance: np.ndarray | None = None) -> None:
        """Voxels for the `voxels` view, with their outgoing radiance (K, 3) if known."""
        self._debug.set_voxels(voxels, radiance)

    def reload_shaders(self) -> None:
        """Recompile the shaders from their files; on a ShaderError the old programs stay in use."""
        try:
            self.programs.reload()
        finally:
            if self.mesh is not None:
                self.mesh.forget_programs()
            if self._baked is not None:
                self._baked.forget_programs()
            self._lit_key = None
            for array in self._present_arrays.values():
                array.release()
            self._present_arrays.clear()
            self._resolve_array.release()
            self._resolve_array = self.ctx.vertex_array(self.programs.get("interleave_resolve"), [])
            self._shadow_key = None

    # ---- drawing -----------------------------------------------------------------------------------
    def draw(self, target: HdrTarget | DisplayTarget, camera: Camera | None = None, view: str = "final",
             jitter: tuple[float, float] = (0.0, 0.0)) -> None:
        """Draw `view` into the target, resolved, ready to present or read: linear HDR values into an
        HdrTarget; the tone-mapped, sRGB-encoded image into a DisplayTarget (in one pass where the view
        allows it, see `fused`, else through an HDR image and the tone-mapping pass: the same pixels).
        `jitter`: the image moved by this many pixels (x right, y up), for supersampling. A fused draw
        into a RefiningTarget is one more image of its mean, at the target's own jitter."""
        if view not in VIEWS:
            raise ValueError(f"view must be one of {', '.join(VIEWS)}, not {view!r}")
        if self.scene is None:
            raise RuntimeError("Renderer.draw: no scene (call set_scene first)")
        camera = camera or self.scene.camera
        if isinstance(target, DisplayTarget) and not self.fused(target, view):
            hdr = self._scratch_hdr(target.size, target.samples)
            self.draw(hdr, camera, view, jitter)
            self.present(hdr, target, view)
            return
        display = isinstance(target, DisplayTarget)
        step = target.step() if isinstance(target, RefiningTarget) else None
        with self._timed("shadows and bake"):
            self._ensure_shadows()
            if self._baked_applies(view):
                self._ensure_baked()
                self._ensure_indirect()
        lo, hi = self.bounds
        view_proj = jittered(view_projection(camera, target.aspect, lo, hi), step.jitter if step else jitter,
                             target.size)
        ctx, framebuffer = self.ctx, step.framebuffer if step else target.framebuffer
        framebuffer.use()
        with self._timed("clear"):
            framebuffer.clear(0.0, 0.0, 0.0, 1.0, depth=1.0)
        ctx.enable(moderngl.DEPTH_TEST)
        ctx.disable(moderngl.CULL_FACE | moderngl.BLEND)
        if view == "voxels":
            self._debug.draw_voxels(view_proj, self.settings.voxel_color)
        elif self._baked_applies(view):
            with self._timed("surfaces"):
                self._draw_surfaces(view_proj, view, framebuffer, baked=True, display=display, refine=step)
        elif self._interleaved(target, view):
            with self._timed("surfaces (interleaved)"):
                self._draw_interleaved(target, view_proj, view)
        else:
            with self._timed("surfaces"):
                self._draw_surfaces(view_proj, view, framebuffer, display=display, refine=step)
            if view == "probes":
                if self.probes is not None:
                    self._debug.draw_probes(camera, target.aspect, self.probes, self._probe_textures.use(PROBE_UNIT),
                                            (self._probe_textures.lo, self._probe_textures.hi), self.bounds,
                                            self.settings.probe_radius)
        if step is not None:
            target.finish(step)
        with self._timed("resolve"):
            target.resolve()

    def fused(self, target: HdrTarget | DisplayTarget, view: str) -> bool:
        """Whether `view` is drawn into a display target in one pass, tone mapping as it shades (the
        surface views; the voxels, probes and interleaved views go through an HDR image)."""
        return (isinstance(target, DisplayTarget) and view in SURFACE_VIEWS and view != "probes"
                and not (not self._baked_applies(view) and self._interleaved(target, view)))

    def _scratch_hdr(self, size: tuple[int, int], samples: int) -> HdrTarget:
        """An HDR image for the views drawn into a display target through the tone-mapping pass."""
        fits = self._scratch is not None and (self._scratch.size, self._scratch.samples) == (tuple(size), samples)
        self._scratch = remade(self._scratch, fits, lambda: HdrTarget(self.ctx, size, samples=samples))
        return self._scratch

    @property
    def lightmapped(self) -> bool:
        """The scene's light is read from lightmaps: it has at most `lightmap_faces` faces and a lightmap
        holds them (else it is drawn on the per-fragment path: `set_scene`)."""
        return self._fits and self._faces <= self.settings.lightmap_faces

    def _baked_applies(self, view: str) -> bool:
        s = self.settings
        if not self.lightmapped:
            return False
        if view == "indirect":   # without probes the per-fragment path draws it black
            return s.baked and s.indirect and self.probes is not None
        return s.baked and view in ("final", "direct")

    def _interleaved(self, target: HdrTarget, view: str) -> bool:
        s = self.settings
        return s.interleave and target.samples <= 1 and view in ("final", "direct") and s.light_samples >= 8

    def _draw_interleaved(self, target: HdrTarget, view_proj: np.ndarray, view: str) -> None:
        """Surfaces into the interleave buffers, then the recombining filter into the target."""
        fits = self._interleave is not None and self._interleave.size == target.size
        buffers = self._interleave = remade(self._interleave, fits, lambda: InterleaveBuffers(self.ctx, target.size))
        buffers.framebuffer.use()
        buffers.framebuffer.clear(0.0, 0.0, 0.0, 0.0, depth=1.0)
        self._draw_surfaces(view_proj, view, buffers.framebuffer, interleave=True)
        target.framebuffer.use()
        self.ctx.disable(moderngl.DEPTH_TEST)
        program = self.programs.get("interleave_resolve")
        set_uniforms(program, **buffers.use(INTERLEAVE_UNIT))
        self._resolve_array.render(moderngl.TRIANGLES, vertices=3)
        self.ctx.enable(moderngl.DEPTH_TEST)

    def present(self, target: HdrTarget | DisplayTarget, framebuffer: moderngl.Framebuffer | DisplayTarget,
                view: str = "final") -> None:
        """Show the target in `framebuffer`'s viewport (which may be larger than the target: the image is
        then scaled up bilinearly). An HdrTarget goes through exposure, tone curve and sRGB (the
        tone-mapping pass); a DisplayTarget is already tone-mapped and encoded: copied as it is (a blit,
        ~1 ms at 1280x720 on llvmpipe) where the sizes match."""
        if isinstance(framebuffer, DisplayTarget):
            if isinstance(target, DisplayTarget):
                raise ValueError("present: a display target into a display target (copy it instead)")
            framebuffer = framebuffer.resolved
        if isinstance(target, DisplayTarget) and tuple(framebuffer.viewport) == (0, 0, *target.size):
            with self._timed("present"):
                self.ctx.copy_framebuffer(framebuffer, target.resolved)
            return
        self._tone_map(target, framebuffer, view)

    def _tone_map(self, target: HdrTarget | DisplayTarget, framebuffer: moderngl.Framebuffer, view: str) -> None:
        """The full-screen pass of present.glsl from the target's texture into `framebuffer`'s viewport."""
        s = self.settings
        raw = view in ("albedo", "normals") or (view == "voxels" and not self._debug.radiance_shown(s.voxel_color))
        same_size = tuple(framebuffer.viewport[2:]) == target.size
        defines = dict(TONE_CURVE=TONEMAPS[s.tonemap], RAW=int(raw), SAME_SIZE=int(same_size),
                       ENCODED=int(isinstance(target, DisplayTarget)))
        program = self.programs.get("present", **defines)
        key = tuple(sorted(defines.items()))
        if key not in self._present_arrays:
            self._present_arrays[key] = self.ctx.vertex_array(program, [])
        framebuffer.use()
        self.ctx.disable(moderngl.DEPTH_TEST)
        target.texture.use(location=HDR_UNIT)
        set_uniforms(program, hdr_image=HDR_UNIT, exposure_scale=float(2.0 ** s.exposure),
                     output_viewport=tuple(float(v) for v in framebuffer.viewport))
        with self._timed("present"):
            self._present_arrays[key].render(moderngl.TRIANGLES, vertices=3)

    def _draw_surfaces(self, view_proj: np.ndarray, view: str, framebuffer: moderngl.Framebuffer,
                       interleave: bool = False, baked: bool = False, display: bool = False, refine=None) -> None:
        s = self.settings
        probes = self.probes if s.indirect else None
        mesh = self.mesh
        extra = {}
        if baked:   # the lightmap with the irradiance this view shows
            mesh = self._ensure_baked()
            indirect = self._ensure_indirect()
            framebuffer.use()
            extra.update(self._baked.use(BAKED_UNIT))
            if indirect is not None:
                extra.update(indirect.use(INDIRECT_UNIT))
        defines = self._surface_defines(view, probes is not None, interleave, baked,
                                        baked and indirect is not None, display)
        if display:
            extra.update(exposure_scale=float(2.0 ** s.exposure), **(refine.uniforms if refine else {}))
            defines["ACCUMULATE"] = int(refine is not None)
        program = self.programs.get("surface", **defines)
        # a textured scene's groups without a texture are drawn by the variant that samples nothing
        plain = self.programs.get("surface", **{**defines, "TEXTURED": 0}) if defines["TEXTURED"] else program
        units = self._probe_textures.use(PROBE_UNIT, upload=bool(defines["INDIRECT"]) and not defines["BAKED_INDIRECT"])
        self._emitter_shadows.use(ATLAS_UNIT)
        self._sun_shadow.use(SUN_UNIT)
        if refine is not None:   # the mean so far, bound last: nothing rebinds its unit before the draw
            refine.bind()
        for shader in {id(program): program, id(plain): plain}.values():
            set_uniforms(shader, view_proj=gl_bytes(view_proj), probe_sh=units, **self._probe_uniforms(probes),
                         shadow_bias=float(s.shadow_bias), **self._emitter_shadows.uniforms(ATLAS_UNIT),
                         **self._sun_shadow.uniforms(SUN_UNIT), **extra)
        if baked:   # a cheap shader (two fetches): early z on the draw order costs less than a pre-pass
            self.ctx.depth_func = "<"
        else:
            self._depth_prepass(view_proj, framebuffer, mesh)
        self._textures.draw(mesh, program, plain)
        self.ctx.depth_func = "<"

    def _surface_defines(self, view: str, indirect: bool, interleave: bool, baked: bool, baked_indirect: bool,
                         display: bool) -> dict:
        defines = dict(VIEW=SURFACE_VIEWS[view], INDIRECT=int(indirect), INTERLEAVE=int(interleave),
                       BAKED=int(baked), BAKED_INDIRECT=int(baked_indirect), DISPLAY=int(display),
                       TEXTURED=int(self._textures.active))
        if display:   # tone mapping as present.glsl does it (tonemap.glsl)
            defines.update(TONE_CURVE=TONEMAPS[self.settings.tonemap], RAW=int(view in ("albedo", "normals")))
        return defines

    def warm_up(self) -> None:
        """Compile the surface shader's variants that the final view goes through when GI arrives (no
        probes, probes read per fragment while their texel weights are made, baked probes): a variant
        compiles in a few hundred ms on llvmpipe, a stalled frame when first met."""
        for indirect, baked_indirect in ((False, False), (True, False), (True, True)):
            self.programs.get("surface", **self._surface_defines("final", indirect, False, self.settings.baked,
                                                                  baked_indirect, True))

    def _probe_uniforms(self, probes: ProbeGrid | None) -> dict:
        """probe_grid.glsl's uniforms: the grid's box, and the normal offset and plane falloff in world
        units."""
        s = self.settings
        spacing = float(np.min(probes.spacing)) if probes is not None else 1.0
        return dict(probe_lo=tuple(self._probe_textures.lo), probe_hi=tuple(self._probe_textures.hi),
                    probe_normal_offset=s.probe_normal_offset * spacing,
                    probe_plane_falloff=s.probe_plane_falloff / spacing)

    def _depth_prepass(self, view_proj: np.ndarray, framebuffer: moderngl.Framebuffer, mesh) -> None:
        """Lay down the depth first, so the expensive surface shader runs once per visible pixel
        (the Cornell box is shaded 1.4 times per pixel without it). Both programs declare
        `invariant gl_Position`, so the depths match exactly and the second pass tests with <=."""
        program = self.programs.get("shadow_depth")
        program["view_proj"].write(gl_bytes(view_proj))
        attachments = len(framebuffer.color_attachments)
        framebuffer.color_mask = (False,) * 4 if attachments == 1 else ((False,) * 4,) * attachments
        self.ctx.depth_func = "<"
        mesh.render(program)
        framebuffer.color_mask = (True,) * 4 if attachments == 1 else ((True,) * 4,) * attachments
        self.ctx.depth_func = "<="

    def release(self) -> None:
        self._release_baked()
        for obj in (self.mesh, self._emitter_shadows, self._sun_shadow, self._probe_textures, self._scratch,
                    self._textures):
            if obj is not None:
                obj.release()
        self._debug.release()
        if self._interleave is not None:
            self._interleave.release()
        for obj in (*self._present_arrays.values(), self._resolve_array):
            obj.release()
        self.programs.release()

"""Baked indirect light: the indirect irradiance at every texel of the lightmap atlas
(viewer/gpu/direct_bake.py), so that the per-frame surface pass reads it with one bilinear fetch beside
the direct light. Two steps per GI update: the probe grid's irradiance, weighted per texel as
viewer/probes/weights.py says (trilinear, validity, back-face and exact visibility: a face never mixes
in a probe it cannot see); then, with `gather_rays` (RenderSettings.final_gather, the default), a final
gather (viewer/gpu/final_gather.py): each sample sums what the texels its rays land on reflect, albedo x
(direct + that probe light), and a tent over its coplanar neighbours takes the noise out. The probes
then light only the second bounce on, and light they cannot resolve (a face looking out of an open
side, contacts) comes from the surfaces themselves.

The weights depend on the scene and the probe lattice only: made once (`SurfaceBake`), then each new
probe grid is evaluated on the CPU, about 24 multiply-adds a texel, and uploaded: on llvmpipe about 10x
cheaper than the same sum in a fragment shader (8 probes x 7 fetches a texel: ~300 ms for the Cornell
box's 0.77 M texels). Each face reads its own texels, `lightmap_texel` of the scene apart.
"""

from __future__ import annotations

from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import replace

import moderngl
import numpy as np

from viewer import wake
from viewer.rays.cast import TriangleCaster
from viewer.gpu.half_floats import widened
from viewer.rays.moved_faces import few_moved
from viewer.gpu.final_gather import GatherRays
from viewer.gpu.gather_cast import caster_of
from viewer.gpu.context import finish
from viewer.gpu.direct_bake import BakedDirectLight, same_atlas
from viewer.gpu.lightmap_update import (Landing, Reached, gather_reflected, gather_texels, reflectance, with_lit,
                                        texture_ratio)
from viewer.gpu.tent import Tent, tent_neighbours
from viewer.gpu.texel_samples import (dark_fill, gather_records, sample_points, small_tiles, strided_samples, texel_rows,
                                     weight_rows)
from viewer.probes.moved_weights import Weighed, after_moving, moved_box
from viewer.probes.weights import SurfaceBake, lobe_normals
from viewer.probes.grid import ProbeGrid
from viewer.scene import Scene

MAX_SAMPLES = 3_000_000
"""Above this many samples (both sides) the probes stay per fragment: their weights would take minutes
and gigabytes (a detailed mesh of 82k triangles has 0.3 M)."""
KEPT_LATTICES = 2
"""Weights kept per scene: the GI sources' lattices (the network's and the solver's) when they differ."""


def lattice_key(probes: ProbeGrid) -> tuple:
    """What the weights depend on, of a probe grid: its box, resolution and validity."""
    return (tuple(np.round(probes.lo, 9)), tuple(np.round(probes.hi, 9)), probes.resolution,
            hash(np.asarray(probes.valid, bool).tobytes()))


class BakedIndirectLight:
    """The indirect irradiance of every lightmap texel, front sides | back sides as the direct lightmap.

    The weights of a new probe lattice take a few tenths of a second: with `background`, they are
    computed on a worker thread (numba releases the GIL) and `ready_for` answers False until they are
    installed, so that the caller can draw the probes per fragment meanwhile instead of stalling."""

    def __init__(self, ctx: moderngl.Context, lightmap: BakedDirectLight, scene: Scene, background: bool = False,
                 gather_rays: int = 0, caster: Future | None = None):
        self.lightmap, self.scene = lightmap, scene
        height, width = lightmap.covered.shape
        self.texture = ctx.texture((2 * width, height), 3, dtype="f4")
        self.texture.filter, self.texture.repeat_x, self.texture.repeat_y = (moderngl.LINEAR, moderngl.LINEAR), False, False
        self._image, self._written = np.zeros((height * 2 * width, 3), np.float32), False
        rows, columns = np.nonzero(lightmap.covered)           # the order of lightmap.texel_points
        sample, sources, weights = strided_samples(lightmap, rows, columns)
        self._samples = np.flatnonzero(sample)   # the texels (of lightmap.texel_points) the probes' light is evaluated at
        self._small = small_tiles(lightmap, self._samples)   # a scan's: records' weights, half rays, rounded lobes
        pixels = rows * 2 * width + columns
        self._pixels = np.concatenate([pixels[sample], pixels[sample] + width])
        """Each sample's pixel in the (front | back) image: the front sides', then the back sides'."""
        self._row_of = np.full(len(self._image), -1, np.int32)
        self._row_of[self._pixels] = np.arange(len(self._pixels))
        rows, weights, self._texel_pixels = texel_rows(sources, weights, pixels, self._row_of, width)
        self._texel_rows = (rows, weights)
        """Every covered pixel of both sides, and the samples (rows of `SurfaceBake.irradiance`) it
        interpolates with their weights: the same for every lattice (`_dark` fills in what differs)."""
        self._caster: TriangleCaster | None = None
        """The rays' caster of the installed geometry (Embree where installed, else the DDA's cells)."""
        self._moved_from: TriangleCaster | None = None   # before a move: the next keeps its unmoved faces' hierarchy
        self._early = None if caster is None else (scene, caster)   # `caster_of(scene)`, started by the caller
        self.gather_rays = gather_rays
        """Final-gather rays per sample (viewer/gpu/final_gather.py); 0: the probes' light alone."""
        self._gather: tuple[GatherRays, Tent, Landing] | None = None   # rays, `tent_neighbours`, their Landing
        self._records: tuple[np.ndarray, np.ndarray] | None = None   # `gather_records`, once per layout
        self._sample_rows, self._all_texels = np.arange(len(self._pixels)), None   # the latter made if asked
        self._direct: tuple | None = None   # each pixel's direct irradiance and its (3,) scale, read back per bake
        self._reflectance: tuple[np.ndarray, np.ndarray] | None = None
        """(albedo, albedo x direct irradiance) of the pixels the rays land on, once per bake or colour edit."""
        self._covered_pixels: tuple[np.ndarray, np.ndarray] | None = None
        self._texture_ratio: tuple[tuple, np.ndarray | None] | None = None   # (textures, texture_ratio)
        self._landing: Landing | None = None   # the pixels the rays land on, once per install
        self._scratch = self._values = None   # albedo x (direct + indirect) there (the rays read it); the samples' light
        self._reached: Reached | None = None      # the samples and texels the gather's light reaches
        self._bake: SurfaceBake | None = None
        self.weights_key = None
        """lattice_key of the probe grid whose weights are installed (None: none yet)."""
        self.installs = 0
        """Counts the weights installed (a new lattice's, or a moved geometry's)."""
        self._executor = ThreadPoolExecutor(1, thread_name_prefix="indirect-weights") if background else None
        self._job: tuple[tuple, int, Future] | None = None   # (lattice key, geometry, future) of the worker's weights
        self._prefetching: Future | None = None   # the geometry's work started by `prefetch`, while it runs
        self._geometry = 0
        """Counts `moved` calls: work started for an earlier geometry is dropped."""
        self._made: tuple[int, TriangleCaster, tuple | None] | None = None   # (geometry, caster, gather): reused
        self._points: tuple | None = None   # `_sample_points`' lightmap, answer and rounded face normals
        self._weighed: dict[int, tuple[TriangleCaster, Weighed]] = {}   # per lattice: its last weights' caster
        self._lobes: tuple = (None, None)   # (normal_id, `lobe_normals`) of the last weights
        self._traced: tuple[Scene, BakedDirectLight, GatherRays] | None = None
        """The scene and lightmap the last gather rays were traced for, and the rays (a moved lamp's job
        traces again only the rays the move can change)."""
        self.stale = False
        """The weights and rays installed are those of the geometry before a `moved`: not shown (texels the
        moved faces covered before would stay dark: the old rays met the lamp's back there), but the
        rays are what the worker traces the move's changes from."""
        self._last_key: tuple[ProbeGrid, tuple] | None = None
        self._kept: dict[tuple, SurfaceBake] = {}
        """The weights of the last KEPT_LATTICES lattices, newest last."""

    def ready_for(self, probes: ProbeGrid) -> bool:
        """Whether the weights of the probes' lattice are installed; starts computing them if not (at
        once, or on the worker with `background`). Never, for a scene over MAX_SAMPLES."""
        if len(self._pixels) > MAX_SAMPLES:
            return False
        if self._last_key is None or self._last_key[0] is not probes:   # asked twice a frame: hash once
            self._last_key = (probes, lattice_key(probes))
        key = self._last_key[1]
        if self.weights_key == key and not self.stale:
            return True
        if key in self._kept:   # a lattice met before (the viewer toggling GI sources; `moved` forgets them)
            self._install(key, self._kept[key])
            return True
        if self._job is None or self._job[:2] != (key, self._geometry):
            if self._executor is None:
                self._install(key, *self.weights_of(probes))
                return True
            self._job = (key, self._geometry, self._executor.submit(self.weights_of, probes, *self._geometry_now()))
            self._job[2].add_done_callback(lambda _: wake.notify())   # the window draws them at once
        return self.poll()

    def poll(self) -> bool:
        """Install the worker's weights if they are done (and of the current geometry); True when they were."""
        if self._job is None or not self._job[2].done():
            return False
        key, geometry, job = self._job
        self._job = None
        if geometry != self._geometry:
            return False
        self._install(key, *job.result())
        return True

    def moved(self, lightmap: BakedDirectLight, scene: Scene) -> None:
        """`scene` is new geometry with the same lightmap layout as the last (a lamp moved: the same
        triangles elsewhere), baked into `lightmap`. The old geometry's rays stay, stale, for the worker
        to trace again only the rays the move can change (`_gather_rays`); until the new weights are in
        (on the worker with `background`, else on the next `ready_for`) the renderer reads the probes per
        fragment, as for a new scene."""
        self.lightmap, self.scene = lightmap, scene
        self._geometry += 1
        self._moved_from = self._caster if self._caster is not None else self._moved_from
        self._caster, self._direct, self._reflectance = None, None, None
        self._kept = {}
        self.stale = self._bake is not None

    @property
    def pending(self) -> bool:
        return self._job is not None

    def _geometry_now(self) -> tuple:
        """What the weights are made for, read together on the calling thread (the worker's job gets them
        as arguments: `moved` may change them while it runs)."""
        return self._geometry, self.scene, self.lightmap, self.stale or self._gather is None

    def prefetch(self) -> None:
        """Start the geometry's work (the triangle cells, the final gather's rays and neighbours: seconds
        for a new scene, a few tenths after a lamp moved) on the worker before the new probes exist, while
        the GI source computes them: the weights that follow then take a tenth of a second. Only with
        `background`, and one at a time (a lamp dragged asks every frame: the work of the geometry the
        drag stops at is started by the weights that follow, if not here)."""
        made = self._made is not None and self._made[0] == self._geometry
        if self._executor is None or self._job is not None or made:
            return
        if self._prefetching is None or self._prefetching.done():
            self._prefetching = self._executor.submit(self._geometry_work, *self._geometry_now())

    def weights_of(self, probes: ProbeGrid, geometry: int | None = None, scene: Scene | None = None,
                   lightmap: BakedDirectLight | None = None, rays: bool | None = None,
                   ) -> tuple[SurfaceBake, TriangleCaster, tuple | None]:
        """Every texel's probe weights for both sides (the back sides with their normals negated), the
        scene's ray caster, and the final gather's rays and neighbours when the geometry has none yet
        (else None)."""
        if scene is None:
            geometry, scene, lightmap, rays = self._geometry_now()
        caster, gather = self._geometry_work(geometry, scene, lightmap, rays)
        points, normals, normal_id = self._sample_points(lightmap)
        weighed, rows = weight_rows(self._small, self._records)
        points, at = points[weighed], normals[normal_id[weighed]]
        before = self._weighed.get(probes.resolution)   # this lattice's weights before a move: kept where they hold
        box = moved_box(before[0], caster) if before else None
        done = after_moving(before[1], points, at, probes, caster, box) if box is not None else Weighed.of(
            points, at, probes, caster)
        self._weighed[probes.resolution] = (caster, done)
        if self._lobes[0] is not normal_id:   # the same normals after a move that turned no face: 15 ms of a scan
            self._lobes = (normal_id, lobe_normals(normals, normal_id, np.tile(self._small, 2)))
        return SurfaceBake.of(done.weights.take(rows), *self._lobes[1]), caster, gather

    def _geometry_work(self, geometry: int, scene: Scene, lightmap: BakedDirectLight,
                       rays: bool) -> tuple[TriangleCaster, tuple | None]:
        """(caster, (rays, neighbours) or None) of a geometry, made once on the worker: a second lattice's
        weights (the network's validity changes with the scene) and the weights after a prefetch reuse
        them."""
        made = self._made
        if made is not None and made[0] == geometry:
            return made[1], made[2]
        caster = self._caster if self._caster is not None and not rays else caster_of(scene, self._early,
                                                                                       self._moved_from)
        gather = None
        if self.gather_rays and rays:
            points, normals, normal_id = self._sample_points(lightmap)
            if self._records is None:   # the same across moves (the same layout): the old rays stay theirs
                self._records = gather_records(lightmap, self._samples)
            records = np.concatenate([self._records[0], len(self._samples) + self._records[0]])
            traced = self._gather_rays(scene, lightmap, caster, points[records], normals[normal_id[records]])
            landing = Landing.of(traced.landing[0], self._texel_pixels, self._texel_rows, lightmap.texel_faces,
                                 len(self._image))
            before = None if self._gather is None else self._gather[1]   # the same samples: kept where no record moved
            gather = (traced, tent_neighbours(lightmap, self._samples, *self._records, traced, before), landing)
            self._traced = (scene, lightmap, traced)
        self._made = (geometry, caster, gather)
        return caster, gather

    def _sample_points(self, lightmap: BakedDirectLight) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(points (S, 3), normals (N, 3), normal_id (S,)): the samples of both sides, the distinct normals
        (the back sides' negated) and each sample's; once per lightmap (the rays and the weights read them)."""
        cached = self._points
        if cached is not None and cached[0] is lightmap:
            return cached[1]
        points, rounded = sample_points(lightmap, self._samples, None if cached is None else cached[1:])
        self._points = (lightmap, points, rounded)
        return points

    def _gather_rays(self, scene: Scene, lightmap: BakedDirectLight, caster: TriangleCaster, points: np.ndarray,
                     normals: np.ndarray) -> GatherRays:
        """The final gather's rays: traced again only where a move can have changed them when the last
        rays were traced for the same faces laid out alike (a lamp dragged), else all of them. They start
        4e-6 of the scene's smallest extent off the surface (1e-4 of a probe spacing at 24^3 probes: the
        rays need no probes, so the worker traces them while the GI source computes the first ones)."""
        keep = scene.face_areas > 0
        face_tile = np.where(keep, np.cumsum(keep) - 1, -1)
        width = lightmap.covered.shape[1]
        lo, hi = scene.bounds
        layout = (caster, face_tile, lightmap.tile_origin, lightmap.tile_n, width,
                  4e-6 * float(np.min(hi - lo)))
        moved = self._moved_tiles(scene, lightmap)
        if moved is None:
            return GatherRays.of(points, normals, *layout, self.gather_rays,
                                 coarse=np.tile(self._small[self._records[0]], 2))
        _, old_lightmap, old_rays = self._traced
        tiles = lightmap.texel_faces[self._samples[self._records[0]]]
        sample_moved = np.isin(np.concatenate([tiles, tiles]), moved)
        pixels, faces = self._covered   # the fronts' pixels first, ascending; each back's is its front's + width
        landed = old_rays.landing[0]
        texel = np.searchsorted(pixels[:len(pixels) // 2], landed - np.where(landed % (2 * width) >= width, width, 0))
        corners = scene.triangles[keep][moved]
        return old_rays.after_moving(sample_moved, np.isin(faces[texel], moved), old_lightmap.texel_points[texel],
                                     corners, 2.0 * lightmap.texel, points, normals, *layout)

    def _moved_tiles(self, scene: Scene, lightmap: BakedDirectLight) -> np.ndarray | None:
        """The tiles (non-degenerate faces) that moved since the last rays were traced, when only some
        did and the faces and layout are the same; else None (trace everything)."""
        if self._traced is None:
            return None
        old_scene, old_lightmap, _ = self._traced
        if (old_scene.faces.shape != scene.faces.shape or not np.array_equal(old_scene.faces, scene.faces)
                or not same_atlas(old_lightmap, lightmap)
                or not np.array_equal(old_scene.face_areas > 0, scene.face_areas > 0)):
            return None
        return few_moved(old_scene.triangles, scene.triangles, scene.face_areas > 0)

    def _install(self, key: tuple, bake: SurfaceBake, caster: TriangleCaster | None = None,
                 gather: tuple | None = None) -> None:
        if caster is not None:   # the caster before the move is no longer needed: its hierarchy is freed
            self._caster, self._moved_from = caster, None
        self._gather = gather if gather is not None else self._gather
        self.stale = False
        self.installs += 1
        self._bake, self.weights_key = bake, key
        self._kept = {k: v for k, v in self._kept.items() if k != key}
        self._kept[key] = bake
        while len(self._kept) > KEPT_LATTICES:
            del self._kept[next(iter(self._kept))]
        # (rows, lit rows): a sample that sees no probe (a face's strip under the floor) next to one of its tile
        # that does shows its light on each update, so that a visible pixel's fetch never mixes in the dark
        pixels, sources = dark_fill(self.lightmap, self._samples, self._pixels, bake.weights.sum(axis=1) == 0.0)
        self._dark = (self._row_of[pixels].astype(np.int64), self._row_of[sources].astype(np.int64))
        self._landing = None

    def update(self, probes: ProbeGrid) -> None:
        """Evaluate and upload the indirect irradiance of `probes` (a lattice that is ready_for)."""
        dark, lit = self._dark
        if self._gather is None:
            if self._all_texels is None:   # the texels the update spreads to without a gather: every one
                self._all_texels = np.arange(len(self._texel_pixels))
            values, texels = self._bake.irradiance(probes.coefficients), self._all_texels
        else:
            rays, filtered, _ = self._gather
            landing, albedo, reflected = self._reflected()
            values = self._bake.irradiance(probes.coefficients, self._values, landing.samples)
            values[dark] = values[lit]
            gather_reflected(values, landing.rows, landing.weights, albedo, reflected, self._scratch)
            samples, texels = self._reached.samples, self._reached.texels
            gather_texels(rays.irradiance(self._scratch), filtered.near, filtered.tent, self._sample_rows, values,
                          samples)
        values[dark] = values[lit]
        gather_texels(values, *self._texel_rows, self._texel_pixels, self._image, texels)
        self.texture.write(self._image)
        self._written = True

    def _reflected(self) -> tuple[Landing, np.ndarray, np.ndarray]:
        """(landing, albedo, albedo x direct irradiance) of the pixels the gather's rays land on."""
        self._read_direct()
        if self._landing is None:   # once per install
            rays, filtered, landing = self._gather
            self._landing = replace(landing, samples=with_lit(landing.samples, *self._dark))
            self._reached = Reached.of(rays.landed, filtered.near, filtered.tent, *self._texel_rows, self._dark)
            self._scratch, self._values = (np.empty((n, 3), np.float32) for n in (len(rays.landing[0]), len(filtered.near)))
            self._reflectance = self._texture_ratio = None
            if self._written:   # the texels no light reaches stay 0 (a new image is 0 without a write)
                self._image[:] = 0.0
        if self._reflectance is None:
            landing = self._landing
            textures = tuple(map(id, self.scene.textures or ()))    # the same across colour edits
            if self._texture_ratio is None or self._texture_ratio[0] != textures:   # a textured face reflects it
                ratio = texture_ratio(self.scene, self.lightmap, landing.faces, landing.texels)
                self._texture_ratio = (textures, np.zeros((0, 3), np.float32) if ratio is None else ratio)
            face_albedo = np.ascontiguousarray(self.scene.albedo[self.scene.face_areas > 0], np.float32)
            albedo, reflected = (np.empty((len(landing.pixels), 3), np.float32) for _ in range(2))
            reflectance(landing.pixels, landing.faces, face_albedo, self._texture_ratio[1], *self._direct,
                        albedo, reflected)
            self._reflectance = (albedo, reflected)
        return (self._landing, *self._reflectance)

    def _read_direct(self) -> None:
        if self._direct is None:
            lightmap = self.lightmap
            finish(lightmap.ctx)   # the bake drawn without Python's lock (a scan's: 0.15 s the worker waited)
            texels = np.frombuffer(lightmap.texture.read(), np.float16).reshape(-1, 4)   # (front | back) rows
            self._direct = (widened(texels, 3), np.array(lightmap.scale, np.float32))   # and its scale
            self._reflectance = None

    @property
    def _covered(self) -> tuple[np.ndarray, np.ndarray]:
        """(pixels, faces): the (front | back) image's pixels that a tile covers, and their faces."""
        if self._covered_pixels is None:
            width = self.lightmap.covered.shape[1]
            rows, columns = np.nonzero(self.lightmap.covered)
            front = rows * 2 * width + columns
            self._covered_pixels = (np.concatenate([front, front + width]), np.concatenate([self.lightmap.texel_faces] * 2))
        return self._covered_pixels

    def relit(self, scene: Scene, ratio: np.ndarray | None = None) -> None:
        """The lightmap was baked again for `scene` (the same triangles): its direct light is read back on the
        next update; or only scaled by `ratio` (3,) (`BakedDirectLight.scale`: the copy read back, alike)."""
        self.scene = scene
        if ratio is not None and self._direct is not None:   # the scale (scaling the image took 10 ms on a scan)
            self._direct = (self._direct[0], (self._direct[1] * np.asarray(ratio, np.float32)).astype(np.float32))
            self._reflectance = None
        else:
            self._direct = None

    def read_direct(self) -> None:
        """Read the direct light just baked back, and what the gather's landing pixels reflect of it, now (on
        the render thread, while the GI source works), not in the first update after the probes come, where
        it delayed the settled frame by 40-110 ms."""
        if self.gather_rays:
            self._reflected() if self._gather is not None and not self.stale else self._read_direct()

    def recolour(self, scene: Scene) -> None:
        """`scene` has other albedos: what each pixel reflects is computed again, now (on the render thread,
        while the GI source computes the new probes) where the gather's rays are in."""
        self.scene = scene
        self._reflectance = None
        self.read_direct()

    def use(self, unit: int) -> dict:   # the surface shader's uniforms, the indirect lightmap bound
        self.texture.use(location=unit)
        return dict(indirect_lightmap=unit)

    def release(self) -> None:
        if self._executor is not None:
            self._executor.shutdown(wait=False, cancel_futures=True)
        self.texture.release()

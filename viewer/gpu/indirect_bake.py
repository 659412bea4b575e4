"""Baked indirect light: the probe grid's irradiance at every texel of the lightmap atlas
(viewer/gpu/direct_bake.py), weighted per texel as viewer/probe_weights.py says (trilinear, validity,
back-face and exact visibility: a face never mixes in a probe it cannot see), so that the per-frame
surface pass reads a surface's indirect irradiance with one bilinear fetch beside the direct one.

The weights depend on the scene and the probe lattice only: they are computed once (a few tenths of a
second for the Cornell box, numba) with each texel's (probe, normal) pairs (`SurfaceBake`). Each new
probe grid (a relight, a network update) is then evaluated on the CPU, about 24 multiply-adds a texel,
and uploaded. On llvmpipe that is about 10x cheaper than the same weighted sum in a fragment shader
(8 probes x 7 texel fetches a texel: ~300 ms for the Cornell box's 0.77 M atlas texels). Indirect light
is smooth over a probe spacing and the texels are `RenderSettings.lightmap_texel` apart, so the surface
pass needs no screen-space upsampling and has no edges to respect: a silhouette is a change of face,
and each face reads its own texels.
"""

from __future__ import annotations

from concurrent.futures import Future, ThreadPoolExecutor

import moderngl
import numpy as np

from viewer import dda
from viewer.geometry import voxelize_with_faces
from viewer.gpu.direct_bake import BakedDirectLight
from viewer.probe_weights import SurfaceBake, SurfaceWeights
from viewer.probes import ProbeGrid
from viewer.scene import Scene

VISIBILITY_VOXELS = 32
"""Cells per axis of the triangle grid that the probes' visibility is traced in."""


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

    def __init__(self, ctx: moderngl.Context, lightmap: BakedDirectLight, scene: Scene, background: bool = False):
        self.lightmap = lightmap
        self.scene = scene
        height, width = lightmap.covered.shape
        self.texture = ctx.texture((2 * width, height), 3, dtype="f2")
        self.texture.filter = (moderngl.LINEAR, moderngl.LINEAR)
        self.texture.repeat_x = self.texture.repeat_y = False
        self._image = np.zeros((height * 2 * width, 3), np.float32)
        rows, columns = np.nonzero(lightmap.covered)           # the order of lightmap.texel_points
        self._pixels = np.concatenate([rows * 2 * width + columns, rows * 2 * width + width + columns])
        """Each texel's pixel in the (front | back) image: the front sides', then the back sides'."""
        self._cells: dda.Cells | None = None
        self._bake: SurfaceBake | None = None
        self.weights_key = None
        """lattice_key of the probe grid whose weights are installed (None: none yet)."""
        self._executor = ThreadPoolExecutor(1, thread_name_prefix="indirect-weights") if background else None
        self._job: tuple[tuple, Future] | None = None
        self._kept: dict[tuple, SurfaceBake] = {}
        """The weights of the last KEPT_LATTICES lattices, newest last."""

    def ready_for(self, probes: ProbeGrid) -> bool:
        """Whether the weights of the probes' lattice are installed; starts computing them if not (at
        once, or on the worker with `background`)."""
        key = lattice_key(probes)
        if self.weights_key == key:
            return True
        if key in self._kept:   # a lattice met before (the viewer toggling between GI sources)
            self._install(key, self._kept[key])
            return True
        if self._job is None or self._job[0] != key:
            if self._executor is None:
                self._install(key, self.weights_of(probes))
                return True
            self._job = (key, self._executor.submit(self.weights_of, probes))
        return self.poll()

    def poll(self) -> bool:
        """Install the worker's weights if they are done; True when they were."""
        if self._job is None or not self._job[1].done():
            return False
        key, job = self._job
        self._job = None
        self._install(key, job.result())
        return True

    @property
    def pending(self) -> bool:
        return self._job is not None

    def weights_of(self, probes: ProbeGrid) -> SurfaceBake:
        """Every texel's probe weights for both sides (the back sides with their normals negated)."""
        if self._cells is None:
            self._cells = dda.Cells.of(voxelize_with_faces(self.scene, VISIBILITY_VOXELS), self.scene)
        lightmap = self.lightmap
        faces = lightmap.texel_faces
        face_normal = np.zeros((int(faces.max()) + 1 if len(faces) else 0, 3))
        face_normal[faces] = lightmap.texel_normals
        normals, ids = np.unique(np.round(np.concatenate([face_normal, -face_normal]), 6), axis=0,
                                 return_inverse=True)
        normal_id = np.concatenate([ids[faces], ids[len(face_normal) + faces]])
        weights = SurfaceWeights.of(np.concatenate([lightmap.texel_points] * 2), normals[normal_id], probes,
                                    self._cells)
        return SurfaceBake.of(weights, normal_id, normals)

    def _install(self, key: tuple, bake: SurfaceBake) -> None:
        self._bake, self.weights_key = bake, key
        self._kept = {k: v for k, v in self._kept.items() if k != key}
        self._kept[key] = bake
        while len(self._kept) > KEPT_LATTICES:
            del self._kept[next(iter(self._kept))]
        self._fill = self._dark_fill(bake)

    def _dark_fill(self, bake: SurfaceBake) -> tuple[np.ndarray, np.ndarray]:
        """(pixels, sources): the texels that see no probe (a face's strip under the floor, the ceiling
        above a lamp) next to one of their tile's texels that does take that texel's light, so that the
        bilinear fetch of a visible pixel near the edge never mixes in their darkness."""
        height, width = self.lightmap.covered.shape
        dark = bake.weights.sum(axis=1) == 0.0
        tile = np.full(height * 2 * width, -1, np.int64)
        faces = self.lightmap.texel_faces
        tile[self._pixels] = np.concatenate([2 * faces, 2 * faces + 1])
        lit = np.zeros(height * 2 * width, bool)
        lit[self._pixels[~dark]] = True
        pixels, sources = [], []
        for step in (1, -1, 2 * width, -2 * width):
            candidate = self._pixels[dark] + step
            inside = (candidate >= 0) & (candidate < len(tile))
            candidate = np.where(inside, candidate, 0)
            ok = inside & lit[candidate] & (tile[candidate] == tile[self._pixels[dark]])
            pixels.append(self._pixels[dark][ok])
            sources.append(candidate[ok])
        pixels, sources = np.concatenate(pixels), np.concatenate(sources)
        first = np.unique(pixels, return_index=True)[1]
        return pixels[first], sources[first]

    def update(self, probes: ProbeGrid) -> None:
        """Evaluate and upload the indirect irradiance of `probes` (a lattice that is ready_for)."""
        self._bake.irradiance(probes.coefficients, self._image, self._pixels)
        pixels, sources = self._fill
        self._image[pixels] = self._image[sources]
        self.texture.write(self._image.astype(np.float16).tobytes())

    def use(self, unit: int) -> dict:
        """Bind the indirect lightmap; returns the surface shader's uniforms."""
        self.texture.use(location=unit)
        return dict(indirect_lightmap=unit)

    def release(self) -> None:
        if self._executor is not None:
            self._executor.shutdown(wait=False, cancel_futures=True)
        self.texture.release()

"""VoxelGrid -> the network's input: voxel attributes gathered onto the probe lattice, one colour channel
at a time.

The neural GI source (`viewer.neural.field`) and the training code (`viewer.training`) both call `encode`, so
what the network sees at training time is, bit for bit, what it sees in the viewer.

Four choices make a small network generalize beyond the layouts it was trained on:

- **One colour channel at a time.** Diffuse transport is linear and never mixes colour channels: the red
  probes depend only on the red albedo and red emission (eq. 30 runs per channel). The network is
  monochrome and runs as a batch of three, so a pink wall is just a wall whose albedo differs between
  the three passes, and every training scene teaches three problems.
- **Scale out.** Transport is linear in the emitted light too: each channel's inputs are divided by a
  scale `s` (the mean direct radiance over the probes, shadows included) and the network's output is
  multiplied by it, so a lamp twice as bright gives exactly twice the light, whatever was trained.
- **Direct light as an input, shadowed.** The light arriving straight from the emitters is most of the
  field: one term per emitting lattice cell, times its visibility from the probe. The shadows are
  traced against the scene's own triangles (`viewer.rays.dda`, cell-exact, on the encoder's coarse voxel
  grid), one ray per probe and cluster of VISIBILITY_CELLS^2 emitting cells, and the sun's one ray per
  probe. Version 2 left the shadows to the network, and it could not learn them: on the v2 rooms
  (partitions, objects, lamps on walls) the unshadowed input was 54% off the shadowed direct light in
  the median room, and after training all the light was 64% off, against 12% with traced shadows
  (docs/TRAINING.md).
- **One bounce as an input.** The reflected light, which the renderer shades, is a gather over the whole
  room, beyond what a small network's receptive field carries well: `bounce_sh` reflects the direct
  light once off every surface (albedo x irradiance / pi) and gathers it at a coarse lattice, without
  shadows. The network learns the rest: further bounces, and the shadows of the reflected light.

Layout: inputs (3, CHANNELS, M, M, M) float32, indexed [channel of colour, feature, x, y, z], on the
same lattice as the probes (`ProbeGrid.positions_for(lo, hi, M)`): cell (i, j, k) of the lattice holds
probe (i, j, k) at its centre.
"""

from __future__ import annotations

from dataclasses import dataclass

import numba
import numpy as np
from scipy import sparse

from viewer.rays import dda
from viewer.probes import sh
from viewer.probes.grid import ProbeGrid
from viewer.rays.voxels import VoxelGrid

VERSION = 4
"""Bump when the features change: a model card records the version its network was trained on, and
`viewer.neural.field` refuses a model of another version."""
FEATURES = (
    "density",          # surface area in the cell / cell face area
    "normal_x", "normal_y", "normal_z",  # area-weighted normals / cell face area
    "albedo",           # area-weighted mean albedo of the cell (this colour channel)
    "emission",         # emitted radiance x area / cell face area, / scale
    *(f"direct_{k}" for k in range(sh.SH_COUNT)),  # emitter + sun SH, shadows traced, / scale
    "coord_x", "coord_y", "coord_z",  # probe position in [-1, 1] over the lattice
    "extent_x", "extent_y", "extent_z",  # lattice extent per axis / the largest
    *(f"bounce_{k}" for k in range(sh.SH_COUNT)),  # one bounce of the direct light, unshadowed, / scale
)
CHANNELS = len(FEATURES)
DIRECT = slice(6, 6 + sh.SH_COUNT)
"""Where the direct-light SH sits among the features (the network adds its output to it)."""
BOUNCE = slice(21, 21 + sh.SH_COUNT)
"""Where the one-bounce SH sits (`bounce_sh`: the network's reflected light starts from it)."""
NEAR_FIELD = 1.0 / np.pi
"""r^2 + A/pi: the near-field clamp of the transport kernel, so a probe next to a lamp stays finite."""


@dataclass(frozen=True)
class Encoding:
    inputs: np.ndarray
    """(3, CHANNELS, M, M, M) float32."""
    scale: np.ndarray
    """(3,) per colour channel: multiply the network's output by it (0 where a channel has no light)."""
    lo: np.ndarray
    hi: np.ndarray

    @property
    def resolution(self) -> int:
        return self.inputs.shape[-1]


VISIBILITY_CELLS = 2
"""Edge, in lattice cells, of the clusters of emitting patches that share one visibility ray per probe."""
SHADOW_OFFSET = 1.0
"""A cluster's visibility ray ends this many voxels (of the occluders' grid) in front of its patches'
mean position. Not less: a voxel averages every surface of one facing in its cell, so a lamp lying on
the floor has its position between the lamp's top and the floor, and a ray to it would end inside the
lamp."""


SHADOW_CELLS = 2
"""The occluders' grid is this many times finer than the voxels' (the cells a shadow ray marches)."""


def occluders(scene, voxels: VoxelGrid) -> dda.Cells:
    """What casts the encoding's shadows: every triangle of `scene`, listed on the cells of `voxels`
    divided SHADOW_CELLS times per axis."""
    k = SHADOW_CELLS
    return dda.Cells.blocking(scene, voxels.lo, voxels.voxel_size / k, voxels.resolution * k)


def encode_scene(scene, resolution: int, voxel_resolution: int, lo=None, hi=None) -> Encoding:
    """`encode` of `scene` voxelized at `voxel_resolution`, on the lattice over [lo, hi] (its bounds by
    default)."""
    from viewer.rays.voxels import voxelize

    grid = voxelize(scene, voxel_resolution)
    if lo is None or hi is None:
        lo, hi = scene.bounds
    return encode(grid, scene.sun, lo, hi, resolution, occluders(scene, grid))


def encode(voxels: VoxelGrid, sun, lo, hi, resolution: int, blockers: dda.Cells | None) -> Encoding:
    """The network's input for the probe lattice of `resolution`^3 cells over the box [lo, hi], with the
    direct light shadowed by `blockers` (`occluders`; None: nothing casts a shadow)."""
    lo, hi = np.asarray(lo, np.float64), np.asarray(hi, np.float64)
    m = int(resolution)
    spacing = (hi - lo) / m
    face_area = np.array([spacing[1] * spacing[2], spacing[0] * spacing[2], spacing[0] * spacing[1]])
    cell_area = float(np.mean(face_area))
    cell = np.clip(np.floor((voxels.position - lo) / spacing).astype(np.int64), 0, m - 1)
    flat = (cell[:, 0] * m + cell[:, 1]) * m + cell[:, 2]
    cells = m ** 3
    corners = splat(voxels.position, lo, spacing, m)

    def gather(values: np.ndarray) -> np.ndarray:
        """Trilinear splat onto the cell centres: voxels and lattice cells rarely line up (cubic
        voxels, a lattice over the scene's bounds), and nearest-cell binning leaves whole layers of a
        wall empty where no voxel centre falls."""
        return sum(np.bincount(index, values * weight, minlength=cells) for index, weight in corners)

    area = voxels.area
    density = gather(area)
    normals = np.stack([gather(area * voxels.normal[:, a]) for a in range(3)])
    safe = np.where(density > 0, density, 1.0)
    albedo = np.stack([gather(area * voxels.albedo[:, c]) for c in range(3)]) / safe
    emitted = np.stack([gather(area * voxels.emission[:, c]) for c in range(3)])

    points = lo + (np.stack(np.meshgrid(*[np.arange(m)] * 3, indexing="ij"), -1).reshape(-1, 3) + 0.5) * spacing
    lights = emitting_patches(flat, voxels)
    visible = None
    if blockers is not None:
        visible = patch_visibility(blockers, points, lights[0], lights[1], lo, spacing)
    direct = emitter_sh(lights, points, visible)
    direct += sun_sh(sun, blockers, points)  # (P, 9, 3)
    bounce = bounce_sh(voxels, direct, lo, hi, m)
    scale = np.maximum(direct[:, 0, :], 0.0).mean(axis=0)
    inv = np.where(scale > 0, 1.0 / np.where(scale > 0, scale, 1.0), 0.0)

    inputs = np.empty((3, CHANNELS, cells), np.float32)
    inputs[:, 0] = density / cell_area
    inputs[:, 1:4] = normals / cell_area
    inputs[:, 4] = albedo
    inputs[:, 5] = emitted / cell_area * inv[:, None]
    inputs[:, DIRECT] = (direct * inv).transpose(2, 1, 0)
    coords = (points - lo) / (hi - lo) * 2.0 - 1.0
    inputs[:, 15:18] = coords.T
    extent = hi - lo
    inputs[:, 18:21] = (extent / extent.max())[:, None]
    inputs[:, BOUNCE] = (bounce * inv).transpose(2, 1, 0)
    return Encoding(inputs=inputs.reshape(3, CHANNELS, m, m, m), scale=scale.astype(np.float32), lo=lo, hi=hi)


def splat(points: np.ndarray, lo: np.ndarray, spacing: np.ndarray, m: int):
    """[(flat cell index (P,), weight (P,))] for the 8 cell centres around each point (weights sum to
    1; clamped at the lattice's faces, so a wall on the scene's bounds stays in the boundary layer)."""
    u = np.clip((points - lo) / spacing - 0.5, 0.0, m - 1)
    i0 = np.minimum(np.floor(u).astype(np.int64), max(m - 2, 0))
    f = u - i0
    out = []
    for corner in range(8):
        bits = [(corner >> a) & 1 for a in range(3)]
        index = [i0[:, a] + bits[a] for a in range(3)]
        weight = np.prod([f[:, a] if bits[a] else 1.0 - f[:, a] for a in range(3)], axis=0)
        out.append((np.minimum((index[0] * m + index[1]) * m + index[2], m ** 3 - 1), weight))
    return out


def facings(normal: np.ndarray) -> np.ndarray:
    """(K,) int 0-5: the signed axis each normal (K, 3) is closest to (2 a + 1 for +a, 2 a for -a). Patches
    merge surfaces of one facing only: the two sides of a thin wall in one cell have opposite normals,
    and merged, their mean normal is zero and the patch shines nowhere."""
    axis = np.argmax(np.abs(normal), axis=1)
    return axis * 2 + (np.take_along_axis(normal, axis[:, None], 1)[:, 0] > 0)


def emitting_patches(cell: np.ndarray, voxels: VoxelGrid):
    """The emitting voxels merged per lattice cell and facing: (positions (E, 3), normals (E, 3), areas
    (E,), radiance (E, 3)). Seen from the probes (a lattice cell or more away), the pieces of a lamp in
    one cell all arrive from about the same direction, so one patch per cell keeps the feature cheap."""
    lit = np.flatnonzero(np.any(voxels.emission > 0, axis=1))
    if len(lit) == 0:
        return np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0), np.zeros((0, 3))
    facing = facings(voxels.normal[lit])
    key, group = np.unique(cell[lit] * 8 + facing, return_inverse=True)
    count = len(key)
    a = voxels.area[lit]
    area = np.bincount(group, a, minlength=count)

    def mean(values):
        return np.stack([np.bincount(group, a * values[:, k], minlength=count) for k in range(3)], 1) / area[:, None]

    normal = mean(voxels.normal[lit])
    normal /= np.maximum(np.linalg.norm(normal, axis=1, keepdims=True), 1e-12)
    return mean(voxels.position[lit]), normal, area, mean(voxels.emission[lit])


def patch_visibility(blockers: dda.Cells, points: np.ndarray, position: np.ndarray, normal: np.ndarray,
                     lo: np.ndarray, spacing: np.ndarray) -> np.ndarray:
    """(P, E) float32, 1 where probe p sees emitting patch e (at `position` facing `normal`), else 0: one
    ray per probe and cluster of patches (`shadow_targets`)."""
    if len(position) == 0:
        return np.ones((len(points), 0), np.float32)
    target, cluster = shadow_targets(blockers, position, normal, lo, spacing)
    return dda.pairs_clear(blockers, points, target)[:, cluster]


def shadow_targets(blockers: dda.Cells, position: np.ndarray, normal: np.ndarray, lo: np.ndarray,
                   spacing: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Where the visibility rays of emitting patches end: (C, 3) one point per cluster, and (E,) each
    patch's cluster. Patches are clustered VISIBILITY_CELLS lattice cells a side per facing; a cluster's
    ray ends at the mean of its patches' positions, lifted SHADOW_OFFSET voxels along their normal. So
    a patch's visibility depends on every patch of its cluster, whichever emitter they belong to."""
    if len(position) == 0:
        return np.zeros((0, 3)), np.zeros(0, np.int64)
    facing = facings(normal)
    block = np.floor((position - lo) / (spacing * VISIBILITY_CELLS)).astype(np.int64)
    _, cluster = np.unique(np.column_stack([block, facing]), axis=0, return_inverse=True)
    cluster = cluster.ravel()
    count = cluster.max() + 1
    centre = np.stack([np.bincount(cluster, position[:, a], minlength=count) for a in range(3)], 1)
    centre /= np.bincount(cluster, minlength=count)[:, None]
    lift = np.stack([np.bincount(cluster, normal[:, a], minlength=count) for a in range(3)], 1)
    lift /= np.maximum(np.linalg.norm(lift, axis=1, keepdims=True), 1e-12)
    return centre + SHADOW_OFFSET * blockers.h * lift, cluster


def emitter_sh(lights, points: np.ndarray, visible: np.ndarray | None = None) -> np.ndarray:
    """(P, 9, 3) SH of the light arriving straight from the emitting patches: each patch is a solid
    angle cos_e A / (r^2 + A/pi), seen from the probe if its front faces it, times `visible` (P, E)
    (`patch_visibility`; None: nothing in the way)."""
    rows = None if visible is None else np.asarray(visible).T
    return emitter_sh_rows(lights, points, rows).transpose(2, 1, 0).astype(np.float64)


def emitter_sh_rows(lights, points: np.ndarray, visible: np.ndarray | None = None) -> np.ndarray:
    """`emitter_sh` as (C, 9, P) float32 for a radiance of C channels (lights[3] is (E, C)), with the
    visibility as (E, P) rows: the layout the compiled loop works in (`viewer.neural.encoder` keeps one
    channel per emitter, a radiance of 1 times its weights)."""
    source, normal, area, radiance = lights
    radiance = np.asarray(radiance)   # (E, C)
    out = np.zeros((radiance.shape[1], sh.SH_COUNT, len(points)), np.float32)
    if len(area) == 0:
        return out
    f32 = [np.ascontiguousarray(a, np.float32) for a in (np.asarray(points).T, source, normal, area, radiance)]
    seen = np.ones((len(area), 1), np.float32) if visible is None else np.ascontiguousarray(visible, np.float32)
    _emitter_sh(*f32, seen, visible is not None, np.float32(NEAR_FIELD), out)
    return out


SH_BLOCK = 256
"""Probes per block of `_emitter_sh`: the patch loop runs over a block that stays in L1, and the probe
loop inside it vectorizes."""


@numba.njit(cache=True, nogil=True, fastmath=True, error_model="numpy")
def _emitter_sh(points, source, normal, area, radiance, visible, shadowed, near_field, out):
    """The terms of `emitter_sh`: points (3, P), radiance (E, C), visible (E, P) when `shadowed`, out
    (C, 9, P)."""
    count = points.shape[1]
    w = np.empty(SH_BLOCK, np.float32)
    b = np.empty((9, SH_BLOCK), np.float32)
    one, tiny, zero = np.float32(1.0), np.float32(1e-12), np.float32(0.0)
    for start in range(0, count, SH_BLOCK):
        n = min(SH_BLOCK, count - start)
        px, py, pz = points[0, start:start + n], points[1, start:start + n], points[2, start:start + n]
        for e in range(source.shape[0]):
            sx, sy, sz = source[e, 0], source[e, 1], source[e, 2]
            mx, my, mz = normal[e, 0], normal[e, 1], normal[e, 2]
            flux, clamp = area[e], area[e] * near_field
            for i in range(n):
                x, y, z = sx - px[i], sy - py[i], sz - pz[i]
                r2 = x * x + y * y + z * z
                inv = one / np.sqrt(max(r2, tiny))
                x, y, z = x * inv, y * inv, z * inv
                weight = max(-(x * mx + y * my + z * mz), zero) * flux / (r2 + clamp)
                if shadowed:
                    weight *= visible[e, start + i]
                w[i] = weight
                b[0, i] = np.float32(0.282095)
                b[1, i] = np.float32(0.488603) * y
                b[2, i] = np.float32(0.488603) * z
                b[3, i] = np.float32(0.488603) * x
                b[4, i] = np.float32(1.092548) * x * y
                b[5, i] = np.float32(1.092548) * y * z
                b[6, i] = np.float32(0.315392) * (np.float32(3.0) * z * z - one)
                b[7, i] = np.float32(1.092548) * x * z
                b[8, i] = np.float32(0.546274) * (x * x - y * y)
            for c in range(radiance.shape[1]):
                rc = radiance[e, c]
                if rc == 0:
                    continue
                for k in range(9):
                    row, basis = out[c, k, start:start + n], b[k]   # contiguous views: the loop vectorizes
                    for i in range(n):
                        row[i] += rc * w[i] * basis[i]


BOUNCE_PATCH = 2
"""Edge, in probe-lattice cells, of the patches (per facing) that reflect the light in `bounce_sh`."""
BOUNCE_LATTICE = 2
"""`bounce_sh` gathers on a lattice this many times coarser than the probes' and interpolates: the
bounce is smooth, and the coarse lattice is 8x cheaper (measured on 20 v2 rooms, the best-scaled
one-bounce DC is 37% off the solver's reflected light at 12^3 interpolated, 41% at 24^3, where each
room's mean is 66% off)."""


def bounce_sh(voxels: VoxelGrid, direct: np.ndarray, lo: np.ndarray, hi: np.ndarray, m: int) -> np.ndarray:
    """(P, 9, 3) the direct light reflected once by the surfaces, gathered at the probes without shadows.

    Each voxel's irradiance is its normal's cosine lobe over the direct SH (`direct` (P, 9, 3)) read half
    a voxel in front of it; times albedo / pi it leaves as radiance. Voxels are merged into patches
    (BOUNCE_PATCH cells per facing) that shine on the probes of a lattice BOUNCE_LATTICE times coarser,
    as the emitters do (`emitter_sh`), and the coarse SH is splatted back onto the probes. The light
    reflected many times, and the shadows of this light, are the network's to learn; this term gives it
    the shape: which walls are lit, their colour, how far they are."""
    if voxels.count == 0:
        return np.zeros((m ** 3, sh.SH_COUNT, 3))
    return Bounce(voxels, lo, hi, m).sh(voxels.albedo, direct)


class Bounce:
    """`bounce_sh` for one voxel geometry on one lattice, kept across edits (viewer.neural.encoder).

    The gathered SH is linear in the patches' radiance, so a call whose patches mostly shine as they did
    on the previous call (an albedo edit: the direct light is the same, a group's voxels change colour)
    gathers only the difference of the patches that changed and adds it to the kept coarse SH. The
    voxels' irradiance is kept while the direct light stays equal. A call where more than half the
    patches change gathers everything again, which also drops the round-off the sums carried."""

    def __init__(self, voxels: VoxelGrid, lo: np.ndarray, hi: np.ndarray, m: int, patch: int = BOUNCE_PATCH,
                 lattice: int = BOUNCE_LATTICE):
        lo, hi = np.asarray(lo, np.float64), np.asarray(hi, np.float64)
        self.position, self.normal, self.area = voxels.position, voxels.normal, voxels.area
        self.m, spacing = m, (hi - lo) / m
        front = voxels.position + 0.5 * voxels.voxel_size * voxels.normal
        self._front = splat(front, lo, spacing, m)
        facing = facings(voxels.normal)
        block = np.floor((voxels.position - lo) / (spacing * patch)).astype(np.int64)
        _, patch = np.unique(np.column_stack([block, facing]), axis=0, return_inverse=True)
        self._patch = patch.ravel()
        self._count = int(self._patch.max()) + 1 if len(self._patch) else 0
        self._patch_area = np.bincount(self._patch, voxels.area, minlength=self._count)
        normal = self._mean(voxels.normal)
        self._patch_normal = normal / np.maximum(np.linalg.norm(normal, axis=1, keepdims=True), 1e-12)
        self._patch_position = self._mean(voxels.position)
        coarse = max(m // lattice, 2)
        self._points = ProbeGrid.positions_for(lo, hi, coarse).reshape(-1, 3)
        rows = np.arange(m ** 3)
        corners = splat(ProbeGrid.positions_for(lo, hi, m).reshape(-1, 3), lo, (hi - lo) / coarse, coarse)
        self._spread = sparse.csr_matrix(
            (np.concatenate([w for _, w in corners]), (np.tile(rows, 8), np.concatenate([i for i, _ in corners]))),
            shape=(m ** 3, coarse ** 3))
        self._direct = self._leaving_per_albedo = None
        self._radiance = self._gathered = None
        self.gathered_patches = 0
        """How many patches the last `sh` gathered (all of them, or the ones whose light changed)."""

    def fits(self, voxels: VoxelGrid) -> bool:
        return all(a is b or np.array_equal(a, b) for a, b in
                   ((self.position, voxels.position), (self.normal, voxels.normal), (self.area, voxels.area)))

    def _mean(self, values: np.ndarray) -> np.ndarray:
        """(patches, 3) the voxels' (K, 3) `values` averaged over each patch by area."""
        return np.stack([np.bincount(self._patch, self.area * values[:, k], minlength=self._count)
                         for k in range(3)], 1) / self._patch_area[:, None]

    def gathered(self, radiance: np.ndarray) -> np.ndarray:
        """(P, 9, 3) the light of the voxels leaving with `radiance` (K, 3), gathered at the probes as `sh`
        gathers the bounce (patches as points, no shadows): what this gather makes of any surface light
        (`viewer.training.bounce_floor` gives it the solver's)."""
        if self._count == 0:
            return np.zeros((self.m ** 3, sh.SH_COUNT, 3))
        lights = (self._patch_position, self._patch_normal, self._patch_area, self._mean(radiance))
        coarse = emitter_sh(lights, self._points)
        return (self._spread @ coarse.reshape(len(self._points), -1)).reshape(-1, sh.SH_COUNT, 3)

    def sh(self, albedo: np.ndarray, direct: np.ndarray, channels: np.ndarray | None = None) -> np.ndarray:
        """(P, 9, 3) `bounce_sh` for the voxels' `albedo` (K, 3) under `direct` (P, 9, 3). Only the colour
        `channels` (3,) bool (default all) are brought up to date; the others hold an earlier call's
        values."""
        channels = np.ones(3, bool) if channels is None else np.asarray(channels, bool)
        if self._count == 0:
            return np.zeros((self.m ** 3, sh.SH_COUNT, 3))
        if self._direct is None or not np.array_equal(direct, self._direct):
            incident = sum(w[:, None, None] * direct[index] for index, w in self._front)  # (K, 9, 3)
            self._leaving_per_albedo = np.maximum(sh.irradiance(incident, self.normal), 0.0) / np.pi
            self._direct = np.array(direct, copy=True)
        radiance = self._mean(albedo * self._leaving_per_albedo)  # (patches, 3)
        if self._gathered is None:
            change, rows = np.where(channels, radiance, 0.0), np.arange(self._count)
            self._gathered, self._radiance = np.zeros((len(self._points), sh.SH_COUNT, 3)), np.zeros_like(radiance)
        else:
            change = np.where(channels, radiance - self._radiance, 0.0)
            rows = np.flatnonzero(np.any(change != 0.0, axis=1))
            if 2 * len(rows) > self._count:   # most patches changed: gather them all again
                self._gathered[..., channels] = 0.0
                change, rows = np.where(channels, radiance, 0.0), np.arange(self._count)
        if len(rows):
            lights = (self._patch_position[rows], self._patch_normal[rows], self._patch_area[rows], change[rows])
            self._gathered += emitter_sh(lights, self._points)
        self._radiance[:, channels] = radiance[:, channels]
        self.gathered_patches = len(rows)
        return (self._spread @ self._gathered.reshape(len(self._points), -1)).reshape(-1, sh.SH_COUNT, 3)


def sun_sh(sun, blockers: dda.Cells | None, points: np.ndarray) -> np.ndarray:
    """(P, 9, 3) the sun's delta at the probes where a ray towards it leaves the scene unblocked."""
    out = np.zeros((len(points), sh.SH_COUNT, 3))
    if sun is None or not np.any(np.asarray(sun.irradiance) > 0):
        return out
    direction = np.asarray(sun.direction, np.float64)
    visible = sun_visibility(blockers, points, direction)
    return visible[:, None, None] * sh.project_delta(direction, sun.irradiance)[None]


def sun_visibility(blockers: dda.Cells | None, points: np.ndarray, direction: np.ndarray) -> np.ndarray:
    """(P,) float 1 where a ray from the probe towards the sun (`direction` points to it) escapes."""
    if blockers is None:
        return np.ones(len(points))
    return dda.escapes(blockers, points, direction).astype(np.float64)

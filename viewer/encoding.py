"""VoxelGrid -> the network's input: voxel attributes gathered onto the probe lattice, one colour channel
at a time.

The neural GI source (`viewer.neural`) and the training code (`viewer.training`) both call `encode`, so
what the network sees at training time is, bit for bit, what it sees in the viewer.

Three choices make a small network generalize beyond the layouts it was trained on:

- **One colour channel at a time.** Diffuse transport is linear and never mixes colour channels: the red
  probes depend only on the red albedo and red emission (eq. 30 runs per channel). The network is
  monochrome and runs as a batch of three, so a pink wall is just a wall whose albedo differs between
  the three passes, and every training scene teaches three problems.
- **Scale out.** Transport is linear in the emitted light too: each channel's inputs are divided by a
  scale `s` (the mean unshadowed direct radiance over the probes) and the network's output is
  multiplied by it, so a lamp twice as bright gives exactly twice the light, whatever was trained.
- **Direct light as an input.** The light arriving straight from the emitters, without shadows, is
  cheap to compute exactly (one term per emitting cell) and is most of the field; the network learns
  the rest: shadows and the bounces. The sun is a single direction, so its visibility is traced
  exactly (`Tracer.escapes`), as the solver does.

Layout: inputs (3, CHANNELS, M, M, M) float32, indexed [channel of colour, feature, x, y, z], on the
same lattice as the probes (`ProbeGrid.positions_for(lo, hi, M)`): cell (i, j, k) of the lattice holds
probe (i, j, k) at its centre.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from viewer import sh
from viewer.voxels import VoxelGrid

VERSION = 2
"""Bump when the features change: a model card records the version its network was trained on, and
`viewer.neural` refuses a model of another version."""
FEATURES = (
    "density",          # surface area in the cell / cell face area
    "normal_x", "normal_y", "normal_z",  # area-weighted normals / cell face area
    "albedo",           # area-weighted mean albedo of the cell (this colour channel)
    "emission",         # emitted radiance x area / cell face area, / scale
    *(f"direct_{k}" for k in range(sh.SH_COUNT)),  # unshadowed emitter + traced sun SH, / scale
    "coord_x", "coord_y", "coord_z",  # probe position in [-1, 1] over the lattice
    "extent_x", "extent_y", "extent_z",  # lattice extent per axis / the largest
)
CHANNELS = len(FEATURES)
DIRECT = slice(6, 6 + sh.SH_COUNT)
"""Where the direct-light SH sits among the features (the network adds its output to it)."""
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


def encode(voxels: VoxelGrid, sun, lo, hi, resolution: int) -> Encoding:
    """The network's input for the probe lattice of `resolution`^3 cells over the box [lo, hi]."""
    lo, hi = np.asarray(lo, np.float64), np.asarray(hi, np.float64)
    m = int(resolution)
    spacing = (hi - lo) / m
    face_area = np.array([spacing[1] * spacing[2], spacing[0] * spacing[2], spacing[0] * spacing[1]])
    cell_area = float(np.mean(face_area))
    cell = np.clip(np.floor((voxels.position - lo) / spacing).astype(np.int64), 0, m - 1)
    flat = (cell[:, 0] * m + cell[:, 1]) * m + cell[:, 2]
    cells = m ** 3
    corners = _splat(voxels.position, lo, spacing, m)

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
    direct = emitter_sh(lights, points)
    direct += sun_sh(sun, density.reshape(m, m, m) / cell_area, points, lo, spacing)  # (P, 9, 3)
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
    return Encoding(inputs=inputs.reshape(3, CHANNELS, m, m, m), scale=scale.astype(np.float32), lo=lo, hi=hi)


def _splat(points: np.ndarray, lo: np.ndarray, spacing: np.ndarray, m: int):
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


def emitting_patches(cell: np.ndarray, voxels: VoxelGrid):
    """The emitting voxels merged per lattice cell and facing: (positions (E, 3), normals (E, 3), areas
    (E,), radiance (E, 3)). Seen from the probes (a lattice cell or more away), the pieces of a lamp in
    one cell all arrive from about the same direction, so one patch per cell keeps the feature cheap."""
    lit = np.flatnonzero(np.any(voxels.emission > 0, axis=1))
    if len(lit) == 0:
        return np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0), np.zeros((0, 3))
    facing = np.argmax(np.abs(voxels.normal[lit]) * 2 + (voxels.normal[lit] > 0), axis=1)
    key, group = np.unique(cell[lit] * 8 + facing, return_inverse=True)
    count = len(key)
    a = voxels.area[lit]
    area = np.bincount(group, a, minlength=count)

    def mean(values):
        return np.stack([np.bincount(group, a * values[:, k], minlength=count) for k in range(3)], 1) / area[:, None]

    normal = mean(voxels.normal[lit])
    normal /= np.maximum(np.linalg.norm(normal, axis=1, keepdims=True), 1e-12)
    return mean(voxels.position[lit]), normal, area, mean(voxels.emission[lit])


def emitter_sh(lights, points: np.ndarray) -> np.ndarray:
    """(P, 9, 3) SH of the light arriving straight from the emitting patches, ignoring occlusion: each
    patch is a solid angle cos_e A / (r^2 + A/pi), seen from the probe if its front faces it."""
    source, normal, area, radiance = lights
    out = np.zeros((len(points), sh.SH_COUNT, 3))
    if len(area) == 0:
        return out
    d = source.astype(np.float32)[None, :, :] - points.astype(np.float32)[:, None, :]  # (P, E, 3) to the light
    x, y, z = d[..., 0], d[..., 1], d[..., 2]
    r2 = x * x + y * y + z * z
    inv_r = 1.0 / np.sqrt(np.maximum(r2, 1e-12))
    x, y, z = x * inv_r, y * inv_r, z * inv_r
    n = normal.astype(np.float32)
    cos_e = np.maximum(-(x * n[:, 0] + y * n[:, 1] + z * n[:, 2]), 0.0)
    solid_angle = cos_e * (area / (r2 + area * NEAR_FIELD)).astype(np.float32)
    basis = _basis32(x, y, z)
    basis *= solid_angle  # (9, P, E)
    p, e = solid_angle.shape
    return (basis.reshape(9 * p, e) @ radiance.astype(np.float32)).reshape(9, p, 3).transpose(1, 0, 2)


def _basis32(x: np.ndarray, y: np.ndarray, z: np.ndarray) -> np.ndarray:
    """`sh.basis` in float32, coefficient first: (9, ...) for the components of unit directions."""
    out = np.empty((sh.SH_COUNT,) + x.shape, np.float32)
    out[0] = 0.282095
    np.multiply(y, 0.488603, out=out[1])
    np.multiply(z, 0.488603, out=out[2])
    np.multiply(x, 0.488603, out=out[3])
    np.multiply(x * y, 1.092548, out=out[4])
    np.multiply(y * z, 1.092548, out=out[5])
    np.multiply(z * z, 3 * 0.315392, out=out[6])
    out[6] -= 0.315392
    np.multiply(x * z, 1.092548, out=out[7])
    np.multiply(x * x - y * y, 0.546274, out=out[8])
    return out


SUN_BLOCKING_DENSITY = 0.3
"""A lattice cell whose surface density (area / cell face area) passes this blocks the sun: a wall
through the cell has density about 1, split between two layers at worst (0.5 + 0.5) by the splat."""


def sun_sh(sun, density: np.ndarray, points: np.ndarray, lo: np.ndarray, spacing: np.ndarray) -> np.ndarray:
    """(P, 9, 3) the sun's delta at the probes, times its visibility (`sun_visibility`)."""
    out = np.zeros((len(points), sh.SH_COUNT, 3))
    if sun is None or not np.any(np.asarray(sun.irradiance) > 0):
        return out
    direction = np.asarray(sun.direction, np.float64)
    visible = sun_visibility(density, direction, spacing).reshape(-1)
    return visible[:, None, None] * sh.project_delta(direction, sun.irradiance)[None]


def sun_visibility(density: np.ndarray, direction: np.ndarray, spacing: np.ndarray) -> np.ndarray:
    """(M, M, M) in [0, 1]: how much of the sun reaches each lattice cell's centre.

    A sweep through the lattice slice by slice along the sun's dominant axis, starting at the side that
    faces the sun: a cell sees the sun if the cell one slice towards it (bilinearly, along the sun's
    direction) sees it and is not blocked (surface density above SUN_BLOCKING_DENSITY). Outside the
    lattice is outside the scene: open sky, but a ray leaves the lattice through one of its boundary
    cells, and surfaces on the scene's bounds (the walls of a room) lie in those cells: a ray that
    leaves through a boundary cell holding a surface is blocked. An inner cell's own surface does not
    shade it (a probe next to a box is lit on its side of the box). M slices of M^2 cells: well under
    a millisecond."""
    m = density.shape[0]
    axis = int(np.argmax(np.abs(direction)))
    others = [b for b in range(3) if b != axis]
    towards_sun = 1 if direction[axis] > 0 else -1
    # per slice towards the sun, the ray moves this many cells along the two other axes
    shift = [direction[b] / abs(direction[axis]) * spacing[axis] / spacing[b] for b in others]
    open_ = np.moveaxis(density <= SUN_BLOCKING_DENSITY, axis, 0).astype(np.float32)
    visible = np.ones_like(open_)
    first = m - 1 if towards_sun > 0 else 0
    visible[first] = open_[first]  # the slice facing the sun: only its surfaces stand between it and the sky
    order = range(m - 2, -1, -1) if towards_sun > 0 else range(1, m)
    j, k = np.meshgrid(np.arange(m), np.arange(m), indexing="ij")
    x, y = j + shift[0], k + shift[1]
    x0, y0 = np.floor(x).astype(np.int64), np.floor(y).astype(np.int64)
    fx, fy = (x - x0).astype(np.float32), (y - y0).astype(np.float32)
    for i in order:
        upstream = i + towards_sun
        passed = visible[upstream] * open_[upstream]
        total = np.zeros((m, m), np.float32)
        for dx, wx in ((0, 1 - fx), (1, fx)):
            for dy, wy in ((0, 1 - fy), (1, fy)):
                xi, yi = x0 + dx, y0 + dy
                inside = (xi >= 0) & (xi < m) & (yi >= 0) & (yi < m)
                # leaving sideways: through the boundary cell of this slice, open unless it holds a wall
                edge = open_[i, np.clip(xi, 0, m - 1), np.clip(yi, 0, m - 1)]
                value = np.where(inside, passed[np.clip(xi, 0, m - 1), np.clip(yi, 0, m - 1)], edge)
                total += wx * wy * value
        visible[i] = total
    return np.moveaxis(visible, 0, axis)

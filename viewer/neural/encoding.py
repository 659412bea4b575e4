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
  scale `s` (the mean of the direct-light input's radiance over the probes) and the network's output is
  multiplied by it, so a lamp twice as bright gives exactly twice the light, whatever was trained.
- **Direct light as an input; the probes' direct light computed, not learned.** The light arriving
  straight from the emitters is most of the field: one term per emitting lattice cell, times its
  visibility from the probe. The network predicts the reflected light; all the light at a probe is the
  direct light computed exactly (`probe_direct`: the shadows traced against the scene's own triangles on
  the ray layer, `viewer.rays.voxel_rays`, one ray per probe and cluster of VISIBILITY_CELLS^2 emitting
  cells, and the sun's one ray per probe) plus the predicted reflected light. So the direct input the
  network reads need not carry the probes' shadows (DIRECT_SHADOWS): it is what the reflected light
  needs to know of where the lamps are and how bright, and the voxels' own direct light, which the
  bounces start from, keeps its shadows. Version 2 left the shadows to a network that predicted all
  the light, and it could not learn them (on the v2 rooms all the light 64% off, against 12% with traced
  shadows, docs/TRAINING.md).
- **One bounce as an input.** The reflected light, which the renderer shades, is a gather over the whole
  room, beyond what a small network's receptive field carries well: `bounce_sh` reflects the direct
  light once off every surface (albedo x irradiance / pi, the irradiance summed at each voxel with its
  own shadow rays: viewer/neural/irradiance.py) and gathers it at a coarse lattice, without shadows.
- **The bounce, seen.** Gathered without visibility, light passes through walls, and no network gets
  back which surfaces a probe sees. The `seen` features gather the light reflected once and twice with
  SEEN_RAYS exact rays a probe (viewer/neural/seen.py): noisy, but shadowed. The network learns the
  rest: the denoising, further bounces.

Layout: inputs (3, CHANNELS, M, M, M) float32, indexed [channel of colour, feature, x, y, z], on the
same lattice as the probes (`ProbeGrid.positions_for(lo, hi, M)`): cell (i, j, k) of the lattice holds
probe (i, j, k) at its centre.

The direct light's parts are viewer/neural/direct.py (its shadows viewer/neural/shadows.py), the one
bounce viewer/neural/bounce.py.
"""

from __future__ import annotations

from dataclasses import dataclass
from types import SimpleNamespace

import numpy as np

from viewer.neural.asinh import asinh_rows
from viewer.rays import dda
from viewer.rays.cast import embree_available
from viewer.rays.lattice_sight import SEED_CELLS, SOFT
from viewer.rays.sun import SUN_SIDE
from viewer.rays.voxel_rays import VoxelRays, keyed_cells
from viewer.probes import sh
from viewer.rays.voxels import VoxelGrid, face_facing

# The features' parts, re-exported: callers read them as `encoding.<name>`.
from viewer.neural.bounce import BOUNCE_LATTICE, BOUNCE_PATCH, READ_BACK, Bounce, bounce_sh  # noqa: F401
from viewer.neural.seen import (CHAIN_EVERY, INTERLEAVE, SEED, SEEN_BOUNCES, SEEN_RAYS, TAIL_RATIO_MAX,  # noqa: F401
                                SeenRays, seen_light)
from viewer.neural.irradiance import (emitter_irradiance_rows, sun_irradiance, surface_points,  # noqa: F401
                                      voxel_direct)
from viewer.neural.direct import (NEAR_ALL, NEAR_FIELD, NEAR_PIECES, Pieces, emitter_sh,  # noqa: F401
                                  emitter_sh_rows, emitting_patches, facings, lattice_cells, patch_pieces, splat)
from viewer.neural.shadows import (SHADOW_OFFSET, VISIBILITY_CELLS, lattice_visibility,  # noqa: F401
                                   patch_visibility, shadow_targets, sun_sh, sun_visibility)

VERSION = 14
"""Bump when the features change: a model card records the version its network was trained on, and
`viewer.neural.field` refuses a model of a version it cannot feed (`VERSION_CHANNELS`). Version 7 deals
the seen rays' directions out over the lattice (`viewer.neural.seen.interleaved_lattices`) where
version 6 turned each probe's own: the same features, with less noise in any 3x3x3 neighbourhood.
Version 8 sums the lamps' pieces near them (`direct.NEAR_PIECES`) where version 7 took each lattice
cell's worth of lamp as one term: the same features, the direct light as close to Mitsuba's as the
solver's. Version 9 starts the bounces from the direct light on each voxel (`irradiance.voxel_direct`)
where version 8 read it from the probes' direct SH: the same features, the bounce and seen ones from
the solver's own direct light on the surfaces, and adds the seen rays' open share (`OPEN`) by which
the network weighs the probes it filters. Version 10 reads each further bounce back through the
open-weighted filter (`seen.seen_light`) and gathers the surfaces' light of every bounce without shadows
as the `bounce` input (version 9: the first bounce alone), from which the network takes the fine
detail its filter of the seen light blurs (`viewer.training.models.ProbeNet`). Version 11 gathers four
bounces before the tail where version 10 gathered three (`seen.SEEN_BOUNCES`), and reads each further
bounce three quarters of a voxel in front of the voxels where version 10 read it at half
(`bounce.READ_BACK`): the same features, the seen light's amount within 1.1% of the solver's probes on
the public scenes where it was 1-7% short. Version 12 casts 32 seen rays a probe where version 11 cast
16 (`seen.SEEN_RAYS`): the same features, with less noise in the directions of the seen light. Version
13 lights each voxel by the share of its surface the sun reaches (`viewer.rays.sun`) where version 12
took one ray from its centre: the same features, the sunlit patch not drawn in whole voxels. Version 14
gathers the `bounce` input at a lattice three times coarser than the probes' where version 13 gathered at
half theirs (`bounce.BOUNCE_LATTICE`): the same feature, smoother, for less work at every edit."""
FEATURES = (
    "density",          # surface area in the cell / cell face area
    "normal_x", "normal_y", "normal_z",  # area-weighted normals / cell face area
    "albedo",           # area-weighted mean albedo of the cell (this colour channel)
    "emission",         # emitted radiance x area / cell face area, / scale
    *(f"direct_{k}" for k in range(sh.SH_COUNT)),  # emitter + sun SH, shadows traced, / scale
    "coord_x", "coord_y", "coord_z",  # probe position in [-1, 1] over the lattice
    "extent_x", "extent_y", "extent_z",  # lattice extent per axis / the largest
    *(f"bounce_{k}" for k in range(sh.SH_COUNT)),  # the seen light's surfaces gathered unshadowed, / scale
    *(f"seen_{k}" for k in range(sh.SH_COUNT)),  # the surfaces' reflected light through SEEN_RAYS rays, / scale
    "open",             # the share of those rays that leave the probe into the open (0 inside a solid)
)
CHANNELS = len(FEATURES)
DIRECT_SHADOWS = False
"""Whether the direct-light input (and the scale it sets) carries the probes' shadows, for the networks
trained now (`viewer.training.samples` encodes with it, the card records it); the viewer encodes as a
network's card says (`ModelCard.direct_shadows`: networks trained before it record none and had them). Without
them a new scene skips tracing every probe's visibility to every lamp (val-00003 148 -> 121 ms, val-00009
181 -> 131 ms, stage by stage on 2 cores), and an object's move every probe's basis it changed, where
the reflected light moved little: the network trained with them and fed unshadowed direct light was at
worst 1.46x -> 1.52x the solver's error on the 26 evaluation scenes; fine-tuned on it, 1.498x
(docs/TRAINING.md)."""
SETTINGS = {"seen_rays": SEEN_RAYS, "direct_shadows": DIRECT_SHADOWS, "seen_bounces": SEEN_BOUNCES,
            "chain_every": CHAIN_EVERY,
            "tail_ratio_max": TAIL_RATIO_MAX, "interleave": INTERLEAVE, "seed": SEED, "read_back": READ_BACK,
            "bounce_patch": BOUNCE_PATCH,
            "bounce_lattice": BOUNCE_LATTICE, "near_pieces": NEAR_PIECES, "shadow_offset": SHADOW_OFFSET,
            "visibility_cells": VISIBILITY_CELLS, "sun_side": SUN_SIDE, "near_all": NEAR_ALL,
            "sight_seed_cells": SEED_CELLS, "sight_soft": SOFT}
"""The constants the features are made with besides their version: a training cache is keyed by them,
so that features tuned without a version bump are made again rather than read stale."""
VERSION_CHANNELS = {10: CHANNELS, 11: CHANNELS, 12: CHANNELS, 13: CHANNELS, 14: CHANNELS}
"""The features a network of each encoding version reads: the first this many of FEATURES. A version-10
network is fed version 11's features: the same features with the seen light's amount closer to the
truth, on which the version-10 network's indirect light is closer to Mitsuba on the public scenes, and
its images too; a version-11 network is fed version 12's, whose directions are less noisy (9.6% -> 9.3%
and 8.2% -> 7.7% off Mitsuba's indirect light in paper-test and CornellBox-Original, docs/TRAINING.md). Networks of
versions 4-7 are refused: they learnt to correct a direct light of one term per lattice cell of lamp and
overcorrect version 8's (the version-7 network's paper-test went from 6.4% to 9.1% off Mitsuba), and
version 8's learnt the reflected light of surfaces lit as the probes' SH lit them, and version 9's a
`bounce` input of the first bounce alone, with no detail taken from it."""
DIRECT = slice(6, 6 + sh.SH_COUNT)
"""Where the direct-light SH sits among the features (the network adds its output to it)."""
BOUNCE = slice(21, 21 + sh.SH_COUNT)
"""Where the unshadowed gather of the seen light's surfaces sits (`Bounce.gathered`: smooth, exact
between the probes, leaking through walls)."""
SEEN = slice(30, 30 + sh.SH_COUNT)
"""Where the seen bounce's SH sits (viewer/neural/seen.py)."""
OPEN = FEATURES.index("open")
"""The seen rays' open share (`SeenRays.open`): the weight of each probe in the network's filter of the
seen light, so that a probe beside a wall does not average in the dark of the probes inside it."""
COMPRESSED = (slice(FEATURES.index("emission"), DIRECT.stop), slice(BOUNCE.start, SEEN.stop))
"""The features the network's convolutions read through asinh (`compressed`): the light, which spans five
orders of magnitude within a room."""


def compressed(inputs: np.ndarray, previous: tuple[np.ndarray, np.ndarray] | None = None) -> np.ndarray:
    """(passes, CHANNELS, M, M, M) float32: the encoded `inputs` as the network's convolutions read them,
    the light (`COMPRESSED`) through asinh. A network exported with two inputs takes it beside the
    inputs: the eight ONNX operators that spell asinh cost 4 ms of the network's 19 on a 24^3 lattice's
    three passes. Compiled, in one pass that copies the other channels, shared among the cores
    (`viewer.neural.asinh`, with a logarithm that vectorizes: 0.8-0.9 ms for those three passes on an
    Intel Xeon with AVX-512, where the C library's log took 2.9). numpy's asinh took 1.3 ms on an Intel
    Xeon machine, whose vector library it has a kernel for, but 27 ms of one core on an AMD EPYC one,
    which it has none for.

    `previous`: (inputs, compressed) of an earlier call of the same shape: the rows (pass, feature) whose
    inputs are equal to its are copied from it rather than computed again (an albedo edit leaves the
    emission and the direct light as they were)."""
    source = np.ascontiguousarray(inputs, np.float32)
    shape = source.shape
    flat = source.reshape(shape[0], shape[1], -1)
    light = np.zeros(shape[1], np.bool_)
    for part in COMPRESSED:
        light[part] = True
    out = np.empty_like(flat)
    if previous is not None and previous[0].shape == shape and previous[1].shape == shape:
        before = (np.ascontiguousarray(previous[0], np.float32).reshape(flat.shape),
                  np.ascontiguousarray(previous[1], np.float32).reshape(flat.shape))
    else:
        before = (flat[:0], out[:0])
    asinh_rows(flat, light, out, *before)
    return out.reshape(shape)


@dataclass(frozen=True)
class Encoding:
    inputs: np.ndarray
    """(3, CHANNELS, M, M, M) float32."""
    scale: np.ndarray
    """(3,) per colour channel: multiply the network's output by it (0 where a channel has no light)."""
    lo: np.ndarray
    hi: np.ndarray
    links: np.ndarray | None = None
    """(3, M, M, M) bool: `SeenRays.links`, where the network's seen filter stops (None: nothing seen)."""

    @property
    def resolution(self) -> int:
        return self.inputs.shape[-1]


SHADOW_CELLS = 2
"""The occluders' grid is this many times finer than the voxels' (the cells a shadow ray marches)."""


class Occluders(VoxelRays):
    """What casts the encoding's shadows: every triangle of `scene`, on the ray layer (Embree where it is
    installed; else the DDA on the cells of `voxels` divided SHADOW_CELLS times per axis: Embree needs only
    the grid's frame, and listing a 68k-triangle scan's triangles in the cells took 52 ms); and
    `landing`, the same triangles listed on the voxels' own grid, where the seen rays land (one Embree
    hierarchy serves both)."""

    def __init__(self, scene, voxels: VoxelGrid, backend: str | None = None, previous: "Occluders | None" = None):
        """`previous`: the occluders of the same faces before some of them moved (`VoxelRays`).

        Embree is built for the encoding's rays, about a million a geometry (the seen rays, 64 from each of
        a 24^3 lattice): at its default build quality up to QUICK_FACES triangles a hierarchy, quickly
        above (`embree.Hierarchy`). Those rays in generator rooms of 118 and 904 triangles: 47 -> 29 and
        70 -> 47 ms at the default quality, where the build stays under half a millisecond; a 68k-triangle
        scan's 58 -> 51 ms would cost 10 ms more to build. (Where coplanar faces tie, a box's base on the
        floor, the two builds may give a ray different faces: docs/PERFORMANCE.md.)"""
        k = SHADOW_CELLS
        backend = backend or ("embree" if embree_available() else "dda")
        grid = (scene, voxels.lo, voxels.voxel_size / k, voxels.resolution * k)
        super().__init__(scene, dda.Cells.unlisted(*grid) if backend == "embree" else dda.Cells.blocking(*grid), backend,
                         previous=previous, quick=None)
        if self.backend == "embree":   # Embree names the faces: their voxels are looked up by key
            landing = keyed_cells(voxels, voxel_keys(voxels), scene)
        else:
            landing = landing_cells(scene, voxels, None if previous is None else previous.landing.cells)
        self.landing = VoxelRays(scene, landing, self.backend, self.caster)


def voxel_keys(voxels: VoxelGrid) -> np.ndarray:
    """(K,) each voxel's key (flat cell x 6 + facing), remade from its cell and its normal, whose signed
    dominant axis is its pieces' (their area-weighted mean keeps it)."""
    n, c = voxels.resolution, voxels.coords
    return (c[:, 0] + n * (c[:, 1] + n * c[:, 2])) * 6 + face_facing(voxels.normal)


def occluders(scene, voxels: VoxelGrid, previous: Occluders | None = None) -> Occluders:
    """The `Occluders` of `scene`'s triangles, for the voxels made from it; `previous`: those of the same
    faces before some of them moved."""
    return Occluders(scene, voxels, previous=previous if isinstance(previous, Occluders) else None)


def landing_cells(scene, voxels: VoxelGrid, previous: dda.Cells | None = None) -> dda.Cells:
    """`dda.Cells.of` for a voxel grid without its voxelization (`voxel_keys`). `previous`: the landing
    cells of the same faces before some moved."""
    return dda.Cells.of(SimpleNamespace(grid=voxels, keys=voxel_keys(voxels)), scene, previous)


def seen_rays(blockers: VoxelRays | None, voxels: VoxelGrid, points: np.ndarray, previous: SeenRays | None = None,
              box=None, rays: int = SEEN_RAYS, reuse: bool = False) -> SeenRays | None:
    """The seen rays of the lattice `points` on `blockers`' landing listing, `rays` a probe; None without
    `Occluders` (nothing is seen then: the seen features are zero). `previous`, `box`, `reuse`: see
    `SeenRays`."""
    if not isinstance(blockers, Occluders):
        return None
    return SeenRays(blockers.landing, voxels.count, points, rays, previous=previous, box=box, voxels=voxels,
                    reuse=reuse)


def encode_scene(scene, resolution: int, voxel_resolution: int, lo=None, hi=None,
                 direct_shadows: bool = True) -> Encoding:
    """`encode` of `scene` voxelized at `voxel_resolution`, on the lattice over [lo, hi] (its bounds by
    default)."""
    from viewer.rays.voxels import voxelize

    grid = voxelize(scene, voxel_resolution)
    if lo is None or hi is None:
        lo, hi = scene.bounds
    return encode(grid, scene.sun, lo, hi, resolution, occluders(scene, grid), direct_shadows)


def lit_voxels(scene, resolution: int) -> tuple[VoxelGrid, VoxelRays | None, np.ndarray]:
    """The scene voxelized on the lattice of `resolution`^3 cells over its bounds, what casts its shadows
    (`occluders`) and each voxel's direct irradiance (`voxel_direct`, K x 3): where `encode`'s bounce and
    seen features start."""
    from viewer.rays.voxels import voxelize

    lo, hi = scene.bounds
    m = int(resolution)
    grid = voxelize(scene, m)
    blockers = occluders(scene, grid)
    spacing = (hi - lo) / m
    flat = lattice_cells(grid.position, lo, spacing, m)
    lights = emitting_patches(flat, grid)
    pieces = patch_pieces(flat, grid, lights[3], NEAR_PIECES * spacing.max())
    return grid, blockers, voxel_direct(grid, lights, pieces, blockers, scene.sun, lo, spacing)


def lattice_points(lo: np.ndarray, spacing: np.ndarray, m: int) -> np.ndarray:
    """(m^3, 3) the lattice's cell centres, x slowest (`ProbeGrid.positions_for`'s order)."""
    return lo + (np.stack(np.meshgrid(*[np.arange(m)] * 3, indexing="ij"), -1).reshape(-1, 3) + 0.5) * spacing


def probe_direct(voxels: VoxelGrid, sun, lo, hi, resolution: int, blockers: VoxelRays | None) -> np.ndarray:
    """(m^3, 9, 3) the light arriving at the probes straight from the emitters and the sun, shadowed by
    `blockers`: what all the light adds to the reflected light the network predicts (`encode`'s direct
    input, with its shadows)."""
    lo, hi = np.asarray(lo, np.float64), np.asarray(hi, np.float64)
    m = int(resolution)
    spacing = (hi - lo) / m
    flat = lattice_cells(voxels.position, lo, spacing, m)
    lights = emitting_patches(flat, voxels)
    pieces = patch_pieces(flat, voxels, lights[3], NEAR_PIECES * spacing.max())
    return _direct(lights, pieces, sun, lattice_points(lo, spacing, m), lo, spacing, blockers)


def _direct(lights, pieces, sun, points, lo, spacing, blockers: VoxelRays | None) -> np.ndarray:
    """(P, 9, 3) the emitters' and the sun's light at `points`, shadowed by `blockers` (None: unshadowed)."""
    visible = None if blockers is None else lattice_visibility(blockers, points, lights[0], lights[1], lo, spacing)
    return emitter_sh(lights, points, visible, pieces) + sun_sh(sun, blockers, points)


def encode(voxels: VoxelGrid, sun, lo, hi, resolution: int, blockers: VoxelRays | None,
           direct_shadows: bool = True) -> Encoding:
    """The network's input for the probe lattice of `resolution`^3 cells over the box [lo, hi], the
    light shadowed by `blockers` (`occluders`; None: nothing casts a shadow); the probes' direct light
    without its shadows where not `direct_shadows` (the voxels' keeps them)."""
    lo, hi = np.asarray(lo, np.float64), np.asarray(hi, np.float64)
    m = int(resolution)
    spacing = (hi - lo) / m
    face_area = np.array([spacing[1] * spacing[2], spacing[0] * spacing[2], spacing[0] * spacing[1]])
    cell_area = float(np.mean(face_area))
    flat = lattice_cells(voxels.position, lo, spacing, m)
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

    points = lattice_points(lo, spacing, m)
    lights = emitting_patches(flat, voxels)
    pieces = patch_pieces(flat, voxels, lights[3], NEAR_PIECES * spacing.max())
    direct = _direct(lights, pieces, sun, points, lo, spacing, blockers if direct_shadows else None)
    bounce, seen, rays = np.zeros((cells, sh.SH_COUNT, 3)), np.zeros((cells, sh.SH_COUNT, 3)), None
    if voxels.count:
        once = Bounce(voxels, lo, hi, m)
        once.light(direct, voxel_direct(voxels, lights, pieces, blockers, sun, lo, spacing))
        surface = once.leaving(voxels.albedo)
        rays = seen_rays(blockers, voxels, points)
        if rays is not None:
            seen, surface = seen_light(rays, once, voxels.albedo, surface)
        bounce = once.gathered(surface)
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
    inputs[:, SEEN] = (seen * inv).transpose(2, 1, 0)
    inputs[:, OPEN] = 1.0 if rays is None else rays.open
    return Encoding(inputs=inputs.reshape(3, CHANNELS, m, m, m), scale=scale.astype(np.float32), lo=lo, hi=hi,
                    links=None if rays is None else rays.links)

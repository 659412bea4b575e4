"""The network's input across edits: `viewer.neural.encoding.encode`'s numbers for one probe lattice, where an
edit recomputes only what it changes.

Geometry changes rarely and light often (docs/ARCHITECTURE.md). `encode` spends most of its time on the direct
light (every emitting patch against every probe, its shadows traced: `encoding.patch_visibility`) and
on splatting the voxels onto the lattice. An `Encoder` keeps, for the voxel geometry it last saw
(positions, normals, areas) and the occluders it was given (`encoding.occluders`; these two parts are
viewer/neural/lattice.py):

- the trilinear splat as a sparse matrix (lattice cells x voxels), and what it gives from geometry
  alone: the density and normal features, with the coordinate and extent ones;
- the emitters: the emitting patches of `encoding.emitting_patches`, in groups that share one colour
  and touch each other (a lamp), each with the shadowed SH of its patches at every probe summed once
  (`emitter_basis`; the probes near a patch sum its pieces, `encoding.patch_pieces`): each patch's
  terms times its visibility, traced as `encode` traces it (one ray per probe and cluster of patches,
  `encoding.shadow_targets`; none where the network reads the direct light without the probes'
  shadows, `direct_shadows`). It is linear in the emitted radiance: a colour is the basis times an RGB;
- the sun's visibility for the last direction (`encoding.sun_visibility`): its irradiance is a factor;
- the bounce feature's patches and the voxels' last direct light (`encoding.Bounce`);
- the seen rays (`encoding.seen_rays`), cast once per geometry and occluders: any edit of light or
  colour gathers the voxels' new reflected light along them, without casting, and gathers the same
  light again from the patches without shadows (the bounce feature).

So an emission colour or intensity edit is a few products over the cached bases, and an albedo edit
recomputes the albedo feature and the bounces of the passes it changes; neither traces a ray. New
occluders (a moved lamp or object: the triangles cast other shadows) recompute every basis and the
sun's visibility. With the same occluders, patches that start emitting or change cluster get new bases,
traced for their clusters alone (the other emitters keep theirs), and a new geometry recomputes the
splat.

A colour pass whose inputs an edit leaves unchanged is noted in `revisions`, so that the network's
output for it can be reused: the scale-out normalization divides each pass's light by its own scale,
so a light edit that scales every emitter of a channel by the same factor (a single lamp's colour or
intensity) leaves that channel's network input as it was. The network then does not run at all.
"""

from __future__ import annotations

import itertools
import time
from dataclasses import dataclass
from types import SimpleNamespace

import numpy as np
from scipy import ndimage

from viewer.rays.voxel_rays import VoxelRays
from viewer.neural import encoding
from viewer.probes import sh
from viewer.neural.encoding import CHANNELS, Encoding
from viewer.neural.changes import (kept_received, patch_keys, proportional_channels, rows_changed, same_columns,
                                   same_direction, same_sun, sun_parts)
from viewer.neural.lattice import LatticeGeometry, LatticeShadows, assemble, direct_light, moved_box
from viewer.probes.grid import ProbeGrid
from viewer.rays.voxels import VoxelGrid

SAME_COLOUR = 1e-9
"""Two patches belong to one emitter when their radiances point the same way in RGB to this
tolerance; an emitter keeps its basis while its patches' radiances stay proportional to it."""
_serials = itertools.count()


@dataclass
class Emitter:
    """Emitting patches that share one colour and touch each other: a lamp, or one glowing object."""

    weights: dict[bytes, float]
    """Patch (position, normal, area and the end of its visibility ray, as bytes) -> its share w: its
    radiance is w x `radiance`."""
    basis: np.ndarray
    """(9, P) float32: sum over the patches of w x their SH at the probes (radiance 1), times their
    visibility."""
    received: np.ndarray
    """(K,) float32: the same for the voxels' irradiance (`irradiance.voxel_direct`)."""
    radiance: np.ndarray
    """(3,) the current radiance per unit weight."""
    shadows: tuple | None = None
    """(visibility rows (R, P), each patch's row of them (E,)) the basis was made with: after a move, only
    the probes whose rows changed are summed again (a probe's basis depends on its own rows alone)."""
    lit: tuple | None = None
    """(voxels, their visibility rows (R, K), each patch's row of them (E,), the patches' pieces)
    `received` was made with: after a move, a voxel that kept its surface (`changes.same_voxels`) and
    its rows keeps its value, and the others are summed again."""


class Encoder:
    """`encoding.encode(voxels, sun, lo, hi, resolution, blockers)`, kept across calls (see the module
    docstring).

    One encoder serves one lattice; any voxel grid and occluders may be passed to `encode`, and whatever
    still holds from the previous call is reused."""

    def __init__(self, lo, hi, resolution: int, rays: int = encoding.SEEN_RAYS,
                 direct_shadows: bool = True):
        """`rays`: the seen rays a probe, and `direct_shadows` whether the probes' direct light carries their
        shadows (as the network was trained: `ModelCard.seen_rays`, `ModelCard.direct_shadows`)."""
        self.lo, self.hi = np.asarray(lo, np.float64), np.asarray(hi, np.float64)
        self.resolution = int(resolution)
        self.rays = int(rays)
        self.direct_shadows = bool(direct_shadows)
        self.points = ProbeGrid.positions_for(self.lo, self.hi, self.resolution).reshape(-1, 3)  # x slowest, as encode
        self.serial = next(_serials)
        """Tells encoders apart (a cache of the network's outputs keys on it and on `revisions`)."""
        self.revisions = np.zeros(3, np.int64)
        """Per colour pass: bumped whenever an encoding's inputs for that pass differ from the previous
        one's; equal revisions of one encoder mean equal inputs."""
        self.emitters: list[Emitter] = []
        self.recomputed: list[str] = []
        """What the last `encode` had to recompute: `geometry`, `shadows` (new occluders), `albedo`,
        `emission`, `emitters` (a basis), `sun`."""
        self.ray_seconds = 0.0
        """How long the last `encode` spent casting the seen rays (a new geometry or new occluders)."""
        self._geometry: LatticeGeometry | None = None
        self._shadows: LatticeShadows | None = None
        self._voxel_shadows: LatticeShadows | None = None   # the same rays from the voxels' surfaces
        self._albedo = self._emission = None        # the voxels' (K, 3) of the last call
        self._albedo_feature = None                 # (3, cells) float32
        self._emitted = None                        # (cells, 3) splatted emitted radiance x area
        self._sun = (None, np.zeros(3))             # (direction or None, irradiance)
        self._bounce: encoding.Bounce | None = None   # the bounce's patches and their last light
        self._seen: encoding.SeenRays | None = None   # the seen rays of this geometry and occluders
        self._last: Encoding | None = None
        self._moved = False   # the last occluders were the ones before with some triangles moved
        self._last_voxels: VoxelGrid | None = None

    @property
    def seen(self) -> "encoding.SeenRays | None":
        """The seen rays of the last encoded geometry (None without occluders)."""
        return self._seen

    def fits(self, lo, hi, resolution: int) -> bool:
        return (int(resolution) == self.resolution and np.array_equal(np.asarray(lo, np.float64), self.lo)
                and np.array_equal(np.asarray(hi, np.float64), self.hi))

    def encode(self, voxels: VoxelGrid, sun, blockers: VoxelRays | None) -> Encoding:
        """The network's input for `voxels` and `sun`, shadowed by `blockers` (`encoding.occluders` of the
        scene; None: nothing casts a shadow): `encoding.encode`'s numbers (to float32 round-off). Pass
        the same occluders object while the scene's triangles stay the same: an equal new one is found
        equal, at the cost of comparing its arrays."""
        direction, irradiance = sun_parts(sun)
        shadows_changed = self._shadows is None or not self._shadows.fits(blockers)
        if (voxels is self._last_voxels and not shadows_changed
                and same_sun((direction, irradiance), self._sun) and self._last is not None):
            self.recomputed = []
            return self._last
        self.recomputed = []
        self.ray_seconds = 0.0
        geometry_changed = self._geometry is None or not self._geometry.fits(voxels)
        if geometry_changed:
            self._geometry = LatticeGeometry(voxels, self.lo, self.hi, self.points, self._geometry)
            self.recomputed.append("geometry")
        # where only some triangles moved: the box around their old and new places, outside which the
        # seen rays and the shadow rays keep their answers
        box = None if not shadows_changed or self._shadows is None else moved_box(self._shadows.blockers, blockers)
        if geometry_changed or shadows_changed:
            clock = time.perf_counter()
            previous, self._seen = self._seen, None   # dropped: made into the new ones (none if that fails)
            self._seen = encoding.seen_rays(blockers, voxels, self.points, previous, box, self.rays, reuse=True)
            self.ray_seconds = time.perf_counter() - clock
        if shadows_changed:
            self._shadows = LatticeShadows(blockers, self.points, self.lo, self._geometry.spacing,
                                           None if box is None else self._shadows, box)
            if box is None:   # other occluders: every basis holds the old shadows
                self.emitters = []
            self.recomputed.append("shadows")
        self._moved = shadows_changed and box is not None
        """Whether the occluders are the previous ones with some triangles moved: a kept emitter's basis is
        summed again only at the probes whose visibility rows changed."""
        if shadows_changed or geometry_changed:
            self._voxel_shadows = LatticeShadows(blockers, encoding.surface_points(voxels), self.lo,
                                                 self._geometry.spacing, self._voxel_shadows if box is not None
                                                 else None, box, across=voxels)
        g = self._geometry
        albedo_changed = (np.ones(3, bool) if geometry_changed
                          else ~same_columns(self._albedo, voxels.albedo))
        if albedo_changed.any():
            self._albedo_feature = np.asarray((g.gather(voxels.albedo) / g.safe[:, None]).T, np.float32)
            self.recomputed.append("albedo")
        light_changed = geometry_changed or shadows_changed or not np.array_equal(self._emission, voxels.emission)
        emitters_changed = False
        if light_changed:
            self._emitted = g.gather(voxels.emission)
            emitters_changed = self._update_emitters(voxels, geometry_changed)
            self.recomputed.append("emission")
        sun_moved = not same_direction(direction, self._sun[0])
        if (sun_moved or shadows_changed) and direction is not None:
            self.recomputed.append("sun")
        unchanged = ~albedo_changed
        if geometry_changed or shadows_changed or emitters_changed or sun_moved:
            unchanged[:] = False
        elif light_changed or not np.array_equal(irradiance, self._sun[1]):
            unchanged &= proportional_channels((self._emission, self._sun[1]), (voxels.emission, irradiance))
        self._albedo, self._emission, self._sun = voxels.albedo, voxels.emission, (direction, irradiance)
        direct = self._direct(direction, irradiance)  # (3, 9, P) float32
        scale = np.maximum(direct[:, 0, :], 0.0).mean(axis=1)
        if self._last is not None and unchanged.all():
            inputs = self._last.inputs
        else:
            inputs = self._assemble(voxels, direct, self._received(voxels, direction, irradiance), scale, unchanged)
        self.revisions += ~unchanged
        self._last = Encoding(inputs=inputs, scale=scale.astype(np.float32), lo=self.lo, hi=self.hi)
        self._last_voxels = voxels
        return self._last

    # ---- the parts ----------------------------------------------------------------------------------
    def _assemble(self, voxels: VoxelGrid, direct: np.ndarray, received: np.ndarray, scale: np.ndarray,
                  unchanged: np.ndarray) -> np.ndarray:
        """(3, CHANNELS, M, M, M) float32, as `encode` lays it out; passes in `unchanged` keep the
        previous encoding's values (equal to round-off), so the network's output for them still holds.
        The seen and bounce features are gathered again for the other passes only."""
        g, m = self._geometry, self.resolution
        redo = np.ones(3, bool) if self._last is None else ~unchanged
        if self._bounce is None or not self._bounce.fits(voxels):
            self._bounce = encoding.Bounce(voxels, self.lo, self.hi, m)
        seen = bounce = None
        if voxels.count and redo.any():
            self._bounce.light(None, received)
            surface = self._bounce.leaving(voxels.albedo)[:, redo]
            if self._seen is not None:
                seen, surface = encoding.seen_light(self._seen, self._bounce, voxels.albedo[:, redo], surface)
            bounce = self._bounce.gathered(surface)
        seen, bounce = _passes(seen, redo, np.float32, m ** 3), _passes(bounce, redo, np.float64, m ** 3)
        inv = np.where(scale > 0, 1.0 / np.where(scale > 0, scale, 1.0), 0.0)
        previous = None if self._last is None else self._last.inputs.reshape(3, CHANNELS, -1)
        opened = (np.ones(m ** 3, np.float32) if self._seen is None or not voxels.count
                  else self._seen.open)
        inputs = assemble(g.features, self._albedo_feature, self._emitted.T / g.cell_area, direct, bounce, seen,
                          opened, inv, unchanged, previous)
        inputs = inputs.reshape(3, CHANNELS, m, m, m)
        inputs.flags.writeable = False  # shared with the next encoding when it is the same
        return inputs

    def _direct(self, direction, irradiance) -> np.ndarray:
        """(3, 9, P) float32: the emitters' bases times their radiance, plus the sun."""
        p, sun, visible = len(self.points), None, None
        if direction is not None and np.any(irradiance > 0):
            visible = (self._shadows.sun_visibility(direction) if self.direct_shadows else np.ones(p, np.float32))
            delta = sh.basis(direction / np.linalg.norm(direction))  # per unit irradiance (sh.project_delta)
            sun = (np.asarray(irradiance, np.float64)[:, None] * delta[None, :]).astype(np.float32)
        return direct_light([e.basis for e in self.emitters], [e.radiance for e in self.emitters], sun, visible, p)

    def _received(self, voxels: VoxelGrid, direction, irradiance) -> np.ndarray:
        """(K, 3) the voxels' irradiance straight from the emitters and the sun (`encoding.voxel_direct`)."""
        out = np.zeros((voxels.count, 3))
        for emitter in self.emitters:
            out += emitter.received.astype(np.float64)[:, None] * emitter.radiance[None]
        if direction is not None and np.any(irradiance > 0):
            sun = SimpleNamespace(direction=direction, irradiance=irradiance)
            out += encoding.sun_irradiance(sun, self._voxel_shadows.sun_visibility(direction), voxels.normal)
        return out

    def _update_emitters(self, voxels: VoxelGrid, new_voxels: bool) -> bool:
        """Match the emitting patches to the emitters kept so far; patches of no kept emitter (a lamp
        moved or resized, a new light, a colour no longer shared, a patch whose cluster of visibility
        rays gained or lost a patch) form new ones, whose rays are traced and bases computed. With
        `new_voxels` (the geometry changed) or after a move, the kept emitters' values at the voxels
        (`received`) are summed again where the voxels or their shadows changed. Returns whether the
        emitters changed (beyond their radiances)."""
        position, normal, area, radiance = encoding.emitting_patches(self._geometry.cell, voxels)
        target, cluster = self._shadows.targets(position, normal)
        if self._shadows.switched:   # the probes' visibility is found another way now: no basis holds
            self.emitters = []
        keys = patch_keys(position, normal, area, target[cluster])
        index = {key: e for e, key in enumerate(keys)}
        claimed = np.zeros(len(keys), bool)
        kept, matched = [], []
        for emitter in self.emitters:
            members = [index.get(key) for key in emitter.weights]
            if any(e is None for e in members) or claimed[members].any():
                continue
            weights = np.fromiter(emitter.weights.values(), np.float64, len(members))
            rows = radiance[members]
            top = int(np.argmax(weights))
            per_weight = rows[top] / weights[top]
            if np.abs(rows - weights[:, None] * per_weight).max() <= SAME_COLOUR * max(np.abs(rows).max(), 1e-300):
                emitter.radiance = per_weight
                claimed[members] = True
                kept.append(emitter)
                matched.append((emitter, np.array(members), weights))
        stale = matched if new_voxels or self._moved else []
        resum = matched if self._moved and self.direct_shadows else []   # unshadowed bases hold after a move
        fresh = np.flatnonzero(~claimed)
        changed = len(kept) != len(self.emitters) or len(fresh) > 0
        lamps = self._lamps(fresh, position, radiance, voxels.voxel_size)
        if not lamps and not stale and not resum:   # a colour or intensity edit keeps every emitter, needs no pieces
            self.emitters = kept
            return changed
        pieces = encoding.patch_pieces(self._geometry.cell, voxels, radiance,
                                       encoding.NEAR_PIECES * self._geometry.spacing.max())
        row, visible = np.full(len(target), -1), None   # each traced cluster's row of `visible`
        traced = np.unique(np.concatenate([cluster[fresh]] + [cluster[m] for _, m, _ in resum]))
        if len(fresh):
            self.recomputed.append("emitters")
        if len(traced) and self.direct_shadows:
            row[traced] = np.arange(len(traced))
            visible = self._shadows.visibility(target[traced])
        for emitter, members, weights in resum:
            own = row[cluster[members]]
            basis = self._summed_again(emitter, own, visible, (position[members], normal[members], area[members],
                                                                weights), pieces.of(members))
            if basis is not emitter.basis:
                self.recomputed.append("emitters")
            emitter.basis, emitter.shadows = basis, (visible, own)
        voxel_row = np.full(len(target), -1)   # the same for the voxels' rays, which the stale need too
        traced = np.unique(np.concatenate([cluster[fresh]] + [cluster[m] for _, m, _ in stale]))
        voxel_row[traced] = np.arange(len(traced))
        on_voxels = self._voxel_shadows.visibility(target[traced])
        surface = (encoding.surface_points(voxels), voxels.normal)

        def received(members, weights, own, before: Emitter | None = None):
            patches = (position[members], normal[members], area[members], weights[:, None])
            lit = (voxels, on_voxels, voxel_row[cluster[members]], own)
            again = None if before is None else kept_received(before.lit, before.received, lit)
            if again is None:
                return encoding.emitter_irradiance_rows(patches, *surface, on_voxels, own, lit[2])[0], lit
            redo, values = again
            if len(redo):
                values[redo] = encoding.emitter_irradiance_rows(patches, surface[0][redo], surface[1][redo],
                                                                on_voxels[:, redo], own, lit[2])[0]
            return values, lit

        for emitter, members, weights in stale:
            emitter.received, emitter.lit = received(members, weights, pieces.of(members), emitter)
        for members in lamps:
            weights, own = radiance[members].max(axis=1), pieces.of(members)
            basis = emitter_basis(self.points, position[members], normal[members], area[members], weights,
                                  visible, row[cluster[members]], own)
            values, lit = received(members, weights, own)
            kept.append(Emitter({keys[e]: float(w) for e, w in zip(members, weights)}, basis, values,
                                radiance[members[0]] / weights[0],
                                None if visible is None else (visible, row[cluster[members]]), lit))
        self.emitters = kept
        return changed

    def _summed_again(self, emitter: Emitter, own: np.ndarray, visible: np.ndarray, patches, pieces) -> np.ndarray:
        """The emitter's basis with the new visibility rows `visible` (its patches reading rows `own`),
        summed again only at the probes whose rows differ from those it was made with."""
        if emitter.shadows is None:
            changed = np.ones(len(self.points), bool)
        else:
            changed = rows_changed(*emitter.shadows, visible, own)
        probes = np.flatnonzero(changed)
        if len(probes) == 0:
            return emitter.basis
        basis = emitter.basis.copy()
        basis[:, probes] = emitter_basis(self.points[probes], *patches, visible[:, probes], own, pieces)
        return basis

    def _lamps(self, patches: np.ndarray, position: np.ndarray, radiance: np.ndarray,
               voxel_size: float) -> list[np.ndarray]:
        """`patches` split into emitters: the same colour (direction in RGB), and cells that touch. Voxels
        larger than the lattice's cells leave gaps between a lamp's patches, so cells touch on a lattice
        coarsened to the voxels' size."""
        if len(patches) == 0:
            return []
        spacing = self._geometry.spacing
        colour = radiance[patches] / radiance[patches].max(axis=1, keepdims=True)
        _, family = np.unique(np.round(colour / SAME_COLOUR).astype(np.int64), axis=0, return_inverse=True)
        reach = max(1, int(np.ceil(voxel_size / spacing.min())))
        cell = np.floor((position[patches] - self.lo) / (reach * spacing)).astype(np.int64)
        out = []
        for f in range(family.max() + 1):
            mine = np.flatnonzero(family.ravel() == f)
            corner = cell[mine].min(axis=0)
            local = cell[mine] - corner
            occupied = np.zeros(local.max(axis=0) + 1, bool)   # the box around them is enough
            occupied[tuple(local.T)] = True
            labels, _ = ndimage.label(occupied, structure=np.ones((3, 3, 3), bool))
            part = labels[tuple(local.T)]
            out += [patches[mine[part == label]] for label in np.unique(part)]
        return out


def _passes(part: np.ndarray | None, redo: np.ndarray, dtype, probes: int) -> np.ndarray:
    """(P, 9, 3) `part`'s light (P, 9, C) in the colour passes `redo` (3,) bool, zero in the others: `part`
    itself where it holds all three (an edit that changes every pass: no copy of 1-3 MB to make)."""
    if part is not None and redo.all() and part.dtype == dtype and part.flags.c_contiguous:
        return part
    out = np.zeros((probes, sh.SH_COUNT, 3), dtype)
    if part is not None:
        out[..., redo] = part
    return out


def emitter_basis(points: np.ndarray, position, normal, area, weights, visible: np.ndarray,
                  ray: np.ndarray, pieces: encoding.Pieces | None = None) -> np.ndarray:
    """(9, P) float32: sum over patches of weight x the SH of their light at the probes (P, 3), for
    radiance 1: `encoding.emitter_sh`'s terms (with the patches' `pieces` near them), each patch seen
    where row `ray[e]` of `visible` (C, P) says so, summed once per emitter instead of per edit."""
    lights = (position, normal, area, np.asarray(weights)[:, None])
    return encoding.emitter_sh_rows(lights, points, visible, pieces, np.asarray(ray, np.int64))[0]

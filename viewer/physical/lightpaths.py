"""Lamps: their light samples, and what each voxel and each probe receives from them per unit radiance.

A lamp is small and bright (viewer.physical.geometry.LAMP_SHARE): its light is integrated over pieces of at most
half a voxel (next-event estimation), with the physical kernel of viewer.physical.transport: a piece s of area
A_s reaches a receiver at distance r with the solid angle cos_s A_s / (r^2 + A_s / pi) (the near-field
clamp keeps it finite), times the receiver's cosine for a surface. Pieces are grouped into patches (one
cell and facing of the voxel grid) that share one visibility ray, cast on the ray layer
(viewer.rays.voxel_rays) against the scene's triangles: exact shadows.

Everything here is linear in the patches' radiance, so a colour or intensity edit is one small matrix
product (viewer.physical.relight); a lamp move builds the LightPaths again, not the Geometry.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass, field

import numba
import numpy as np
from scipy import sparse

from viewer.rays.voxel_rays import VoxelRays
from viewer.physical.geometry import SURFACE_OFFSET, Geometry, lamp_faces
from viewer.probes.sh import add_basis
from viewer.scene import Scene
from viewer.rays.voxels import FACINGS, subdivide

PATCH_VOXELS = 2
"""Edge of a patch (the pieces that share one visibility ray), in voxels. Measured on the eight benchmark
scenes (mean relative RMSE, CPU seconds for the lamp paths): 1 voxel 4.13%, 0.61 s; 2: 4.09%, 0.34 s;
3: 4.11%, 0.36 s; 4: 4.17%, 0.50 s."""
PAIRS_PER_CALL = 1 << 20
"""Visibility rays cast at a time (their origins, directions and lengths take about 60 MB)."""
FAR_FIELD = 6.0
"""Distance, in patch sizes, beyond which a flat patch reaches a receiver as one piece at its centre (the
pieces' directions differ by less than ~1/FAR_FIELD radians there, below what L2 SH resolves)."""
FLAT = 0.999
"""A patch is flat when every piece's normal is this close (cosine) to the patch's mean normal."""


@dataclass(frozen=True)
class LightPaths:
    key: str
    sample_face: np.ndarray
    """(S,) scene face of each light sample."""
    patch_of_sample: sparse.csr_matrix
    """(U, S) area share of each sample in its patch: patch radiance = this @ sample radiance."""
    voxel_irradiance: np.ndarray
    """(K, U) float32 irradiance at each voxel per unit radiance of each patch, visibility included."""
    lamp_of_patch: np.ndarray
    """(U,) the lamp (scene group) of each patch, or a number of its own for a patch that mixes lamps."""
    lamp_voxel_irradiance: np.ndarray
    """(K, G) voxel_irradiance summed over each lamp's patches: while every patch of a lamp has the
    same radiance (a colour or intensity edit changes a whole group), the relight's products need one
    column per lamp instead of one per patch."""
    _probes: dict = field(default_factory=dict, compare=False, repr=False)
    """The probes' matrices, made on first use (the renderer's indirect light never needs them), and
    what they are made from."""

    @property
    def count(self) -> int:
        return self.patch_of_sample.shape[0]

    def columns(self, patch_radiance: np.ndarray, probes: bool = False) -> tuple[np.ndarray, np.ndarray]:
        """(matrix, radiance per column): the voxels' (or with `probes` the probes') matrix per lamp when
        every patch of each lamp has the same radiance, else per patch."""
        lamps = self.lamp_voxel_irradiance.shape[1]
        first = np.zeros(lamps, np.int64)
        first[self.lamp_of_patch[::-1]] = np.arange(self.count)[::-1]
        radiance = patch_radiance[first]
        per_lamp = np.array_equal(patch_radiance, radiance[self.lamp_of_patch])
        if probes:
            return self.probe_matrix(per_lamp), radiance if per_lamp else patch_radiance
        if per_lamp:
            return self.lamp_voxel_irradiance, radiance
        return self.voxel_irradiance, patch_radiance

    def probe_matrix(self, per_lamp: bool = False) -> np.ndarray:
        """(P * 9, U) float32 incident-radiance SH at each probe per unit radiance of each patch, or
        (P * 9, G) summed per lamp."""
        if "patch" not in self._probes:
            points, patches, rays, summed = self._probes["inputs"]
            probe_sh = _probe_sh(points, *patches)
            probe_sh *= _clear_paths(probe_sh[:, 0] > 0, points, patches[-2], rays)[:, None]
            probe_sh = probe_sh.reshape(len(points) * 9, self.count)
            self._probes.update(patch=probe_sh, lamp=probe_sh @ summed)
        return self._probes["lamp" if per_lamp else "patch"]


def lights_key(scene: Scene, geometry: Geometry) -> str:
    """What LightPaths depend on: the geometry, and which faces are lamps and where."""
    digest = hashlib.blake2b(geometry.key.encode(), digest_size=16)
    lamp = lamp_faces(scene)
    digest.update(np.packbits(lamp).tobytes())
    digest.update(np.ascontiguousarray(scene.triangles[lamp]).tobytes())
    return digest.hexdigest()


def build(scene: Scene, geometry: Geometry) -> LightPaths:
    grid = geometry.voxels
    h, n = grid.voxel_size, grid.resolution
    lamp = np.nonzero(lamp_faces(scene))[0]
    k, p = grid.count, len(geometry.probe_points)
    if not len(lamp):
        none = np.zeros((p * 9, 0), np.float32)
        return LightPaths(lights_key(scene, geometry), np.zeros(0, np.int64), sparse.csr_matrix((0, 0)),
                          np.zeros((k, 0), np.float32), np.zeros(0, np.int64), np.zeros((k, 0), np.float32),
                          {"patch": none, "lamp": none})
    position, area, source = subdivide(scene.triangles[lamp], 0.5 * h)
    face = lamp[source]
    normal = scene.face_normals[face]
    size = PATCH_VOXELS * h
    coords = np.clip(np.floor((position - grid.lo) / size).astype(np.int64), 0, n)
    facing = np.argmax(normal @ FACINGS.T, axis=1)
    _, patch = np.unique(((coords[:, 2] * (n + 1) + coords[:, 1]) * (n + 1) + coords[:, 0]) * 6 + facing,
                         return_inverse=True)
    patch = patch.astype(np.int64).ravel()
    u = int(patch.max()) + 1
    select = sparse.csr_matrix((area, (patch, np.arange(len(area)))), shape=(u, len(area)))
    patch_area = np.asarray(select.sum(axis=1)).ravel()
    centre = (select @ position) / patch_area[:, None]
    patch_normal = select @ normal
    patch_normal /= np.maximum(np.linalg.norm(patch_normal, axis=1, keepdims=True), 1e-300)
    target = np.ascontiguousarray(centre + SURFACE_OFFSET * h * patch_normal)
    order = np.argsort(patch, kind="stable")                         # pieces grouped by patch
    first = np.concatenate([[0], np.cumsum(np.bincount(patch, minlength=u))]).astype(np.int64)
    # a curved patch (the pieces of a small sphere: a glTF point light) is summed piece by piece at any
    # distance: its area times the cosine of its mean normal is not its projected area (0.62-0.67 of a
    # point light's I / d^2 straight below it, 1.00 piece by piece)
    bent = np.zeros(u, bool)
    np.logical_or.at(bent, patch, np.einsum("ij,ij->i", normal, patch_normal[patch]) < FLAT)
    far = np.where(bent, np.inf, FAR_FIELD * size)
    patches = (np.ascontiguousarray(centre), np.ascontiguousarray(patch_normal), patch_area, first,
               np.ascontiguousarray(position[order]), np.ascontiguousarray(normal[order]),
               np.ascontiguousarray(area[order]), target, far)
    voxel_irradiance = _surface_irradiance(np.ascontiguousarray(grid.position), np.ascontiguousarray(grid.normal),
                                           *patches)
    starts = grid.position + SURFACE_OFFSET * h * grid.normal           # in front of the voxel's own patch
    voxel_irradiance *= _clear_paths(voxel_irradiance > 0, starts, target, geometry.rays)
    share = sparse.diags(1.0 / patch_area) @ select
    group = scene.face_group[face]
    lowest = np.full(u, np.iinfo(np.int64).max)
    highest = np.full(u, -1)
    np.minimum.at(lowest, patch, group)
    np.maximum.at(highest, patch, group)
    _, lamp_of_patch = np.unique(np.where(lowest == highest, lowest, -1 - np.arange(u)), return_inverse=True)
    lamp_of_patch = lamp_of_patch.ravel()
    summed = np.zeros((u, lamp_of_patch.max() + 1), np.float32)
    summed[np.arange(u), lamp_of_patch] = 1.0
    probes = {"inputs": (np.ascontiguousarray(geometry.probe_points), patches, geometry.rays, summed)}
    return LightPaths(lights_key(scene, geometry), face, share.tocsr(), voxel_irradiance, lamp_of_patch,
                      voxel_irradiance @ summed, probes)


def _clear_paths(lit: np.ndarray, starts: np.ndarray, targets: np.ndarray, rays: VoxelRays) -> np.ndarray:
    """(R, U) bool: where `lit`, whether the segment from starts[i] to targets[j] crosses no surface (the
    lamp's patch j is seen from point i); False elsewhere. One ray per lit pair, cast a block of rows at
    a time."""
    clear = np.zeros(lit.shape, bool)
    rows = max(1, PAIRS_PER_CALL // max(lit.shape[1], 1))
    for start in range(0, len(lit), rows):
        i, j = np.nonzero(lit[start:start + rows])
        clear[start + i, j] = rays.segments_clear(starts[start + i], targets[j])
    return clear


@numba.njit(cache=True, nogil=True, inline="always")
def _solid_angle(p, q, q_normal, q_area):
    """(solid angle of a patch of area q_area at q facing q_normal, seen from p; unit direction p -> q)
    with the near-field clamp: cos_q A / (r^2 + A / pi)."""
    dx, dy, dz = q[0] - p[0], q[1] - p[1], q[2] - p[2]
    r2 = dx * dx + dy * dy + dz * dz
    r = np.sqrt(max(r2, 1e-300))
    dx, dy, dz = dx / r, dy / r, dz / r
    cos_q = -(dx * q_normal[0] + dy * q_normal[1] + dz * q_normal[2])
    if cos_q <= 0:
        return 0.0, dx, dy, dz
    return cos_q * q_area / (r2 + q_area / np.pi), dx, dy, dz


@numba.njit(cache=True, nogil=True, inline="always")
def _is_near(p, c, far):
    dx, dy, dz = c[0] - p[0], c[1] - p[1], c[2] - p[2]
    return dx * dx + dy * dy + dz * dz <= far * far


@numba.njit(cache=True, nogil=True, parallel=True)
def _surface_irradiance(points, normals, centre, patch_normal, patch_area, first, spos, snormal, sarea, target,
                        far):
    """(R, U) float32 irradiance per unit patch radiance at surface points, before visibility: sum over
    the patch's pieces of cos_i cos_s A_s / (r^2 + A_s / pi) (one term for the whole patch beyond
    `far[j]`)."""
    u = centre.shape[0]
    out = np.zeros((points.shape[0], u), np.float32)
    for i in numba.prange(points.shape[0]):
        p, m = points[i], normals[i]
        for j in range(u):
            total = 0.0
            if _is_near(p, centre[j], far[j]):
                for s in range(first[j], first[j + 1]):
                    omega, dx, dy, dz = _solid_angle(p, spos[s], snormal[s], sarea[s])
                    total += omega * max(dx * m[0] + dy * m[1] + dz * m[2], 0.0)
            else:
                omega, dx, dy, dz = _solid_angle(p, centre[j], patch_normal[j], patch_area[j])
                total = omega * max(dx * m[0] + dy * m[1] + dz * m[2], 0.0)
            out[i, j] = total
    return out


@numba.njit(cache=True, nogil=True, parallel=True)
def _probe_sh(points, centre, patch_normal, patch_area, first, spos, snormal, sarea, target, far):
    """(P, 9, U) float32 SH of each patch's light at each probe per unit radiance, before visibility:
    piece by piece for near patches, one direction and solid angle for the whole patch beyond `far[j]`."""
    u = centre.shape[0]
    out = np.zeros((points.shape[0], 9, u), np.float32)
    for i in numba.prange(points.shape[0]):
        p = points[i]
        acc = np.zeros(9)
        for j in range(u):
            acc[:] = 0.0
            if _is_near(p, centre[j], far[j]):
                for s in range(first[j], first[j + 1]):
                    omega, dx, dy, dz = _solid_angle(p, spos[s], snormal[s], sarea[s])
                    if omega > 0:
                        add_basis(dx, dy, dz, acc, omega)
            else:
                omega, dx, dy, dz = _solid_angle(p, centre[j], patch_normal[j], patch_area[j])
                if omega > 0:
                    add_basis(dx, dy, dz, acc, omega)
            if acc[0] > 0:
                for b in range(9):
                    out[i, b, j] = acc[b]
    return out

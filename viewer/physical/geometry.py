"""The geometry stage of the physical GI: everything that depends on where surfaces are and on nothing
that a light or colour edit changes. Traced once per scene, then reused by every relight
(viewer.physical.relight), the way precomputed real-time radiosity engines split their work (Enlighten:
ray-traced form factors in a precompute, a linear solve at run time with albedo and emission as inputs).

- `Geometry`: the voxels; from every voxel a fixed set of cosine-weighted gather rays to the voxel each
  one hits, aggregated into a sparse transport matrix (row = receiver); from every probe a fixed set of
  directions to the voxel each one hits (the probe projection); which probes lie inside solids.
- `viewer.physical.lightpaths.LightPaths`: what every voxel and probe receives from the small emitters (lamps)
  per unit radiance, visibility included: one per lamp position.
- `SunPaths`: which voxels and probes see the sun: one per sun direction.

Every ray is cast against the scene's triangles and lands on the voxel that carries the surface it meets
(viewer.rays.voxel_rays: Embree where it is installed, else the cell-exact DDA of viewer.rays.dda), so
the hemisphere of every receiver is counted exactly: a gather ray hits a surface or leaves the scene,
and the rows of the transport matrix sum to the share of rays that hit (1 in a closed room).
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass, replace

import numpy as np
from scipy import sparse

from viewer.rays import dda
from viewer.probes import sh
from viewer.probes.grid import ProbeGrid, fill_waves
from viewer.scene import DirectionalLight, Scene
from viewer.rays.sun import voxel_sun_cover
from viewer.rays.voxel_rays import VoxelRays
from viewer.rays.voxels import SURFACE_OFFSET, VoxelGrid, Voxelization, voxelize_with_faces  # noqa: F401
LAMP_SHARE = 0.1
"""Emitters whose total area is at most this share of the scene's are lamps: small and bright, their
light is integrated over fine light samples with visibility (next-event estimation). Larger emitters (a
glowing wall, the white furnace) are found by the gather rays like any other surface."""


@dataclass(frozen=True)
class GeometrySettings:
    voxels: int = 32
    """N: voxels per axis."""
    probes: int = 24
    """M: probes per axis over the scene bounds."""
    gather_rays: int = 64
    """Cosine-weighted rays per voxel (the transport matrix has at most this many entries a row)."""
    directions: int = 256
    """Directions per probe (a spherical Fibonacci lattice, the same for every probe)."""
    normal_mode: str = "area"
    """Voxel normals: `area` (area-weighted) or `paper` (eq. 3)."""
    invalid_backface_fraction: float = 0.25
    """A probe that sees the back of surfaces in more than this share of its directions is inside a
    solid: invalid, and filled from valid neighbours (viewer.probes.grid.fill_invalid)."""


def lamp_faces(scene: Scene) -> np.ndarray:
    """(F,) bool: the faces whose light comes through light samples (see LAMP_SHARE)."""
    emitting = scene.emitting
    areas = scene.face_areas
    if areas[emitting].sum() > LAMP_SHARE * areas.sum():
        return np.zeros(len(emitting), bool)
    return emitting


def scene_key(scene: Scene, settings: GeometrySettings) -> str:
    """What a Geometry depends on: the triangles, the bounds and the settings (not colours or lights)."""
    digest = hashlib.blake2b(digest_size=16)
    digest.update(scene.geometry_digest)   # kept across colour edits (Scene._recoloured)
    if scene.textured:   # the voxels' texture shares (Geometry.tint) depend on the coordinates and images
        digest.update(np.ascontiguousarray(scene.uv).tobytes())
        for texture in scene.textures:
            digest.update(repr(None if texture is None else (texture.pixels.shape, texture.mean.tobytes(),
                                                             texture.wrap)).encode())
    digest.update(repr(settings).encode())
    return digest.hexdigest()


def cosine_directions(count: int) -> np.ndarray:
    """(count, 3) directions over the hemisphere around +z, cosine-weighted and stratified: the centres
    of a grid of equal-probability cells in (u1, u2), mapped by r = sqrt(u1), phi = 2 pi u2 (Malley's
    method). Each carries pi / count of the irradiance integral."""
    rows = max(1, int(round(np.sqrt(count / 2.0))))
    cols = -(-count // rows)
    u1 = (np.repeat(np.arange(rows), cols) + 0.5) / rows
    u2 = (np.tile(np.arange(cols), rows) + 0.5 + 0.5 * (np.repeat(np.arange(rows), cols) % 2)) / cols
    u1, u2 = u1[:count], u2[:count]
    r, phi = np.sqrt(u1), 2.0 * np.pi * u2
    return np.stack([r * np.cos(phi), r * np.sin(phi), np.sqrt(np.maximum(1.0 - u1, 0.0))], axis=1)


def tangent_frames(normals: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Unit tangents and bitangents (N, 3) completing unit normals (N, 3) to right-handed frames."""
    n = np.asarray(normals, np.float64)
    helper = np.where(np.abs(n[:, :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
    t = np.cross(helper, n)
    t /= np.linalg.norm(t, axis=1, keepdims=True)
    return t, np.cross(n, t)


def gather_directions(normals: np.ndarray, count: int, index: np.ndarray | None = None) -> np.ndarray:
    """(K, count, 3) world directions of each voxel's gather rays: `cosine_directions` around its
    normal, turned about it by an angle fixed per voxel (its index times the golden angle), so that
    neighbouring voxels do not share the pattern's gaps, and the same every time (nothing flickers).
    `index`: the voxels' indices when `normals` are some of a grid's (by default 0..K-1)."""
    n = np.asarray(normals, np.float64)
    t, b = tangent_frames(n)
    angle = (np.arange(len(n)) if index is None else np.asarray(index)) * (np.pi * (3.0 - np.sqrt(5.0)))
    c, s = np.cos(angle)[:, None], np.sin(angle)[:, None]
    t, b = c * t + s * b, c * b - s * t
    local = cosine_directions(count)
    return (local[None, :, :1] * t[:, None] + local[None, :, 1:2] * b[:, None]
            + local[None, :, 2:] * n[:, None])


@dataclass(frozen=True)
class Geometry:
    key: str
    settings: GeometrySettings
    voxels: VoxelGrid
    cells: dda.Cells
    """Each cell's triangles, and the voxel each one's surface belongs to there."""
    rays: VoxelRays
    """The triangles and `cells`, ready for rays that land on voxels."""
    faces: sparse.csr_matrix
    """(K, F) share of each voxel's area per scene face (colours per voxel from colours per face)."""
    lamp: np.ndarray
    """(F,) bool: faces whose emission is a lamp's (light samples), not gathered."""
    transport: sparse.csr_matrix
    """(K, K) float32: the share of voxel i's gather rays that hit voxel j from the front. Irradiance
    E_i = pi sum_j transport_ij L_j for outgoing radiance L (cosine-weighted rays)."""
    probe_lo: np.ndarray
    probe_hi: np.ndarray
    probe_points: np.ndarray
    """(P, 3) probe centres, P = M^3 in [x, y, z] order."""
    probe_hits: np.ndarray
    """(P, D) int32 voxel seen by each probe direction; K where the ray sees nothing or a back face."""
    probe_basis: np.ndarray
    """(D, 9) float32: quadrature weight x SH basis of each probe direction (SH = basis^T L[hits])."""
    probe_basis_t: np.ndarray
    """(9, D) float32: the same, transposed (the CPU projection's layout)."""
    valid: np.ndarray
    """(M, M, M) bool: probes not inside solids."""
    fill_waves: np.ndarray
    """(M^3,) int32 the wave of viewer.probes.grid.fill_invalid in which each invalid probe gets its value
    (0: valid; -1 everywhere: no valid probe)."""
    probe_backface: np.ndarray
    """(P, D) bool: the probe direction sees the back of a surface (what `valid` counts)."""
    voxel_keys: np.ndarray
    """(K,) int64 each voxel's key, cell x 6 + facing (viewer.rays.voxels.Voxelization.keys)."""
    gather_hits: np.ndarray
    """(K, gather_rays) int32 the voxel each gather ray hits, dda.MISS or dda.BACKFACE (the transport
    matrix's entries before they are summed: what viewer.physical.retrace keeps when faces move)."""
    tint: tuple | None = None
    """What textured faces add to the voxel albedo (viewer.rays.voxels.Voxelization.tint, `voxel_albedo`)."""

    @property
    def probe_resolution(self) -> int:
        return self.valid.shape[0]


def build(scene: Scene, settings: GeometrySettings = GeometrySettings(), backend: str | None = None) -> Geometry:
    """Voxelize and trace: see the module docstring. `backend`: the rays' (VoxelRays), None for the
    fastest installed."""
    voxelization = voxelize_with_faces(scene, settings.voxels, settings.normal_mode)
    return trace(scene, voxelization, settings, backend)


def trace(scene: Scene, voxelization: Voxelization, settings: GeometrySettings,
          backend: str | None = None) -> Geometry:
    grid, faces = voxelization.grid, voxelization.faces
    cells = dda.Cells.of(voxelization, scene)
    rays = VoxelRays(scene, cells, backend)
    k, h = grid.count, grid.voxel_size
    # voxel -> voxel: cosine-weighted gather rays, one matrix entry per (receiver, voxel hit)
    origins = grid.position + SURFACE_OFFSET * h * grid.normal
    hits = rays.bundle_hits(origins, gather_directions(grid.normal, settings.gather_rays))
    lo, hi = scene.bounds
    probe_part = _probe_rays(rays, k, np.asarray(lo, np.float64), np.asarray(hi, np.float64), settings)
    return Geometry(scene_key(scene, settings), settings, grid, cells, rays, faces, lamp_faces(scene),
                    transport_matrix(hits), *probe_part, voxel_keys=np.asarray(voxelization.keys, np.int64),
                    gather_hits=hits, tint=voxelization.tint)


def transport_matrix(hits: np.ndarray) -> sparse.csr_matrix:
    """(K, K) the transport matrix of the gather rays' hits (K, R): each ray that hits a voxel from the
    front carries 1 / R of its receiver's hemisphere."""
    k, rays = hits.shape
    flat = hits.reshape(-1).astype(np.int64)
    seen = flat >= 0
    receiver = np.repeat(np.arange(k), rays)
    transport = sparse.csr_matrix((np.full(int(seen.sum()), 1.0 / rays, np.float32),
                                   (receiver[seen], flat[seen])), shape=(k, k))
    transport.sum_duplicates()
    return transport


def with_probes(geometry: Geometry, probes: int) -> Geometry:
    """The same geometry with another probe grid over the same box: only the probe rays are traced
    again (the training targets at two probe resolutions share the voxels' transport)."""
    settings = replace(geometry.settings, probes=probes)
    key = hashlib.blake2b((geometry.key + repr(settings)).encode(), digest_size=16).hexdigest()
    _, _, *fields = _probe_rays(geometry.rays, geometry.voxels.count, geometry.probe_lo, geometry.probe_hi,
                                settings)
    return replace(geometry, key=key, settings=settings, **dict(zip(_PROBE_FIELDS, fields)))


_PROBE_FIELDS = ("probe_points", "probe_hits", "probe_basis", "probe_basis_t", "valid", "fill_waves",
                 "probe_backface")


def _probe_rays(rays: VoxelRays, k: int, lo: np.ndarray, hi: np.ndarray, settings: GeometrySettings) -> tuple:
    """probe -> voxel: the same directions from every probe. Returns (lo, hi, then the _PROBE_FIELDS)."""
    m = settings.probes
    points = ProbeGrid.positions_for(lo, hi, m).reshape(-1, 3)
    directions, weights = sh.sphere_directions(settings.directions)
    basis = (weights[:, None] * sh.basis(directions)).astype(np.float32)
    hits, valid, waves, backface = probe_fields(rays.bundle_hits(points, directions), k, m,
                                                settings.invalid_backface_fraction)
    return lo, hi, points, hits, basis, np.ascontiguousarray(basis.T), valid, waves, backface


def probe_fields(raw_hits: np.ndarray, k: int, m: int, invalid_backface_fraction: float) -> tuple:
    """From the probe rays' hits (P, D) as traced (MISS, BACKFACE or a voxel): (hits with K for no voxel,
    valid (M, M, M), fill waves (M^3,), backface (P, D))."""
    backface = raw_hits == dda.BACKFACE
    hits = np.where(raw_hits < 0, k, raw_hits).astype(np.int32)
    valid = (backface.mean(axis=1) <= invalid_backface_fraction).reshape(m, m, m)
    return hits, valid, fill_waves(valid).reshape(-1), backface


# ---- the sun ------------------------------------------------------------------------------------------------

@dataclass(frozen=True)
class SunPaths:
    direction: np.ndarray | None
    """Unit vector towards the sun, or None (no sun)."""
    voxel_cosine: np.ndarray
    """(K,) float32 cos(normal, sun) times the share of the voxel's surface that sees the sun
    (`viewer.rays.sun`)."""
    probe_visible: np.ndarray
    """(P,) bool: the probe sees the sun."""


def sun_paths(geometry: Geometry, sun: DirectionalLight | None) -> SunPaths:
    grid = geometry.voxels
    if sun is None:
        return SunPaths(None, np.zeros(grid.count, np.float32), np.zeros(len(geometry.probe_points), bool))
    cosine = np.maximum(grid.normal @ sun.direction, 0.0) * voxel_sun_cover(geometry.rays, grid, sun.direction)
    return SunPaths(np.array(sun.direction), cosine.astype(np.float32),
                    geometry.rays.escapes(geometry.probe_points, sun.direction))

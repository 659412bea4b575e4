"""What an `Encoder` (viewer/neural/encoder.py) keeps between edits on one probe lattice: the splat and
the features that the voxels' geometry alone fixes, and the shadow rays that the occluders alone fix.
"""

from __future__ import annotations

import numpy as np
from scipy import sparse

from viewer.neural import encoding
from viewer.neural.encoding import CHANNELS
from viewer.rays.voxel_rays import VoxelRays
from viewer.rays.voxels import VoxelGrid


class LatticeGeometry:
    """What the encoding takes from the voxels' geometry alone (positions, normals, areas) on one lattice."""

    def __init__(self, voxels: VoxelGrid, lo: np.ndarray, hi: np.ndarray, points: np.ndarray):
        self.position, self.normal, self.area = voxels.position, voxels.normal, voxels.area
        m = round(len(points) ** (1 / 3))
        spacing = (hi - lo) / m
        face_area = np.array([spacing[1] * spacing[2], spacing[0] * spacing[2], spacing[0] * spacing[1]])
        self.cell_area = float(np.mean(face_area))
        cells = m ** 3
        # the same splat as `encode`, its eight corners as the eight entries of each voxel's column (eight
        # distinct cells): the same numbers to round-off
        corners = encoding.splat(voxels.position, lo, spacing, m)
        rows = np.stack([index for index, _ in corners], axis=1).ravel()
        weights = np.stack([weight for _, weight in corners], axis=1).ravel()
        self.splat = sparse.csc_matrix((weights, rows, np.arange(0, len(rows) + 1, len(corners))),
                                       shape=(cells, voxels.count))
        cell = np.clip(np.floor((voxels.position - lo) / spacing).astype(np.int64), 0, m - 1)
        self.cell = (cell[:, 0] * m + cell[:, 1]) * m + cell[:, 2]
        self.density = self.splat @ voxels.area
        self.safe = np.where(self.density > 0, self.density, 1.0)
        normals = self.splat @ (voxels.area[:, None] * voxels.normal)
        self.features = np.empty((CHANNELS, cells), np.float32)
        """The features that geometry alone fixes; the albedo, emission and direct rows are filled per
        encoding."""
        self.features[0] = self.density / self.cell_area
        self.features[1:4] = normals.T / self.cell_area
        self.features[15:18] = ((points - lo) / (hi - lo) * 2.0 - 1.0).T
        extent = hi - lo
        self.features[18:21] = (extent / extent.max())[:, None]
        self.spacing = spacing

    def fits(self, voxels: VoxelGrid) -> bool:
        return all(a is b or np.array_equal(a, b) for a, b in (
            (self.position, voxels.position), (self.normal, voxels.normal), (self.area, voxels.area)))

    def gather(self, values: np.ndarray) -> np.ndarray:
        """Area-weighted per-voxel values (K, C) splatted onto the lattice cells: (cells, C)."""
        return self.splat @ (self.area[:, None] * values)


class LatticeShadows:
    """What the encoding's shadows take from the occluders (`encoding.occluders`; None: nothing casts a
    shadow) on one lattice: the visibility rays of emitting patches, and the sun's visibility for the
    last direction asked."""

    def __init__(self, blockers: VoxelRays | None, points: np.ndarray, lo: np.ndarray, spacing: np.ndarray):
        self.blockers, self.points, self.lo, self.spacing = blockers, points, lo, spacing
        self._sun: tuple[bytes, np.ndarray] | None = None

    def fits(self, blockers: VoxelRays | None) -> bool:
        """Whether `blockers` are these occluders: the same object, or equal arrays (a new listing of the
        same triangles)."""
        a, b = self.blockers, blockers
        if a is b:
            return True
        if a is None or b is None:
            return False
        return all(np.array_equal(x, y) for x, y in zip(a.cells.args(), b.cells.args()))

    def targets(self, position: np.ndarray, normal: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """`encoding.shadow_targets` of the emitting patches: (C, 3) where each cluster's ray ends, (E,)
        each patch's cluster (one cluster at the origin when nothing casts a shadow)."""
        if self.blockers is None:
            return np.zeros((min(len(position), 1), 3)), np.zeros(len(position), np.int64)
        return encoding.shadow_targets(self.blockers, position, normal, self.lo, self.spacing)

    def visibility(self, target: np.ndarray) -> np.ndarray:
        """(C, P) float32: 1 where probe p sees the end of ray c, as `encoding.patch_visibility` traces
        it (the same `VoxelRays.pairs_clear`, each pair on its own: any subset of the clusters gives their
        columns of the whole)."""
        if self.blockers is None:
            return np.ones((len(target), len(self.points)), np.float32)
        return np.ascontiguousarray(self.blockers.pairs_clear(self.points, target).T)

    def sun_visibility(self, direction: np.ndarray) -> np.ndarray:
        """(P,) `encoding.sun_visibility` against these occluders, kept for the last direction asked."""
        key = direction.tobytes()
        if self._sun is None or self._sun[0] != key:
            self._sun = (key, encoding.sun_visibility(self.blockers, self.points, direction))
        return self._sun[1]

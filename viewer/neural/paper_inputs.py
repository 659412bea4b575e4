"""The paper's network input, in numpy only: what the Table 1 families read, shared by training (torch)
and by the benchmark, which runs the exported families through onnxruntime without torch.

A scene becomes its voxel list (eq. 2 and 4: cell centre, albedo, emission, hash id; one row per occupied
cell of a 16^3 grid, in hash-id order), which the "adjustable pooling layer" resamples to a fixed length.
"""

from __future__ import annotations

import numpy as np

from viewer.rays.voxels import VoxelGrid

VOXEL_FEATURES = 10
"""centre (3), albedo (3), emission (3), hash id (1)."""
PAPER_VOXELS = 16
PAPER_PROBES = 8


def voxel_list(voxels: VoxelGrid) -> np.ndarray:
    """(K, 10) the paper's attributes per occupied cell, hash-id order, in raw units."""
    cells = voxels.cells()
    n = voxels.resolution
    centre = (cells["center"] - voxels.lo) / (voxels.voxel_size * n)  # [0, 1]
    return np.concatenate([centre, cells["albedo"], cells["emission"],
                           (cells["hash_id"] / float(n ** 3))[:, None]], axis=1).astype(np.float32)


def adaptive_pool(rows: np.ndarray, length: int) -> np.ndarray:
    """(K, F) rows -> (F, length): the mean of rows [floor(i K / length), ceil((i + 1) K / length)) for
    output i, as torch's AdaptiveAvgPool1d pools (K may be shorter than length: windows then repeat)."""
    k = len(rows)
    if k == 0:
        raise ValueError("an empty voxel list (the scene has no surfaces)")
    i = np.arange(length)
    start, end = (i * k) // length, -((-(i + 1) * k) // length)
    total = np.concatenate([np.zeros((1, rows.shape[1])), np.cumsum(rows, axis=0, dtype=np.float64)])
    return ((total[end] - total[start]) / (end - start)[:, None]).T.astype(np.float32)

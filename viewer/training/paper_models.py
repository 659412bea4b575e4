"""The paper's five network families, as its section on the networks describes them, for Table 1.

Input: the paper's voxel list (eq. 2 and 4: cell centre, albedo, emission, hash id; one row per occupied
cell of a 16^3 grid, in hash-id order), every attribute standardized to [-1, 1] by the training set's
range. Scenes have different voxel counts, so an adaptive average pooling layer (the paper's "adjustable
pooling layer") resamples the list to a fixed length before the network. Output: all probes of an 8^3
grid at once, 27 coefficients each, standardized per coefficient (z-scores over the training set).
Activations tanh; loss MSE + lambda ||W||^2.

- MLP: the pooled list flattened, three hidden layers.
- ResNet-10: ten linear layers: one in, four residual blocks of two, one out.
- RNN: a two-layer Elman RNN reads the pooled list; its last state predicts the probes.
- CNN: 1D convolutions along the list, pooled, then one linear layer.
- CNN-MLP: the same convolutions followed by an MLP.

These map a whole scene to a whole probe grid through a dense layer, so they cannot share what they
learn between probes or between places in the list; the production network (`models.ProbeNet`) is
built the other way round. Table 1 measures the difference.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np
import torch
from torch import nn

from viewer.voxels import VoxelGrid

FAMILIES = ("mlp", "resnet10", "rnn", "cnn", "cnn-mlp")
VOXEL_FEATURES = 10
"""centre (3), albedo (3), emission (3), hash id (1)."""
PAPER_VOXELS = 16
PAPER_PROBES = 8


@dataclass(frozen=True)
class PaperConfig:
    family: str = "mlp"
    pooled: int = 128
    """Length of the voxel list after the adjustable pooling layer."""
    hidden: int = 256
    """Width of the hidden layers (RNN state: half of it)."""
    outputs: int = PAPER_PROBES ** 3 * 27

    def to_dict(self) -> dict:
        return asdict(self)


def voxel_list(voxels: VoxelGrid) -> np.ndarray:
    """(K, 10) the paper's attributes per occupied cell, hash-id order, in raw units (see `standardize`)."""
    cells = voxels.cells()
    n = voxels.resolution
    centre = (cells["center"] - voxels.lo) / (voxels.voxel_size * n)  # [0, 1]
    return np.concatenate([centre, cells["albedo"], cells["emission"],
                           (cells["hash_id"] / float(n ** 3))[:, None]], axis=1).astype(np.float32)


class Standardizer:
    """Min-max to [-1, 1] per input attribute; z-score per output coefficient; both from training data."""

    def __init__(self, lists: list[np.ndarray], targets: np.ndarray):
        rows = np.concatenate(lists)
        self.lo, self.hi = rows.min(axis=0), rows.max(axis=0)
        self.mean, self.std = targets.mean(axis=0), targets.std(axis=0) + 1e-6

    def inputs(self, voxel_rows: np.ndarray) -> np.ndarray:
        span = np.where(self.hi > self.lo, self.hi - self.lo, 1.0)
        return np.clip((voxel_rows - self.lo) / span * 2 - 1, -1, 1).astype(np.float32)

    def targets(self, values: np.ndarray) -> np.ndarray:
        return ((values - self.mean) / self.std).astype(np.float32)

    def physical(self, standardized: np.ndarray) -> np.ndarray:
        return standardized * self.std + self.mean


class PaperNet(nn.Module):
    def __init__(self, config: PaperConfig):
        super().__init__()
        if config.family not in FAMILIES:
            raise ValueError(f"family must be one of {FAMILIES}")
        self.config = config
        self.pool = nn.AdaptiveAvgPool1d(config.pooled)  # the adjustable pooling layer
        h, k, out = config.hidden, config.pooled, config.outputs
        flat = VOXEL_FEATURES * k
        if config.family == "mlp":
            self.body = nn.Sequential(nn.Flatten(), nn.Linear(flat, h), nn.Tanh(), nn.Linear(h, h), nn.Tanh(),
                                      nn.Linear(h, h), nn.Tanh(), nn.Linear(h, out))
        elif config.family == "resnet10":
            self.body = nn.Sequential(nn.Flatten(), nn.Linear(flat, h), nn.Tanh(),
                                      *[Residual(h) for _ in range(4)], nn.Linear(h, out))
        elif config.family == "rnn":
            self.rnn = nn.RNN(VOXEL_FEATURES, h // 2, num_layers=2, nonlinearity="tanh", batch_first=True)
            self.body = nn.Linear(h // 2, out)
        else:
            self.conv = nn.Sequential(
                nn.Conv1d(VOXEL_FEATURES, 32, 5, padding=2), nn.Tanh(), nn.AvgPool1d(2),
                nn.Conv1d(32, 64, 5, padding=2), nn.Tanh(), nn.AvgPool1d(2),
                nn.Conv1d(64, 64, 5, padding=2), nn.Tanh(), nn.AdaptiveAvgPool1d(8), nn.Flatten())
            if config.family == "cnn":
                self.body = nn.Linear(64 * 8, out)
            else:
                self.body = nn.Sequential(nn.Linear(64 * 8, h), nn.Tanh(), nn.Linear(h, h), nn.Tanh(),
                                          nn.Linear(h, out))

    def forward(self, voxel_rows: torch.Tensor) -> torch.Tensor:
        """(B, K_scene, 10) standardized voxel lists (one scene per call when K differs) -> (B, outputs)."""
        return self.head(self.pool(voxel_rows.transpose(1, 2)))

    def head(self, pooled: torch.Tensor) -> torch.Tensor:
        """(B, 10, pooled) -> (B, outputs): the network after the (parameter-free) pooling layer, so that
        training can pool each scene once and batch scenes of different voxel counts."""
        family = self.config.family
        if family == "rnn":
            _, state = self.rnn(pooled.transpose(1, 2))
            return self.body(state[-1])
        if family in ("cnn", "cnn-mlp"):
            return self.body(self.conv(pooled))
        return self.body(pooled)


class Residual(nn.Module):
    def __init__(self, width: int):
        super().__init__()
        self.layers = nn.Sequential(nn.Linear(width, width), nn.Tanh(), nn.Linear(width, width))

    def forward(self, x):
        return torch.tanh(x + self.layers(x))

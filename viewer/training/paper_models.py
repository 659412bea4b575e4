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

import torch
from torch import nn

from viewer.neural.paper_inputs import PAPER_PROBES, VOXEL_FEATURES

FAMILIES = ("mlp", "resnet10", "rnn", "cnn", "cnn-mlp")


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

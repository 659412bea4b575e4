"""Batches of rooms for training ProbeNet: tensors, mirror images, the targets and the probes' weights.

Apart from the training loop (viewer/training/train.py): the Table 1 families (viewer/training/table1.py)
read the same batches, and the mirror images must match the encoding's channels (viewer/neural/encoding.py).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
import torch

from viewer.neural import encoding
from viewer.training.models import REFLECTED, TOTAL
from viewer.training.samples import Samples

ODD_IN = {0: [3, 4, 7], 2: [2, 5, 7]}
"""SH coefficients that change sign when the x axis (or the z axis) is mirrored (docs/ARCHITECTURE.md order:
00, 1-1 (y), 10 (z), 11 (x), 2-2 (xy), 2-1 (yz), 20, 21 (xz), 22 (x^2 - y^2))."""
NORMAL_CHANNEL = {0: 1, 2: 3}
COORD_CHANNEL = {0: 15, 2: 17}


def mirror(inputs: torch.Tensor, targets: torch.Tensor, valid: torch.Tensor, axis: int):
    """The mirror image in world axis `axis` (0 = x, 2 = z) of a batch (B, C, X, Y, Z)."""
    dim = 2 + axis
    inputs, targets, valid = inputs.flip(dim), targets.flip(dim), valid.flip(dim - 1)
    sign_in = torch.ones(encoding.CHANNELS)
    sign_in[NORMAL_CHANNEL[axis]] = -1
    sign_in[COORD_CHANNEL[axis]] = -1
    sign_in[encoding.DIRECT] = sh_signs(axis)
    sign_in[encoding.BOUNCE] = sh_signs(axis)
    sign_in[encoding.SEEN] = sh_signs(axis)
    sign_out = torch.cat([sh_signs(axis), sh_signs(axis)])
    return inputs * sign_in[:, None, None, None], targets * sign_out[:, None, None, None], valid


@dataclass
class Batch:
    pick: np.ndarray
    """The rooms, in the samples' order."""
    x: torch.Tensor
    """(B, CHANNELS, M, M, M) B = 3 x rooms: one colour channel a row."""
    y: torch.Tensor
    """(B, 18, M, M, M) the truth: all the light (9), the reflected light (9)."""
    valid: torch.Tensor
    """(B, M, M, M) 1.0 outside solids."""
    unbiased: torch.Tensor
    """(B, 9, M, M, M) Mitsuba's reflected light where `has_unbiased`, else zeros."""
    has_unbiased: torch.Tensor
    """(B,) 1.0 for the rows of rooms with Mitsuba's probes."""
    links: torch.Tensor | None = None
    """(rooms, 3, M, M, M) bool: where each room's seen filter stops (`encoding.Encoding.links`)."""

    def mirrored(self, axis: int) -> "Batch":
        x, y, valid = mirror(self.x, self.y, self.valid, axis)
        unbiased = mirror_sh(self.unbiased, axis)
        return Batch(self.pick, x, y, valid, unbiased, self.has_unbiased,
                     None if self.links is None else mirror_links(self.links, axis))

    def but(self, **changes) -> "Batch":
        """The same batch with some of its fields replaced."""
        return replace(self, **changes)


def mirror_links(links: torch.Tensor, axis: int) -> torch.Tensor:
    """(rooms, 3, X, Y, Z) links mirrored in world axis `axis`: the links along the other axes flip with
    their probes; those along `axis` join probes i and i + 1, which the mirror makes M - 2 - i and M - 1 - i
    (the last layer's links stay True: `seen_links.lattice_links`)."""
    dim = 2 + axis
    out = links.flip(dim)
    along = links[:, axis].narrow(axis + 1, 0, links.shape[dim] - 1).flip(axis + 1)
    out[:, axis] = True
    out[:, axis].narrow(axis + 1, 0, links.shape[dim] - 1).copy_(along)
    return out


def sh_signs(axis: int) -> torch.Tensor:
    """(9,) how each SH coefficient changes when world axis `axis` is mirrored."""
    sign = torch.ones(9)
    sign[ODD_IN[axis]] = -1
    return sign


def mirror_sh(sh: torch.Tensor, axis: int) -> torch.Tensor:
    """(B, 9, X, Y, Z) SH mirrored in world axis `axis`."""
    return sh.flip(2 + axis) * sh_signs(axis)[:, None, None, None]


def batches(samples: Samples, indices: np.ndarray, size: int):
    for start in range(0, len(indices), size):
        pick = np.sort(indices[start:start + size])
        m = samples.inputs.shape[-1]
        x = torch.from_numpy(samples.inputs[pick].astype(np.float32)).reshape(-1, encoding.CHANNELS, m, m, m)
        y = torch.from_numpy(samples.targets[pick].astype(np.float32)).reshape(-1, 18, m, m, m)
        v = torch.from_numpy(np.repeat(samples.valid[pick], 3, axis=0).astype(np.float32))
        if samples.unbiased is not None:
            u = torch.from_numpy(samples.unbiased[pick].astype(np.float32)).reshape(-1, 9, m, m, m)
            has = torch.from_numpy(np.repeat(samples.has_unbiased[pick], 3).astype(np.float32))
        else:
            u, has = torch.zeros_like(y[:, 9:]), torch.zeros(len(y))
        links = None if samples.links is None else torch.from_numpy(np.asarray(samples.links[pick], bool))
        yield Batch(pick, x, y, v, u, has, links)


def traced_direct(batch: Batch) -> Batch:
    """The batch with the truth's direct light in place of the encoding's."""
    x = batch.x.clone()
    x[:, encoding.DIRECT] = batch.y[:, TOTAL] - batch.y[:, REFLECTED]
    return batch.but(x=x)


def reflected_target(batch: Batch) -> torch.Tensor:
    """Mitsuba's reflected light where the room has it, else the truth's."""
    has = batch.has_unbiased[:, None, None, None, None]
    return has * batch.unbiased + (1 - has) * batch.y[:, REFLECTED]


def probe_weights(batch: Batch) -> torch.Tensor:
    """(B, 1, M, M, M) each probe's weight in the SH loss: 1 / (|all the light's DC| + the row's mean |DC|).

    The light next to a lamp is hundreds of times the room's mean (up to ~300x in the v2 rooms, in the
    encoding's units), so a plain squared error is the error of a few probes at the lamps: the network
    fits them and never learns the reflected light of the rest of the room. Dividing by the local
    magnitude (with the room's mean as a floor) makes the loss a relative error near the lamps and an
    absolute one in the dim corners."""
    dc = batch.y[:, 0:1].abs()
    return 1.0 / (dc + dc.mean(dim=(2, 3, 4), keepdim=True).clamp_min(1e-6))

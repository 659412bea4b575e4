"""How far a scene lies from the neural model's training set, two ways (the out-of-distribution study's
x axis).

- `outside(values, bounds)`: per drawn parameter, how far it lies outside the range that the shipped
  model was trained on (its card's domain names the ranges), in units of that range's width (0 inside). Exact,
  but only for numbers: a shape or a light placement the generator never makes has no range to be
  outside of, and a colour 0.99 is only 0.1 widths past 0.9 whatever it does to the light.
- `EncodingDistance`: one number for any scene, comparable across axes. The network sees a scene only
  through its input encoding (`viewer.neural.encoding`, one monochrome pass per colour channel), so the
  distance is taken there, in a view of each pass: `statistics` (what the scene is made of: a few
  statistics per feature over the lattice) or `layout` (where: the features averaged over 4^3 blocks
  of the lattice). Standardized by the training set's spread, the scene's distance in a view is that
  of its farthest pass to the nearest training pass, divided by the typical nearest-neighbour distance
  within the training set (the median, each training scene against the others). About 1 is as close
  as one training scene is to the next; 3 is three times farther. Statistics see colours, light sizes
  and proportions but not where things are; the layout sees a lamp on the floor or an object under
  the ceiling but hardly a darker wall: the study reports both and their maximum.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from viewer.neural import encoding
from viewer.scene import Scene

ROOT = Path(__file__).resolve().parents[3]
DATA = ROOT / "data" / "gi-v1"
"""The first dataset: the default reference set (the out-of-distribution study reads the shipped model's
from its card)."""
PERCENTILE = 99.0
OCCUPIED = 0.05
"""Surface density (area / cell face) above which a lattice cell counts as holding a surface for the
albedo statistics."""


def outside(values, bounds) -> float:
    """Largest distance of `values` outside [lo, hi], in units of hi - lo (0 when all lie inside)."""
    lo, hi = bounds
    values = np.asarray(values, np.float64).ravel()
    if values.size == 0:
        return 0.0
    return float(np.max(np.maximum(np.maximum(lo - values, values - hi), 0.0)) / (hi - lo))


def statistics(inputs: np.ndarray) -> np.ndarray:
    """(3, K) statistics of each colour pass of an encoding (3, CHANNELS, M, M, M): mean, spread and the
    99th percentile of |value| of every feature but the lattice coordinates (the same in every scene),
    and the 5th, 50th and 95th percentiles of the albedo where there is a surface; arcsinh-compressed,
    so that one very bright emitter cell does not outweigh everything else."""
    names = encoding.FEATURES
    keep = [i for i, n in enumerate(names) if not n.startswith("coord_")]
    cells = np.asarray(inputs, np.float32).reshape(3, len(names), -1)
    values = cells[:, keep]
    stats = [values.mean(axis=2), values.std(axis=2), np.percentile(np.abs(values), PERCENTILE, axis=2)]
    density, albedo = cells[:, names.index("density")], cells[:, names.index("albedo")]
    surface = [np.percentile(a[d > OCCUPIED], (5, 50, 95)) if np.any(d > OCCUPIED) else np.zeros(3)
               for a, d in zip(albedo, density)]
    return np.arcsinh(np.concatenate(stats + [np.array(surface)], axis=1))


LAYOUT_BLOCK = 4


def layout(inputs: np.ndarray) -> np.ndarray:
    """(3, K) the geometry, emission and direct-light features averaged over blocks of 4^3 lattice
    cells (arcsinh-compressed): where surfaces, lamps and light are, at a quarter of the resolution."""
    cells = np.asarray(inputs, np.float32)[:, :encoding.DIRECT.stop]
    m, b = cells.shape[-1], LAYOUT_BLOCK
    blocks = cells.reshape(*cells.shape[:2], m // b, b, m // b, b, m // b, b).mean(axis=(3, 5, 7))
    return np.arcsinh(blocks.reshape(3, -1))


VIEWS = {"statistics": statistics, "layout": layout}


def scene_encoding(scene: Scene, voxels: int, resolution: int) -> np.ndarray:
    """The network's input for a scene, as `viewer.neural.field` makes it (over the scene's bounds)."""
    return encoding.encode_scene(scene, resolution, voxels).inputs


class EncodingDistance:
    """Nearest-neighbour distance in one view (`statistics`, `layout`) to a reference set of encoded
    scenes."""

    def __init__(self, encodings, view=statistics):
        """`encodings`: the reference (training) scenes' inputs, each (3, CHANNELS, M, M, M)."""
        self.view = view
        passes = np.stack([view(e) for e in encodings])          # (S, 3, K)
        flat = passes.reshape(-1, passes.shape[-1])
        self.mean = flat.mean(axis=0)
        self.spread = flat.std(axis=0) + 1e-3
        self.reference = (flat - self.mean) / self.spread
        self.owner = np.repeat(np.arange(len(passes)), 3)
        self.count = len(passes)
        """Reference scenes."""
        self.typical = 1.0
        if len(passes) > 1:
            nearest = [self._nearest(self.reference[self.owner == s], exclude=s) for s in range(len(passes))]
            self.typical = float(np.median(nearest))

    def _nearest(self, passes: np.ndarray, exclude: int = -1) -> float:
        """Distance of the farthest of a scene's passes to its nearest reference pass (not the scene's own)."""
        others = self.reference[self.owner != exclude]
        gaps = np.linalg.norm(passes[:, None, :] - others[None, :, :], axis=2)
        return float(gaps.min(axis=1).max())

    def __call__(self, inputs: np.ndarray) -> float:
        """The distance of one encoded scene, in units of the training set's typical neighbour distance."""
        return self._nearest((self.view(inputs) - self.mean) / self.spread) / self.typical



REFERENCE_ROOMS = 1000
"""At most this many training rooms, evenly spaced through the split, are the reference set: 5,005
encoded rooms at 24^3 are 12 GB to read, and the distances are in units of the set's own typical
neighbour distance."""


def training_distances(resolution: int, data: Path = DATA, rooms: int = REFERENCE_ROOMS) -> dict[str, EncodingDistance]:
    """Every view against the network's training split (`viewer.training.samples.training_split`,
    encoded at the network's lattice `resolution` and cached under <data>/cache by training), at most
    `rooms` of it. Raises FileNotFoundError without the dataset."""
    from viewer.training.samples import training_split

    inputs = training_split(data, resolution, quiet=True).inputs
    step = max(1, -(-len(inputs) // rooms))
    encodings = [inputs[i] for i in range(0, len(inputs), step)]
    return {name: EncodingDistance(encodings, view) for name, view in VIEWS.items()}

"""Baked grid files changed key by key, for the tests that feed the grid reader bad input."""

from __future__ import annotations

from pathlib import Path

import numpy as np


def rewritten(source: Path, target: Path, compressed: bool = False, **changes) -> Path:
    """A copy of a baked .npz with some keys replaced (None: removed), stored or compressed."""
    with np.load(source, allow_pickle=False) as data:
        values = {k: data[k] for k in data.files}
    for key, value in changes.items():
        if value is None:
            values.pop(key)
        else:
            values[key] = value
    (np.savez_compressed if compressed else np.savez)(target, **values)
    return target

"""Disk cache for ground-truth results: Mitsuba runs take seconds to minutes, tests and benchmarks ask
for the same ones again and again.

$GI_VIEWER_REFERENCE_CACHE_DIR, else $XDG_CACHE_HOME/gi-viewer/reference (~/.cache by default);
GI_VIEWER_REFERENCE_CACHE=0 turns it off.
"""

from __future__ import annotations

import hashlib
import os
from pathlib import Path

import numpy as np

from viewer.scene import Scene


def directory() -> Path:
    explicit = os.environ.get("GI_VIEWER_REFERENCE_CACHE_DIR")
    if explicit:
        return Path(explicit)
    return Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "gi-viewer" / "reference"


def enabled(requested: bool = True) -> bool:
    """Off when the caller says so or GI_VIEWER_REFERENCE_CACHE is '0' / 'off' / 'no'."""
    return requested and os.environ.get("GI_VIEWER_REFERENCE_CACHE", "").lower() not in ("0", "off", "no")


def key(tag: str, scene: Scene, arrays: list[np.ndarray], params: dict) -> str:
    """sha256 of everything a result depends on: a tag (estimator version, variant, Mitsuba version),
    the scene arrays and sun, the inputs and the parameters."""
    digest = hashlib.sha256(tag.encode())
    for a in (scene.vertices, scene.faces, scene.albedo, scene.emission, *arrays):
        a = np.ascontiguousarray(a)
        digest.update(f"{a.dtype}{a.shape}".encode())
        digest.update(a.tobytes())
    if scene.sun is not None:
        digest.update(np.concatenate([scene.sun.direction, scene.sun.irradiance]).tobytes())
    if scene.textured:   # the textures and the coordinates that read them
        digest.update(np.ascontiguousarray(scene.uv).tobytes())
        for texture in scene.textures:
            if texture is not None:
                digest.update(f"{texture.pixels.shape}{texture.srgb}{texture.wrap}".encode())
                digest.update(texture.pixels.tobytes())
    digest.update(repr(sorted(params.items())).encode())
    return digest.hexdigest()[:32]


def load_or_compute(kind: str, digest: str, compute):
    path = directory() / f"{kind}-{digest}.npy"
    if path.exists():
        try:
            return np.load(path)
        except (OSError, ValueError):
            pass  # a torn or foreign file: recompute and overwrite
    result = compute()
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        partial = path.with_suffix(f".{os.getpid()}.tmp")
        with open(partial, "wb") as fh:
            np.save(fh, result)
        os.replace(partial, path)
    except OSError:
        pass  # a read-only cache is no reason to fail
    return result

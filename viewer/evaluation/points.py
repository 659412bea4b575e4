"""Evaluation points: where accuracy is measured (free space, away from every surface)."""

from __future__ import annotations

import numpy as np

from viewer.scene import Scene


def closest_on_triangles(points: np.ndarray, tri: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Distance (P, T) from each point to each triangle and the closest points (P, T, 3)
    (Ericson, Real-Time Collision Detection, 5.1.5, vectorized)."""
    p = points[:, None, :]
    a, b, c = tri[None, :, 0], tri[None, :, 1], tri[None, :, 2]
    ab, ac, ap = b - a, c - a, p - a
    d1, d2 = (ab * ap).sum(-1), (ac * ap).sum(-1)
    bp = p - b
    d3, d4 = (ab * bp).sum(-1), (ac * bp).sum(-1)
    cp = p - c
    d5, d6 = (ab * cp).sum(-1), (ac * cp).sum(-1)
    va, vb, vc = d3 * d6 - d5 * d4, d5 * d2 - d1 * d6, d1 * d4 - d3 * d2
    denom = np.where(np.abs(va + vb + vc) > 1e-30, va + vb + vc, 1e-30)
    v, w = vb / denom, vc / denom
    q = a + ab * v[..., None] + ac * w[..., None]  # interior
    # edges and vertices, later cases override earlier ones
    t_ab = np.clip(d1 / np.where(np.abs(d1 - d3) > 1e-30, d1 - d3, 1e-30), 0, 1)
    q = np.where(((vc <= 0) & (d1 >= 0) & (d3 <= 0))[..., None], a + ab * t_ab[..., None], q)
    t_ac = np.clip(d2 / np.where(np.abs(d2 - d6) > 1e-30, d2 - d6, 1e-30), 0, 1)
    q = np.where(((vb <= 0) & (d2 >= 0) & (d6 <= 0))[..., None], a + ac * t_ac[..., None], q)
    den_bc = (d4 - d3) + (d5 - d6)
    t_bc = np.clip((d4 - d3) / np.where(np.abs(den_bc) > 1e-30, den_bc, 1e-30), 0, 1)
    q = np.where(((va <= 0) & (d4 - d3 >= 0) & (d5 - d6 >= 0))[..., None], b + (c - b) * t_bc[..., None], q)
    q = np.where(((d1 <= 0) & (d2 <= 0))[..., None], a, q)
    q = np.where(((d3 >= 0) & (d4 <= d3))[..., None], b, q)
    q = np.where(((d6 >= 0) & (d5 <= d6))[..., None], c, q)
    return np.linalg.norm(p - q, axis=-1), q


def free_space_points(scene: Scene, count: int, margin: float = 0.06, seed: int = 0) -> np.ndarray:
    """`count` random points in the scene bounds, at least `margin` from every surface, and on the
    front side of the nearest surface (so not inside closed objects)."""
    rng = np.random.default_rng(seed)
    lo, hi = scene.bounds
    tri = scene.triangles
    normals = scene.face_normals
    kept = []
    total = 0
    for _ in range(100):
        p = rng.uniform(lo + margin, hi - margin, (max(4 * count, 256), 3))
        dist = np.empty((len(p), len(tri)))
        closest = np.empty((len(p), len(tri), 3))
        for s in range(0, len(tri), 256):
            dist[:, s:s + 256], closest[:, s:s + 256] = closest_on_triangles(p, tri[s:s + 256])
        nearest = np.argmin(dist, axis=1)
        rows = np.arange(len(p))
        to_point = p - closest[rows, nearest]
        front = (to_point * normals[nearest]).sum(1) > 0
        ok = (dist[rows, nearest] >= margin) & front
        kept.append(p[ok])
        total += ok.sum()
        if total >= count:
            break
    return np.concatenate(kept)[:count]

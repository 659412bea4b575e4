"""Point samples on a scene's area emitters, for the renderer's direct light (numpy only).

Direct irradiance at a surface point p with normal n from the emitters is the area integral

    E(p, n) = integral_A Le(x) cos(n, x - p) cos(n_x, p - x) / |x - p|^2 V(p, x) dA(x),

estimated with N fixed samples: E ~= sum_k Phi_k cos_p cos_k / (r_k^2 + a_k / pi) V_k, where sample k
carries Phi_k = Le a_k (radiance times the area it stands for, a_k). The `a_k / pi` term is the same
near-field clamp as the transport solver's kernel (the on-axis form factor of a disc of area a_k), so the
sum stays finite next to an emitter.

Samples are placed by systematic (stratified) sampling of the emitted power over all emitter triangles,
then stratified inside each triangle, so N samples cover a large light evenly and every emitter with a
sizeable share of the power gets some. The set is deterministic: the same scene always gives the same
soft shadows, which keeps captures reproducible.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from viewer.scene import Scene


@dataclass(frozen=True)
class LightSamples:
    position: np.ndarray
    """(N, 3) points on emitter triangles."""
    normal: np.ndarray
    """(N, 3) unit front normals (the side the light leaves from)."""
    tangent: np.ndarray
    """(N, 3) unit vector perpendicular to `normal` (frames the sample's shadow cube)."""
    bitangent: np.ndarray
    """(N, 3) cross(normal, tangent)."""
    power: np.ndarray
    """(N, 3) Le * a_k: radiance times the emitter area the sample stands for."""
    area: np.ndarray
    """(N,) a_k, the emitter area the sample stands for."""

    @property
    def count(self) -> int:
        return len(self.area)

    def packed(self) -> np.ndarray:
        """(N, 4, 4) float32 rows for a std430 array of structs {vec4 position_area; vec4 normal;
        vec4 tangent; vec4 power}: xyz the vectors, position's w the area."""
        n = self.count
        out = np.zeros((n, 4, 4), np.float32)
        out[:, 0, :3], out[:, 0, 3] = self.position, self.area
        out[:, 1, :3] = self.normal
        out[:, 2, :3] = self.tangent
        out[:, 3, :3] = self.power
        return out


def _radical_inverse(k: np.ndarray) -> np.ndarray:
    """Van der Corput sequence in base 2: a 1D low-discrepancy sequence for the second dimension."""
    k = np.asarray(k, np.uint64)
    out = np.zeros(k.shape, np.float64)
    scale = 0.5
    while np.any(k):
        out += (k & np.uint64(1)) * scale
        k = k >> np.uint64(1)
        scale *= 0.5
    return out


def _frame(normal: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Tangent and bitangent for unit normals (N, 3): any orthonormal completion."""
    helper = np.where(np.abs(normal[:, :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
    tangent = np.cross(helper, normal)
    tangent /= np.linalg.norm(tangent, axis=1, keepdims=True)
    return tangent, np.cross(normal, tangent)


def emitter_samples(scene: Scene, count: int = 32) -> LightSamples:
    """`count` power-stratified samples on the scene's emitting triangles (an empty set if none emit)."""
    area = scene.face_areas
    emitting = np.flatnonzero(scene.emitting & (area > 0))
    if len(emitting) == 0 or count <= 0:
        empty = np.zeros((0, 3))
        return LightSamples(empty, empty, empty, empty, empty, np.zeros(0))
    face_power = area[emitting] * scene.emission[emitting].mean(axis=1)  # the pi of Le*A*pi cancels
    cdf = np.concatenate([[0.0], np.cumsum(face_power)]) / face_power.sum()
    u = (np.arange(count) + 0.5) / count
    which = np.clip(np.searchsorted(cdf, u, side="right") - 1, 0, len(emitting) - 1)
    share = cdf[which + 1] - cdf[which]
    # Stratified inside the triangle: the position within the face's stretch of the CDF is one
    # coordinate, the van der Corput sequence the other (a Hammersley set per face).
    s = np.clip((u - cdf[which]) / share, 0.0, 1.0)
    first = np.searchsorted(which, which, side="left")   # `which` is sorted: samples per face are a run
    t = _radical_inverse(np.arange(count) - first)
    root = np.sqrt(s)  # uniform on a triangle: (1 - sqrt s, sqrt s (1 - t), sqrt s t)
    bary = np.stack([1.0 - root, root * (1.0 - t), root * t], axis=1)
    face = emitting[which]
    corners = scene.triangles[face]
    position = np.einsum("nk,nkc->nc", bary, corners)
    normal = scene.face_normals[face]
    tangent, bitangent = _frame(normal)
    # Each sample stands for the face area divided by the expected number of samples on that face.
    sample_area = area[face] / (share * count)
    power = scene.emission[face] * sample_area[:, None]
    return LightSamples(position, normal, tangent, bitangent, power, sample_area)

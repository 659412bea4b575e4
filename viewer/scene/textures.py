"""Base-colour textures: an image, its colour space and its wrap modes, sampled where the GI needs it.

A textured group's albedo at a surface point is the face's albedo times the texture's colour there over
the texture's mean colour: `Scene.albedo` keeps the mean (what every per-face stage reads), and the
texture adds the pattern around it. A recoloured group then keeps its pattern around the new colour.

Texture coordinates follow glTF (2.0, 3.8.4): (0, 0) is the image's top-left corner, u grows to the
right and v downwards; `pixels` row 0 is the image's top row.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from viewer.scene.types import SceneError, srgb_to_linear

WRAPS = ("repeat", "mirror", "clamp")
"""How coordinates outside [0, 1] read the image: tiled, tiled with every other copy mirrored, or the
edge texel (glTF's REPEAT 10497, MIRRORED_REPEAT 33648, CLAMP_TO_EDGE 33071)."""
SRGB_TABLE = srgb_to_linear(np.arange(256) / 255.0).astype(np.float32)
"""The linear value of each 8-bit sRGB code."""
MAX_SIDE = 16384
"""The longest side of a texture the renderer uploads (llvmpipe's limit)."""


@dataclass(frozen=True, eq=False)
class Texture:
    """One base-colour image."""

    pixels: np.ndarray
    """(H, W, 3): uint8 sRGB-encoded (`srgb` True), or float32 linear RGB (`srgb` False)."""
    srgb: bool = True
    wrap: tuple[str, str] = ("repeat", "repeat")
    """Wrap mode along u and along v, each one of WRAPS."""
    nearest: bool = False
    """Magnified, each texel is a flat square (glTF's magFilter NEAREST: pixel art), not blended with its
    neighbours; minified, the renderer filters trilinearly either way."""
    name: str = ""
    mean: np.ndarray = field(init=False, repr=False)
    """(3,) the image's mean linear colour."""

    def __post_init__(self):
        pixels = np.asarray(self.pixels)
        if pixels.ndim != 3 or pixels.shape[2] != 3 or min(pixels.shape[:2]) < 1:
            raise SceneError(f"texture {self.name!r}: pixels must be an (H, W, 3) image")
        if max(pixels.shape[:2]) > MAX_SIDE:
            raise SceneError(f"texture {self.name!r}: {pixels.shape[1]}x{pixels.shape[0]} pixels, more than "
                             f"{MAX_SIDE} along a side")
        pixels = np.ascontiguousarray(pixels, np.uint8 if self.srgb else np.float32)
        if not self.srgb and not np.all(np.isfinite(pixels)):
            raise SceneError(f"texture {self.name!r}: NaN or infinite colours")
        wrap = tuple(self.wrap)
        if len(wrap) != 2 or any(w not in WRAPS for w in wrap):
            raise SceneError(f"texture {self.name!r}: wrap modes must be two of {', '.join(WRAPS)}")
        pixels.setflags(write=False)
        object.__setattr__(self, "pixels", pixels)
        object.__setattr__(self, "wrap", wrap)
        if self.srgb:   # by histogram: no linear copy of a large image
            counts = [np.bincount(pixels[..., c].ravel(), minlength=256) for c in range(3)]
            mean = np.array([count @ SRGB_TABLE.astype(np.float64) for count in counts]) / pixels[..., 0].size
        else:
            mean = self.linear().reshape(-1, 3).mean(axis=0, dtype=np.float64)
        mean.setflags(write=False)
        object.__setattr__(self, "mean", mean)

    @property
    def size(self) -> tuple[int, int]:
        """(width, height) in pixels."""
        return int(self.pixels.shape[1]), int(self.pixels.shape[0])

    def linear(self) -> np.ndarray:
        """(H, W, 3) float32 linear colours."""
        if self.srgb:
            return SRGB_TABLE[self.pixels]
        return np.maximum(self.pixels, 0.0)

    def sample(self, uv: np.ndarray) -> np.ndarray:
        """(N, 3) linear colours at (N, 2) texture coordinates: bilinear between texel centres (as the
        renderer's finest mip level), or the texel itself for a `nearest` texture, the wrap modes applied
        to the texel indices."""
        uv = np.asarray(uv, np.float64).reshape(-1, 2)
        height, width = self.pixels.shape[:2]
        if self.nearest:
            x = wrapped(np.floor(uv[:, 0] * width), width, self.wrap[0])
            y = wrapped(np.floor(uv[:, 1] * height), height, self.wrap[1])
            texel = self.pixels[y, x]
            return (SRGB_TABLE[texel] if self.srgb else np.maximum(texel, 0.0)).astype(np.float64)
        x = uv[:, 0] * width - 0.5
        y = uv[:, 1] * height - 0.5
        x0, y0 = np.floor(x), np.floor(y)
        fx, fy = (x - x0)[:, None], (y - y0)[:, None]
        xs = [wrapped(x0 + k, width, self.wrap[0]) for k in (0, 1)]
        ys = [wrapped(y0 + k, height, self.wrap[1]) for k in (0, 1)]
        texel = (lambda row, column: SRGB_TABLE[self.pixels[row, column]] if self.srgb
                 else np.maximum(self.pixels[row, column], 0.0))
        top = texel(ys[0], xs[0]) * (1 - fx) + texel(ys[0], xs[1]) * fx
        bottom = texel(ys[1], xs[0]) * (1 - fx) + texel(ys[1], xs[1]) * fx
        return (top * (1 - fy) + bottom * fy).astype(np.float64)

    def relative(self, uv: np.ndarray) -> np.ndarray:
        """(N, 3) the colour at `uv` over the mean colour: what a face's mean albedo is multiplied by
        there (1 in a channel where the image is black throughout: that channel has no pattern)."""
        mean = np.where(self.mean > 0, self.mean, 1.0)
        ratio = self.sample(uv) / mean
        return np.where(self.mean > 0, ratio, 1.0)


def surface_albedo(scene, face: np.ndarray, bary: np.ndarray) -> np.ndarray:
    """(N, 3) the albedo at points of the scene's faces `face` (N,) given by barycentric weights (N, 3) of
    their corners: the face's albedo, times texture(uv) / texture.mean on a textured group."""
    face = np.asarray(face, np.int64)
    albedo = scene.albedo[face].astype(np.float64)
    if not scene.textured:
        return albedo
    uv = np.einsum("nk,nkj->nj", np.asarray(bary, np.float64), scene.uv[face])
    group = scene.face_group[face]
    for index, texture in enumerate(scene.textures):
        chosen = np.flatnonzero(group == index)
        if texture is not None and len(chosen):
            albedo[chosen] *= texture.relative(uv[chosen])
    return np.minimum(albedo, 0.999)   # as Scene keeps albedo: the bounces converge


def relative_at(scene, face: np.ndarray, points: np.ndarray) -> np.ndarray:
    """(N, 3) texture(uv) / texture.mean at world points on the scene's faces `face` (N,) (1 on faces without
    a texture): what the face's albedo is multiplied by there. The points' barycentric weights are those of
    their projection onto the face's plane."""
    face = np.asarray(face, np.int64)
    ratio = np.ones((len(face), 3))
    if not scene.textured:
        return ratio
    textured = np.array([t is not None for t in scene.textures])[scene.face_group[face]]
    chosen = np.flatnonzero(textured)
    corners = scene.triangles[face[chosen]]
    a, b, c = corners[:, 0], corners[:, 1], corners[:, 2]
    e1, e2, d = b - a, c - a, np.asarray(points, np.float64)[chosen] - a
    dot = lambda x, y: np.einsum("ij,ij->i", x, y)
    d11, d12, d22, d1, d2 = dot(e1, e1), dot(e1, e2), dot(e2, e2), dot(d, e1), dot(d, e2)
    det = np.where(np.abs(d11 * d22 - d12 * d12) > 0, d11 * d22 - d12 * d12, 1.0)
    v, w = (d22 * d1 - d12 * d2) / det, (d11 * d2 - d12 * d1) / det
    uv = np.einsum("nk,nkj->nj", np.stack([1 - v - w, v, w], axis=1), scene.uv[face[chosen]])
    group = scene.face_group[face[chosen]]
    for index, texture in enumerate(scene.textures):
        mine = group == index
        if texture is not None and np.any(mine):
            ratio[chosen[mine]] = texture.relative(uv[mine])
    return ratio


def textured_faces(scene) -> np.ndarray:
    """(F,) bool: the faces whose group shows a texture."""
    if not scene.textured:
        return np.zeros(len(scene.faces), bool)
    return np.array([t is not None for t in scene.textures])[scene.face_group]


def wrapped(index: np.ndarray, count: int, mode: str) -> np.ndarray:
    """Integer texel indices wrapped into [0, count) by `mode` (one of WRAPS)."""
    index = index.astype(np.int64)
    if mode == "repeat":
        return np.mod(index, count)
    if mode == "mirror":
        period = np.mod(index, 2 * count)
        return np.where(period < count, period, 2 * count - 1 - period)
    return np.clip(index, 0, count - 1)


def transform_uv(uv: np.ndarray, offset=(0.0, 0.0), rotation: float = 0.0, scale=(1.0, 1.0)) -> np.ndarray:
    """KHR_texture_transform: uv' = T(offset) R(rotation) S(scale) uv. R turns the coordinates
    counter-clockwise as seen on the UV map, whose v axis points down: u' = u cos r + v sin r,
    v' = -u sin r + v cos r, as the Khronos TextureTransformTest sample and the common viewers read it
    (the extension's GLSL listing writes the transposed matrix, a known erratum of the text)."""
    uv = np.asarray(uv, np.float64)
    c, s = np.cos(rotation), np.sin(rotation)
    scaled = uv * np.asarray(scale, np.float64)
    rotated = np.stack([c * scaled[..., 0] + s * scaled[..., 1], -s * scaled[..., 0] + c * scaled[..., 1]], axis=-1)
    return rotated + np.asarray(offset, np.float64)

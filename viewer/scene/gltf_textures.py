"""A glTF material's base-colour texture: its image (sRGB, glTF 2.0, 3.9.2), its sampler's wrap modes (3.8.4)
and the texture coordinates it is read with (TEXCOORD_n, moved by KHR_texture_transform)."""

from __future__ import annotations

import io
from pathlib import Path

import numpy as np

from viewer.scene.gltf_data import MALFORMED, GltfData, integer, one_line
from viewer.scene.textures import MAX_SIDE, Texture, transform_uv
from viewer.scene.types import SceneError

WRAP_MODES = {10497: "repeat", 33648: "mirror", 33071: "clamp"}
"""glTF sampler wrapS / wrapT -> viewer.scene.textures.WRAPS."""
NEAREST = 9728
"""glTF sampler magFilter NEAREST (else LINEAR, 9729, or undefined: the viewer filters linearly)."""


def read_texture(path: Path, data: GltfData, index: int, material: int) -> Texture | None:
    """glTF texture `index` as a Texture; None when it has no image the viewer may read (an image only an
    extension names, or a file outside the scene's folder: said in one line by the caller)."""
    texture = data.item("textures", index)
    if texture.get("source") is None:
        return None
    encoded = data.image(texture["source"])
    if encoded is None:
        return None
    try:
        from PIL import Image

        with Image.open(io.BytesIO(encoded)) as image:
            image = image.convert("RGB")
            if max(image.size) > MAX_SIDE:
                image.thumbnail((MAX_SIDE, MAX_SIDE))
            pixels = np.asarray(image, np.uint8)
    except Exception as exc:  # PIL raises OSError, SyntaxError, zlib.error, ... on bad image data
        raise SceneError(f"{path}: unreadable base-colour texture in glTF material {material} "
                         f"({one_line(exc)})") from None
    wrap, nearest = ("repeat", "repeat"), False
    if texture.get("sampler") is not None:
        sampler = data.item("samplers", texture["sampler"])
        wrap = tuple(WRAP_MODES.get(sampler.get(key, 10497), "repeat") for key in ("wrapS", "wrapT"))
        nearest = sampler.get("magFilter") == NEAREST
    return Texture(pixels, srgb=True, wrap=wrap, nearest=nearest, name=f"texture-{index}")


def face_uv(data: GltfData, attributes: dict, info: dict, faces: np.ndarray, count: int) -> np.ndarray | None:
    """(F, 3, 2) the texture coordinates of the faces' corners that the textureInfo `info` reads: the
    TEXCOORD_n its texCoord names (KHR_texture_transform's own texCoord overrides it), moved by that
    extension's offset, rotation and scale. None when the primitive has no such attribute."""
    transform = (info.get("extensions") or {}).get("KHR_texture_transform") or {}
    try:
        channel = integer(transform.get("texCoord", info.get("texCoord", 0)), f"{data.path}: texCoord", 0, 64)
        if attributes.get(f"TEXCOORD_{channel}") is None:
            return None
        uv = data.accessor(attributes[f"TEXCOORD_{channel}"], {"VEC2"}).astype(np.float64)
        if len(uv) != count:
            raise SceneError(f"{data.path}: TEXCOORD_{channel} is not one coordinate pair per vertex")
        offset = [float(v) for v in transform.get("offset", (0.0, 0.0))][:2]
        scale = [float(v) for v in transform.get("scale", (1.0, 1.0))][:2]
        rotation = float(transform.get("rotation", 0.0))
        uv = transform_uv(uv, offset, rotation, scale)
    except SceneError:
        raise
    except MALFORMED as exc:
        raise SceneError(f"{data.path}: malformed glTF texture coordinates ({one_line(exc)})") from None
    if not np.all(np.isfinite(uv)):
        raise SceneError(f"{data.path}: TEXCOORD_{channel} holds NaN or infinite coordinates")
    return uv[faces]

"""A textured glTF that tests write in a line: a unit quad facing +z showing a 2x2 checker."""

from __future__ import annotations

import base64
import io
import json
from pathlib import Path

import numpy as np
from PIL import Image

CHECKER = np.array([[[204, 51, 51], [51, 204, 51]],
                    [[51, 51, 204], [153, 153, 153]]], np.uint8)
"""sRGB codes: red top-left, green top-right, blue bottom-left, grey bottom-right (as the image shows it)."""
QUAD = np.array([[-1.0, 1.0, 0.0], [1.0, 1.0, 0.0], [1.0, -1.0, 0.0], [-1.0, -1.0, 0.0]])
"""The quad's corners: top-left, top-right, bottom-right, bottom-left seen from +z."""
QUAD_UV = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])
"""glTF's (0, 0) is the image's top-left: the image shows upright on the quad seen from +z."""


def png(pixels: np.ndarray) -> bytes:
    out = io.BytesIO()
    Image.fromarray(pixels).save(out, format="PNG")
    return out.getvalue()


def data_uri(data: bytes, kind: str) -> str:
    return f"data:{kind};base64," + base64.b64encode(data).decode()


def checker_quad(path: Path, transform: dict | None = None, wrap=(10497, 10497), factor=(1.0, 1.0, 1.0, 1.0),
                 uv: np.ndarray = QUAD_UV, pixels: np.ndarray = CHECKER, mag_filter: int | None = None) -> Path:
    """Write the quad with the checker as its base-colour texture (KHR_texture_transform `transform` on the
    textureInfo when given; the sampler's wrapS, wrapT and magFilter) to `path`, a .gltf."""
    sampler = {"wrapS": wrap[0], "wrapT": wrap[1]}
    if mag_filter is not None:
        sampler["magFilter"] = mag_filter
    positions = QUAD.astype(np.float32).tobytes()
    coordinates = np.asarray(uv, np.float32).tobytes()
    indices = np.array([0, 3, 2, 0, 2, 1], np.uint16).tobytes()   # counter-clockwise seen from +z
    blob = positions + coordinates + indices
    info = {"index": 0}
    if transform is not None:
        info["extensions"] = {"KHR_texture_transform": transform}
    document = {
        "asset": {"version": "2.0"},
        "extensionsUsed": ["KHR_texture_transform"] if transform is not None else [],
        "scene": 0, "scenes": [{"nodes": [0]}], "nodes": [{"mesh": 0}],
        "meshes": [{"name": "quad", "primitives": [{"attributes": {"POSITION": 0, "TEXCOORD_0": 1}, "indices": 2,
                                                    "material": 0}]}],
        "materials": [{"name": "checker", "pbrMetallicRoughness": {"baseColorTexture": info,
                                                                   "baseColorFactor": list(factor)}}],
        "textures": [{"source": 0, "sampler": 0}],
        "samplers": [sampler],
        "images": [{"uri": data_uri(png(pixels), "image/png")}],
        "buffers": [{"byteLength": len(blob), "uri": data_uri(blob, "application/octet-stream")}],
        "bufferViews": [{"buffer": 0, "byteOffset": 0, "byteLength": 48},
                        {"buffer": 0, "byteOffset": 48, "byteLength": 32},
                        {"buffer": 0, "byteOffset": 80, "byteLength": 12}],
        "accessors": [{"bufferView": 0, "componentType": 5126, "count": 4, "type": "VEC3",
                       "min": [-1, -1, 0], "max": [1, 1, 0]},
                      {"bufferView": 1, "componentType": 5126, "count": 4, "type": "VEC2"},
                      {"bufferView": 2, "componentType": 5123, "count": 6, "type": "SCALAR"}],
    }
    path.write_text(json.dumps(document))
    return path

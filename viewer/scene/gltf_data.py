"""A glTF 2.0 file's JSON document and the binary data it points at: buffers, buffer views, accessors
(sparse ones included) and image bytes, as the glTF 2.0 specification defines them (sections 3.6, 5.1).

What a file may read besides itself: buffers and images embedded as `data:` URIs, the binary chunk of a
GLB, and regular files of a bounded size inside the file's own folder, by the name the file gives.
Anything else is refused unopened. Every failure is a one-line `SceneError` naming the file.
"""

from __future__ import annotations

import base64
import binascii
import json
import struct
from pathlib import Path
from urllib.parse import unquote

import numpy as np

from viewer.scene.files import check_readable
from viewer.scene.types import SceneError

MALFORMED = (TypeError, ValueError, KeyError, IndexError, AttributeError, RecursionError, OverflowError)
"""What reading a field of an unexpected shape raises (a string where a list was due, a missing key)."""

COMPONENTS = {5120: np.int8, 5121: np.uint8, 5122: np.int16, 5123: np.uint16, 5125: np.uint32, 5126: np.float32}
"""glTF componentType -> numpy type (little-endian in the file)."""
WIDTHS = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4}
"""Accessor type -> components per element (the matrix types carry no geometry or colour here)."""
MAX_ELEMENTS = 1 << 27
"""The most elements an accessor may have: what a 1 GiB file can hold of the smallest accessor (bytes),
and a bound on what an accessor without a buffer view (all zeros, sparse ones filled in) allocates."""


def one_line(exc: BaseException) -> str:
    text = str(exc).strip().splitlines()
    return (text[0] if text else type(exc).__name__)[:160]


def integer(value, what: str, lo: int = 0, hi: int = 1 << 62) -> int:
    """A JSON integer in [lo, hi], or SceneError naming `what` (JSON booleans are not numbers here)."""
    if isinstance(value, bool) or not isinstance(value, int) or not lo <= value <= hi:
        raise SceneError(f"{what}: expected an integer in [{lo}, {hi}], got {str(value)[:40]!r}")
    return value


def rgb(values) -> np.ndarray:
    """The first three numbers of a JSON colour, finite (ValueError otherwise)."""
    colour = np.asarray([float(v) for v in list(values)[:3]], np.float64)
    if colour.shape != (3,) or not np.all(np.isfinite(colour)):
        raise ValueError(f"{values!r} is not an RGB colour")
    return colour


class GltfData:
    """The document of one .gltf or .glb file and its binary data, read when first asked for."""

    def __init__(self, path: Path):
        self.path, self.folder = path, path.parent.resolve()
        self.document, self.glb_binary = _document(path)
        self.refused: list[str] = []   # images skipped: one line each, printed by the caller
        self._buffers: dict[int, bytes] = {}

    def list(self, key: str) -> list:
        """A top-level array of the document (`meshes`, `nodes`, ...), empty when absent."""
        value = self.document.get(key, [])
        if not isinstance(value, list):
            raise SceneError(f"{self.path}: glTF {key!r} is not a list")
        return value

    def item(self, key: str, index) -> dict:
        items = self.list(key)
        index = integer(index, f"{self.path}: glTF {key} index", 0, max(len(items) - 1, 0))
        if index >= len(items) or not isinstance(items[index], dict):
            raise SceneError(f"{self.path}: glTF {key}[{index}] does not exist or is not an object")
        return items[index]

    # ---- bytes ------------------------------------------------------------------------------------------
    def buffer(self, index) -> bytes:
        if index not in self._buffers:
            spec = self.item("buffers", index)
            length = integer(spec.get("byteLength"), f"{self.path}: buffer {index} byteLength", 1)
            uri = spec.get("uri")
            if uri is None:   # the GLB's binary chunk (glTF 2.0, 4.4.3.3)
                if self.glb_binary is None:
                    raise SceneError(f"{self.path}: buffer {index} has no uri and the file has no binary chunk")
                data = self.glb_binary
            else:
                data = self.uri_bytes(uri, "buffer")
            if len(data) < length:
                raise SceneError(f"{self.path}: buffer {index} holds {len(data)} bytes, fewer than its "
                                 f"byteLength {length}")
            self._buffers[index] = data[:length]
        return self._buffers[index]

    def uri_bytes(self, uri, what: str) -> bytes:
        """The bytes of a `data:` URI, or of a file in the glTF's folder (relative, percent-decoded)."""
        if not isinstance(uri, str):
            raise SceneError(f"{self.path}: a {what} uri is not a string")
        if uri.startswith("data:"):
            header, _, payload = uri.partition(",")
            if not header.endswith(";base64"):
                raise SceneError(f"{self.path}: a {what}'s data URI is not base64")
            try:
                return base64.b64decode(payload, validate=False)
            except (binascii.Error, ValueError) as exc:
                raise SceneError(f"{self.path}: a {what}'s data URI does not decode ({one_line(exc)})") from None
        return self.folder_file(unquote(uri), what)

    def folder_file(self, name: str, what: str) -> bytes:
        try:
            target = (self.folder / name.strip()).resolve()
        except (OSError, ValueError, RuntimeError):
            target = None
        if target is None or not target.is_relative_to(self.folder):
            raise SceneError(f"{self.path}: {name[:120]!r} lies outside the scene's folder {self.folder}")
        if not target.exists():
            raise SceneError(f"{self.path}: its {what} {name[:120]!r} is missing (looked in {self.folder})")
        check_readable(target, f"glTF {what}")
        return target.read_bytes()

    def view(self, index) -> tuple[bytes, int | None]:
        """A buffer view's bytes and its byteStride (None: elements packed tightly)."""
        spec = self.item("bufferViews", index)
        data = self.buffer(spec.get("buffer"))
        start = integer(spec.get("byteOffset", 0), f"{self.path}: bufferView {index} byteOffset")
        length = integer(spec.get("byteLength"), f"{self.path}: bufferView {index} byteLength", 1)
        if start + length > len(data):
            raise SceneError(f"{self.path}: bufferView {index} reaches past the end of its buffer")
        stride = spec.get("byteStride")
        if stride is not None:
            stride = integer(stride, f"{self.path}: bufferView {index} byteStride", 4, 252)
        return data[start:start + length], stride

    # ---- accessors ----------------------------------------------------------------------------------------
    def accessor(self, index, types=WIDTHS) -> np.ndarray:
        """Accessor `index` as an (count, width) array: float64 for float and normalized data (normalized
        integers scaled to [0, 1] or [-1, 1], glTF 2.0, 3.11), else the integers. Sparse substitutions
        are applied (3.6.2.3); an accessor without a buffer view starts as zeros."""
        spec = self.item("accessors", index)
        what = f"{self.path}: accessor {index}"
        kind = spec.get("type")
        if kind not in types:
            raise SceneError(f"{what}: type {str(kind)[:20]!r} where {'/'.join(types)} is expected")
        width, dtype = WIDTHS[kind], _component(spec.get("componentType"), what)
        count = integer(spec.get("count"), f"{what} count", 1, MAX_ELEMENTS)
        if spec.get("bufferView") is None:
            values = np.zeros((count, width), dtype)
        else:
            values = self._elements(spec.get("bufferView"), spec.get("byteOffset", 0), count, width, dtype, what)
        sparse = spec.get("sparse")
        if sparse is not None:
            values = self._substituted(values, sparse, width, dtype, what)
        if spec.get("normalized") is True and dtype != np.float32:
            return _normalized(values)
        return values.astype(np.float64) if dtype == np.float32 else values

    def _elements(self, view_index, offset, count, width, dtype, what) -> np.ndarray:
        data, stride = self.view(view_index)
        offset = integer(offset, f"{what} byteOffset")
        size = np.dtype(dtype).itemsize
        stride = stride or width * size
        if offset + stride * (count - 1) + width * size > len(data):
            raise SceneError(f"{what}: {count} elements reach past the end of bufferView {view_index}")
        strided = np.ndarray((count, width), np.dtype(dtype).newbyteorder("<"), buffer=data, offset=offset,
                             strides=(stride, size))
        return strided.astype(dtype)   # a copy, in native byte order

    def _substituted(self, values, sparse, width, dtype, what) -> np.ndarray:
        count = integer(sparse.get("count"), f"{what} sparse count", 1, len(values))
        indices_spec, values_spec = sparse.get("indices"), sparse.get("values")
        index_type = _component(indices_spec.get("componentType"), f"{what} sparse indices")
        if index_type not in (np.uint8, np.uint16, np.uint32):
            raise SceneError(f"{what}: sparse indices must be unsigned integers")
        where = self._elements(indices_spec.get("bufferView"), indices_spec.get("byteOffset", 0), count, 1,
                               index_type, f"{what} sparse indices")[:, 0].astype(np.int64)
        if where.max() >= len(values):
            raise SceneError(f"{what}: a sparse index reaches past the accessor's {len(values)} elements")
        values = values.copy()
        values[where] = self._elements(values_spec.get("bufferView"), values_spec.get("byteOffset", 0), count,
                                       width, dtype, f"{what} sparse values")
        return values

    def image(self, index) -> bytes | None:
        """Image `index`'s encoded bytes; None (with a line in `refused`) for one the file may not read."""
        spec = self.item("images", index)
        if spec.get("bufferView") is not None:
            return self.view(spec["bufferView"])[0]
        try:
            return self.uri_bytes(spec.get("uri"), "image")
        except SceneError as exc:
            self.refused.append(str(exc))
            return None


def _component(value, what: str):
    if isinstance(value, bool) or value not in COMPONENTS:
        raise SceneError(f"{what}: componentType {str(value)[:20]!r} is not a glTF component type")
    return COMPONENTS[value]


def _normalized(values: np.ndarray) -> np.ndarray:
    """glTF 2.0, 3.11: unsigned c / max, signed max(c / max, -1)."""
    scaled = values.astype(np.float64) / float(np.iinfo(values.dtype).max)
    return np.maximum(scaled, -1.0)


def _document(path: Path) -> tuple[dict, bytes | None]:
    """The file's JSON document, and a GLB's binary chunk (None for a .gltf or a GLB without one)."""
    data = path.read_bytes()
    binary = None
    if path.suffix.lower() == ".glb":
        if len(data) < 20 or data[:4] != b"glTF" or data[16:20] != b"JSON":
            raise SceneError(f"{path}: not a binary glTF file (no glTF header and JSON chunk)")
        version, _ = struct.unpack_from("<II", data, 4)
        if version != 2:
            raise SceneError(f"{path}: binary glTF version {version}; the viewer reads version 2")
        (length,) = struct.unpack_from("<I", data, 12)
        if 20 + length > len(data):
            raise SceneError(f"{path}: the JSON chunk reaches past the end of the file (truncated?)")
        text, rest = data[20:20 + length], data[20 + length:]
        if len(rest) >= 8 and rest[4:8] == b"BIN\0":
            (size,) = struct.unpack_from("<I", rest, 0)
            if 8 + size > len(rest):
                raise SceneError(f"{path}: the binary chunk reaches past the end of the file (truncated?)")
            binary = rest[8:8 + size]
    else:
        text = data
    try:
        document = json.loads(text)
    except (ValueError, RecursionError) as exc:
        raise SceneError(f"{path}: glTF JSON does not parse ({one_line(exc)})") from None
    if not isinstance(document, dict):
        raise SceneError(f"{path}: not a glTF document (expected a JSON object)")
    return document, binary

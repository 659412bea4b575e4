"""DDS volume textures: the 3D texture file that Direct3D, Unreal, DirectXTex (texconv) and most engines'
importers read, written with numpy.

No maintained Python library writes float 3D textures (pyktx, the KTX reference library's binding,
ships no wheel and needs libktx built from source), and the format is small: the magic `DDS `, a
124-byte DDS_HEADER with the volume flags, and a 20-byte DDS_HEADER_DXT10 that names a DXGI format, then
the texels slice by slice (z), row by row (y), texel by texel (x). See Microsoft's "DDS" programming
guide (DDS_HEADER, DDS_HEADER_DXT10, DDS_PIXELFORMAT).
"""

from __future__ import annotations

import struct
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from viewer.output import replacing

MAGIC = b"DDS "
DXGI_FORMATS = {np.dtype("<f4"): 2, np.dtype("<f2"): 10}
"""numpy dtype -> DXGI format of four channels: R32G32B32A32_FLOAT (2), R16G16B16A16_FLOAT (10)."""
TEXTURE3D = 4
"""D3D10_RESOURCE_DIMENSION_TEXTURE3D."""
# DDS_HEADER.dwFlags: CAPS, HEIGHT, WIDTH, PITCH, PIXELFORMAT, MIPMAPCOUNT, DEPTH
FLAGS = 0x1 | 0x2 | 0x4 | 0x8 | 0x1000 | 0x20000 | 0x800000
CAPS = 0x1000 | 0x8            # DDSCAPS_TEXTURE | DDSCAPS_COMPLEX
CAPS2_VOLUME = 0x200000         # DDSCAPS2_VOLUME
PIXELFORMAT_FOURCC = 0x4        # DDPF_FOURCC, with the fourCC "DX10": a DDS_HEADER_DXT10 follows


class DDSError(ValueError):
    """Not a DDS file this module reads (RGBA float volume textures with a DX10 header)."""


@dataclass(frozen=True)
class VolumeHeader:
    width: int
    height: int
    depth: int
    dxgi_format: int
    dimension: int
    array_size: int

    @property
    def dtype(self) -> np.dtype:
        return {v: k for k, v in DXGI_FORMATS.items()}[self.dxgi_format]


def write_volume(path: str | Path, texels: np.ndarray) -> None:
    """Write (depth, height, width, 4) float32 or float16 texels as one volume texture (one mip level)."""
    texels = np.ascontiguousarray(texels)
    dtype = texels.dtype.newbyteorder("<")
    if texels.ndim != 4 or texels.shape[3] != 4 or dtype not in DXGI_FORMATS:
        raise ValueError(f"expected (depth, height, width, 4) float32 or float16, got {texels.shape} {texels.dtype}")
    depth, height, width, _ = texels.shape
    pitch = width * 4 * texels.dtype.itemsize
    pixel_format = struct.pack("<II4s5I", 32, PIXELFORMAT_FOURCC, b"DX10", 0, 0, 0, 0, 0)
    header = struct.pack("<7I44x", 124, FLAGS, height, width, pitch, depth, 1) + pixel_format
    header += struct.pack("<4I4x", CAPS, CAPS2_VOLUME, 0, 0)
    dx10 = struct.pack("<5I", DXGI_FORMATS[dtype], TEXTURE3D, 0, 1, 0)
    with replacing(path) as out:
        out.write(MAGIC + header + dx10)
        out.write(texels.astype(dtype, copy=False).tobytes())


def read_header(data: bytes) -> VolumeHeader:
    """The volume header at the start of a DDS file's bytes (DDSError if it is not one we write)."""
    if len(data) < 148 or data[:4] != MAGIC:
        raise DDSError("not a DDS file (no `DDS ` magic)")
    size, flags, height, width, _, depth, _ = struct.unpack_from("<7I", data, 4)
    pf_size, pf_flags, four_cc = struct.unpack_from("<II4s", data, 76)
    caps, caps2 = struct.unpack_from("<2I", data, 108)
    if size != 124 or pf_size != 32 or not pf_flags & PIXELFORMAT_FOURCC or four_cc != b"DX10":
        raise DDSError("DDS without a DX10 header")
    if not (caps2 & CAPS2_VOLUME and flags & 0x800000):
        raise DDSError("DDS is not a volume texture")
    dxgi, dimension, _, array_size, _ = struct.unpack_from("<5I", data, 128)
    if dxgi not in DXGI_FORMATS.values() or dimension != TEXTURE3D:
        raise DDSError(f"DDS format {dxgi} / dimension {dimension}: not an RGBA float 3D texture")
    return VolumeHeader(width, height, depth, dxgi, dimension, array_size)


def read_volume(path: str | Path) -> np.ndarray:
    """(depth, height, width, 4) texels of a volume texture written by `write_volume`."""
    data = Path(path).read_bytes()
    header = read_header(data)
    shape = (header.depth, header.height, header.width, 4)
    count = int(np.prod(shape))
    if len(data) < 148 + count * header.dtype.itemsize:
        raise DDSError("DDS file shorter than its header says")
    return np.frombuffer(data, header.dtype, count, offset=148).reshape(shape)

"""How much memory a request asks for, checked before any of it is spent.

Each GI flag has its own range (viewer.cli_parsing.GI_LIMITS), but the work grows with their product: 128^3
probes x 65536 directions is 137 billion probe rays, and 256 voxels per axis keeps about 7 GiB of voxel
rays. `check_work` estimates the largest arrays each stage makes from the settings (and, for a picture, its
size and multisampling) and refuses a request whose largest stage would pass `memory_limit()`, in one line
that names the flags, the memory and the limit. `sample`, `capture`, `bake`, the window and a baked grid's
reader all ask here.

The estimates are measured peaks (tracemalloc, the Cornell box, the physical kernel), rounded up:

    voxels 32, 48, 64 (24 probes, 256 directions)      114, 401, 458 MiB: 112 to 174 KiB x N^2 (the surface
                                                       voxels, their light samples and gather rays)
    probes 24 x 256 directions, 48 x 256, 24 x 1024    114 MiB, 359 MiB, 182 MiB: about 13 bytes per probe ray
                                                       (16 voxels: 46 MiB, the probe rays' share)
    the paper's kernel, 32 voxels (7028 surface ones)  2287 MiB: its all-pairs matrices, 49 bytes per pair

and for a picture (`capture --gi off`, resident memory above a 64x64 capture's 360 MiB, Mesa llvmpipe):
1024x1024 9 MiB with --msaa 1, 37 MiB with 4; 2048x2048 48 MiB and 163 MiB: about 3 + 9.6 x msaa bytes a
pixel. The largest capture, 8192x8192 at --msaa 4, stays within the default limit.
"""

from __future__ import annotations

import os
from dataclasses import dataclass

MAX_PROBES = 128
"""The most probes per axis a solve makes or a baked grid may hold."""
DEFAULT_LIMIT_GIB = 4.0
"""The memory one request may take, in GiB, unless GI_VIEWER_MAX_GIB says otherwise: at the defaults a solve
takes about 0.2 GiB; 64 voxels, 32 probes or 1024 directions stay well below."""
LIMIT_VARIABLE = "GI_VIEWER_MAX_GIB"

VOXEL_BYTES_PER_N2 = 192 << 10
"""The voxel stage's peak per N^2 (N voxels per axis; measured 112 to 174 KiB)."""
PROBE_RAY_BYTES = 16
"""The probe stage's peak per probe ray (probes^3 x directions; measured 13 bytes)."""
SURFACE_VOXELS_PER_N2 = 7
"""Occupied voxels per N^2: a closed box's six faces and what stands inside (the Cornell box: 6.9)."""
PAIR_BYTES = 56
"""The paper's all-pairs kernel: bytes per pair of surface voxels (measured 49)."""
GATHER_RAY_BYTES = 16
"""The transport matrix: per voxel gather ray (a float32 weight, an int32 column, the hit before it)."""
PIXEL_BYTES = 16
"""A picture's own targets per pixel: the resolved frame, the picture read back, the PNG's bytes (measured
3 bytes over the per-sample share)."""
FRAME_BYTES = 3
"""A turntable's frame per pixel: RGB, every frame kept until the GIF is written."""
SAMPLE_BYTES = 12
"""Per multisample of every pixel: colour and depth (measured 9.6 bytes)."""


class WorkError(ValueError):
    """A request that would take more memory than the limit; the message is one line."""


@dataclass(frozen=True)
class Stage:
    name: str
    """What makes the arrays, in the user's words."""
    flags: str
    """The flags it grows with."""
    bytes: int


def memory_limit() -> int:
    """The bytes one request may take: GI_VIEWER_MAX_GIB (a number of GiB), else DEFAULT_LIMIT_GIB."""
    text = os.environ.get(LIMIT_VARIABLE, "")
    try:
        gib = float(text) if text else DEFAULT_LIMIT_GIB
    except ValueError:
        raise WorkError(f"{LIMIT_VARIABLE}={text!r}: expected a number of GiB") from None
    if not 0 < gib < 1 << 20:
        raise WorkError(f"{LIMIT_VARIABLE}={text!r}: expected a number of GiB above 0")
    return int(gib * (1 << 30))


def stages(settings, size: tuple[int, int] | None = None, msaa: int = 1, frames: int = 1) -> list[Stage]:
    """The largest arrays each stage of a request makes: the solve's (settings: a GISettings) and, with a
    picture's `size`, the picture's targets (and, for an animation of `frames`, every frame kept until
    it is written)."""
    n, m = int(settings.voxels), int(settings.probes)
    surface = SURFACE_VOXELS_PER_N2 * n * n
    out = [Stage("the voxels", f"--voxels {n}", VOXEL_BYTES_PER_N2 * n * n),
           Stage("the probe rays", f"--probes {m} --directions {settings.directions}",
                 PROBE_RAY_BYTES * m ** 3 * int(settings.directions)),
           Stage("the voxel gather rays", f"--voxels {n} --gather-rays {settings.gather_rays}",
                 GATHER_RAY_BYTES * surface * int(settings.gather_rays))]
    if settings.kernel == "paper":
        out.append(Stage("the paper kernel's voxel pairs", f"--voxels {n} --kernel paper",
                         PAIR_BYTES * surface * surface))
    if size is not None:
        pixels = int(size[0]) * int(size[1])
        out.append(Stage("the picture", f"--size {size[0]}x{size[1]} --msaa {msaa}",
                         pixels * (PIXEL_BYTES + SAMPLE_BYTES * max(int(msaa), 1))))
        if frames > 1:
            out.append(Stage("the frames", f"--size {size[0]}x{size[1]} --turntable {frames}",
                             pixels * (PIXEL_BYTES + SAMPLE_BYTES * max(int(msaa), 1)) + FRAME_BYTES * pixels * frames))
    return out


def gib(count: int) -> str:
    return f"{count / (1 << 30):.1f} GiB" if count >= 1 << 30 else f"{count / (1 << 20):.0f} MiB"


def check_work(settings, size: tuple[int, int] | None = None, msaa: int = 1, frames: int = 1) -> None:
    """WorkError, in one line naming the flags, the memory and the limit, when the largest stage of the
    request would take more than `memory_limit()`."""
    limit = memory_limit()
    largest = max(stages(settings, size, msaa, frames), key=lambda stage: stage.bytes)
    if largest.bytes > limit:
        raise WorkError(f"{largest.flags}: {largest.name} would take about {gib(largest.bytes)}, more than "
                        f"the {gib(limit)} a request may use (ask for less, or set {LIMIT_VARIABLE})")


def check_probe_grid(resolution: int, coefficients: int = 27, itemsize: int = 4) -> None:
    """WorkError when a probe grid of `resolution`^3 probes is past MAX_PROBES or the memory limit (a baked
    grid holds two of them)."""
    if not 1 <= resolution <= MAX_PROBES:
        raise WorkError(f"resolution {resolution}: must be 1..{MAX_PROBES} probes per axis")
    need = 2 * resolution ** 3 * coefficients * itemsize
    if need > memory_limit():
        raise WorkError(f"resolution {resolution}: its probes would take about {gib(need)}, more than the "
                        f"{gib(memory_limit())} a request may use")

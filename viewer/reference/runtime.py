"""Mitsuba 3, loaded lazily: which variant runs, and what Dr.Jit needs of the arrays handed to it.

Importing this module works without Mitsuba; the first call says what to install. The variant is chosen
once, on first use: `llvm_ad_rgb` (vectorised, needs libLLVM), else `scalar_rgb` (correct but very
slow); `GI_VIEWER_MITSUBA_VARIANT` forces one. viewer/reference/mitsuba.py is the reference's face.
"""

from __future__ import annotations

import os

import numpy as np

INSTALL_HINT = "pip install mitsuba (or the project's extra: pip install 'gi-viewer[reference]')"
VARIANTS = ("llvm_ad_rgb", "scalar_rgb")

_variant: str | None = None


class ReferenceUnavailable(RuntimeError):
    """Mitsuba 3 (or a usable variant of it) is not installed."""


def variant() -> str:
    """The Mitsuba variant in use, choosing it on the first call (llvm_ad_rgb, else scalar_rgb)."""
    global _variant
    mi, dr = modules()
    if _variant is None:
        wanted = os.environ.get("GI_VIEWER_MITSUBA_VARIANT")
        errors = []
        for name in ([wanted] if wanted else VARIANTS):
            try:
                if name.startswith("llvm") and not dr.has_backend(dr.JitBackend.LLVM):
                    raise RuntimeError("Dr.Jit found no libLLVM (apt-get install libllvm19)")
                mi.set_variant(name)
            except Exception as exc:  # noqa: BLE001 - any failure means: try the next variant
                errors.append(f"{name}: {exc}")
                continue
            _variant = name
            break
        else:
            raise ReferenceUnavailable("no usable Mitsuba variant (" + "; ".join(errors) + ")")
    elif mi.variant() != _variant:
        mi.set_variant(_variant)  # someone else switched it: every call here runs in ours
    return _variant


def modules():
    """(mitsuba, drjit), or ReferenceUnavailable saying what to install."""
    try:
        import drjit as dr
        import mitsuba as mi
    except ImportError as exc:
        raise ReferenceUnavailable(f"the Mitsuba reference needs Mitsuba 3 ({exc}): {INSTALL_HINT}") from None
    return mi, dr


def loaded():
    """(mitsuba, drjit, whether the variant is scalar), the variant chosen."""
    name = variant()
    mi, dr = modules()
    return mi, dr, name.startswith("scalar")


def aligned(values: np.ndarray) -> np.ndarray:
    """A float32 copy at a 64-byte aligned address. Dr.Jit reads numpy memory in place and writes the
    pointer's alignment into the kernel, so a chance alignment would change the kernel's hash and
    miss the kernel cache (~1-15 s of LLVM compilation for a path tracer) from run to run."""
    buffer = np.empty(len(values) + 16, np.float32)
    start = (-buffer.ctypes.data % 64) // 4
    out = buffer[start:start + len(values)]
    out[:] = values
    return out

"""A headless OpenGL 4.3+ context through EGL (no display needed; Mesa llvmpipe on machines without a GPU).

Everything that needs a GL context lives under `viewer.gpu`; this module is the one place that makes
one without a window (the window's context comes from moderngl-window). docs/ARCHITECTURE.md, "The GL stack on
these machines": without `backend="egl"` moderngl looks for an X display.
"""

from __future__ import annotations

import ctypes

import moderngl

GL_REQUIRED = 430
"""Compute shaders, SSBOs and image load/store need OpenGL 4.3."""


class GLUnavailable(RuntimeError):
    """No usable OpenGL context could be created; the message says what to install or check."""


def create_context(require: int = GL_REQUIRED) -> moderngl.Context:
    """A standalone (headless) EGL context of at least GL `require` (430 = 4.3)."""
    try:
        return moderngl.create_standalone_context(backend="egl", require=require)
    except Exception as exc:  # moderngl raises plain Exception subclasses for every failure
        try:   # the runtime packages alone (libegl1, libgl1) have only the versioned names
            return moderngl.create_standalone_context(backend="egl", require=require, libegl="libEGL.so.1",
                                                      libgl="libGL.so.1")
        except Exception:
            pass
        raise GLUnavailable(
            f"cannot create a headless OpenGL {require // 100}.{require % 100 // 10} context through EGL "
            f"({exc}); install libegl1 and libgl1 (Mesa llvmpipe works without a GPU)") from None


def describe(ctx: moderngl.Context) -> str:
    """One line naming the GL implementation, for logs and benchmark records."""
    info = ctx.info
    return f"{info.get('GL_RENDERER', '?')} / OpenGL {info.get('GL_VERSION', '?')}"


SOFTWARE_RENDERERS = ("llvmpipe", "softpipe", "swiftshader", "swrast")


def is_software(ctx: moderngl.Context) -> bool:
    """Whether the context rasterizes on the CPU (its GL_RENDERER names a software rasterizer). Its timer
    queries then do not measure a pass's work: llvmpipe stamps them when commands are queued and bins,
    not when its threads rasterize (measured: a clear's query took the 12 ms of the surface pass after
    it, and a query around a blit read 1 ns)."""
    renderer = str(ctx.info.get("GL_RENDERER", "")).lower()
    return any(name in renderer for name in SOFTWARE_RENDERERS)


def finish(ctx: moderngl.Context) -> None:
    """Wait until the GL commands issued so far are done, as a window's buffer swap waits, without holding
    Python's lock: `ctx.finish()` holds it, and a worker thread's Python steps (a colour edit's relight)
    then wait for the rasterizer (5 ms of llvmpipe's frame). glFinish through ctypes, which lets go of it."""
    global _gl_finish
    if _gl_finish is None:
        try:
            _gl_finish = ctypes.CDLL("libGL.so.1").glFinish
            _gl_finish.restype, _gl_finish.argtypes = None, []
        except (OSError, AttributeError):
            _gl_finish = False
    if _gl_finish:
        _gl_finish()
    else:
        ctx.finish()


_gl_finish = None
"""libGL's glFinish (dispatched to the current context), False where there is no libGL.so.1."""

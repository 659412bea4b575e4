"""The GL objects alive in a context, by kind: how the soak (viewer/bench/soak.py), the viewer's
`--resources` lines and the tests see what a solve or a scene load leaves behind (viewer.memory
puts them beside the resident memory).

moderngl keeps no registry of the objects it made. What it does offer (moderngl >= 5.8) is a garbage
collection mode: with `ctx.gc_mode = "context_gc"`, a wrapper that Python frees without `release()`
queues its GL object in `ctx.objects` instead of dropping it (by default such a GL object simply leaks,
unseen). So the objects alive in GL are the wrappers still reachable from Python and not released, plus
the queued ones that were never released: `watch(ctx)` turns that mode on, `live_objects(ctx)` counts
both. Nothing here frees anything: a leak should be fixed where it is made, not swept up later.
"""

from __future__ import annotations

import gc
from collections import Counter

import moderngl

KINDS = ("Buffer", "Texture", "Texture3D", "TextureArray", "TextureCube", "Renderbuffer", "Framebuffer",
         "VertexArray", "Program", "ComputeShader", "Sampler", "Query")
"""moderngl's wrappers of GL objects (a Scope or a ConditionalRender owns none of its own)."""
DROPPED = "dropped "
"""Prefix of the kinds counted from ctx.objects: freed by Python without release(), alive in GL."""


def watch(ctx: moderngl.Context) -> None:
    """Make wrappers freed without release() countable (and not lost): moderngl's `context_gc` mode.
    A context already in `auto` mode (moderngl releases on free) is left so; nothing leaks there."""
    if ctx.gc_mode is None:
        ctx.gc_mode = "context_gc"


def _alive(mglo) -> bool:
    # release() swaps a wrapper's `mglo` for an InvalidObject (the same in every moderngl 5.x)
    return mglo is not None and type(mglo).__name__ != "InvalidObject"


def live_objects(ctx: moderngl.Context) -> Counter:
    """GL objects of `ctx` alive now, by moderngl kind; those freed by Python without release() (seen
    only under `watch`) as `"dropped <Kind>"`. Collects garbage first, so that only what something
    still holds is counted."""
    gc.collect()
    # exact types, not isinstance: that would ask every object in the process for its __class__, and some
    # (torch's deprecated aliases) warn when asked
    kinds = {getattr(moderngl, name) for name in KINDS if hasattr(moderngl, name)}
    counts: Counter = Counter()
    for obj in gc.get_objects():
        if type(obj) in kinds and getattr(obj, "ctx", None) is ctx and _alive(getattr(obj, "mglo", None)):
            counts[type(obj).__name__] += 1
    if ctx.gc_mode == "context_gc":
        # moderngl queues released wrappers too (their InvalidObject): keep only the live ones, so the
        # queue does not grow for the whole run
        dropped = [mglo for mglo in ctx.objects if _alive(mglo)]
        ctx.objects.clear()
        ctx.objects.extend(dropped)
        for mglo in dropped:
            counts[DROPPED + type(mglo).__name__] += 1
    return counts


"""What the process holds: resident memory (VmRSS, from /proc) and the live GL objects of a context,
for the soak (viewer/bench/soak.py), the viewer's `--resources` lines and the tests that keep both from
growing. Resident memory, not Python's own allocations: Mesa llvmpipe keeps textures, buffers and
compiled shaders in ordinary memory, and onnxruntime allocates outside Python too.

glibc's malloc keeps memory that was freed (in the heap and in the arenas of worker threads, such as the
viewer's voxelizing threads) for later allocations, so resident memory wobbles by tens of MB from one
scene to the next without anything being held. `trim=True` hands that free memory back first
(malloc_trim), leaving the memory that something still holds: what a leak grows.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import gc
import re
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path


def trim_free_memory() -> bool:
    """Return the C heap's free memory to the system (glibc's malloc_trim); False where there is none."""
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")
        return bool(libc.malloc_trim(0))
    except (OSError, AttributeError):   # not glibc
        return False


def resident_mb(pid: int | str = "self", trim: bool = False) -> float:
    """Resident memory of a process in MiB (this one by default: garbage collected first, and with
    `trim`, free C heap memory handed back first)."""
    if pid == "self":
        gc.collect()
        if trim:
            trim_free_memory()
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024.0
    raise OSError(f"no VmRSS in /proc/{pid}/status")


def children_mb() -> float:
    """Resident memory of this process's child processes in MiB, as it is (the CPU solver's worker;
    0 where /proc does not list children)."""
    total = 0.0
    for task in Path("/proc/self/task").iterdir():
        try:
            children = (task / "children").read_text().split()
        except OSError:
            continue
        for pid in children:
            try:
                total += resident_mb(int(pid))
            except OSError:   # gone meanwhile
                pass
    return total


_LINE = re.compile(r"rss (?P<rss>[\d.]+) MB, gl objects (?P<total>\d+)(?: \((?P<kinds>[^)]*)\))?")


@dataclass
class Usage:
    """Resident memory and live GL objects at one moment; `str()` is one line, `parse` reads it back."""

    rss_mb: float
    gl: Counter = field(default_factory=Counter)
    """Live GL objects by moderngl kind (viewer.gpu.gl_objects.live_objects)."""

    @classmethod
    def measure(cls, ctx=None, trim: bool = False) -> "Usage":
        gl = Counter()
        if ctx is not None:
            from viewer.gpu.gl_objects import live_objects

            gl = live_objects(ctx)
        return cls(resident_mb(trim=trim), gl)

    @property
    def gl_total(self) -> int:
        return sum(self.gl.values())

    def __str__(self) -> str:
        kinds = ", ".join(f"{kind} {count}" for kind, count in self.gl.most_common())
        return f"rss {self.rss_mb:.1f} MB, gl objects {self.gl_total}" + (f" ({kinds})" if kinds else "")

    @classmethod
    def parse(cls, text: str) -> "Usage | None":
        """The Usage in a line written by `str()` (None if there is none)."""
        match = _LINE.search(text)
        if match is None:
            return None
        kinds = Counter()
        for part in filter(None, (match.group("kinds") or "").split(", ")):
            kind, _, count = part.rpartition(" ")
            kinds[kind] = int(count)
        return cls(float(match.group("rss")), kinds)

"""Files the viewer writes for a user (sample's SH, bake's grid and DDS, capture's picture): written whole
or not at all, exactly at the path the user named.

A file is written beside its target under a temporary name and renamed onto it when complete (a rename
within one folder is atomic on POSIX), so a full disk, a crash or Ctrl-C never leaves a truncated file
where the user's was, and the writers get a file object, so numpy adds no `.npy` or `.npz` of its own.
"""

from __future__ import annotations

import os
import tempfile
from contextlib import contextmanager, suppress
from pathlib import Path
from typing import BinaryIO, Iterator


@contextmanager
def replacing(path: str | Path) -> Iterator[BinaryIO]:
    """A binary file to write `path`'s new contents to; on leaving the block without an error it becomes
    `path` (with the permissions a newly created file gets), otherwise it is removed."""
    path = Path(path)
    fd, partial = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".partial")
    try:
        with os.fdopen(fd, "wb") as out:
            yield out
            out.flush()
            os.fsync(out.fileno())
        os.chmod(partial, 0o666 & ~_umask())
        os.replace(partial, path)
    except BaseException:
        with suppress(OSError):
            os.unlink(partial)
        raise


def _umask() -> int:
    """The process's umask, read without changing it (Linux /proc); 0o022 where it cannot be read."""
    with suppress(OSError, ValueError, StopIteration):
        status = Path("/proc/self/status").read_text()
        return int(next(line for line in status.splitlines() if line.startswith("Umask:")).split()[1], 8)
    return 0o022

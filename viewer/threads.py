"""How many cores a compiled pass uses: every core for a large one, one for a small one.

numba's parallel passes run on OpenMP threads that wait passively between passes (viewer/__init__.py), so
waking them costs about 70 microseconds a pass on the 2-core test machine, more than a pass over a box
room's few dozen faces takes (0.3 microseconds on one core). A move in a box room runs a dozen such
passes."""

from __future__ import annotations

from contextlib import contextmanager

import numba

SERIAL_BELOW = 20_000
"""Items below which a pass runs on the calling thread alone."""
RUNS = 64
"""Runs a reducing pass (bounds, sums) splits its items into, each run's answer its own, shared among the
cores and combined after."""


@contextmanager
def cores_for(items: int):
    """The compiled passes inside run on one thread where they have fewer than SERIAL_BELOW `items`
    (numba's thread count is the calling thread's own: other threads keep theirs)."""
    if items >= SERIAL_BELOW:
        yield
        return
    before = numba.get_num_threads()
    numba.set_num_threads(1)
    try:
        yield
    finally:
        numba.set_num_threads(before)

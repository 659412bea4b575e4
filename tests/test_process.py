"""What importing the package sets up for the whole process (viewer/__init__.py)."""

from __future__ import annotations

import resource

import numpy as np
import pytest

import viewer


@pytest.mark.skipif(not viewer._keep_freed_blocks(), reason="malloc is not glibc's")
def test_arrays_of_megabytes_reuse_freed_memory_without_page_faults():
    """Arrays of a few megabytes made, written and freed together again and again (what each colour edit
    does with the network's inputs, their asinh and the filtered light) are served from memory freed
    before: the system does not map and zero them afresh each time (with glibc's own thresholds, the
    freed heap is handed back and these rounds cost 47,200 page faults; 840 an albedo edit of a
    68k-triangle scan)."""
    def one_edit():
        blocks = [np.ones((3, 40, 24 ** 3), np.float32) for _ in range(5)]   # 6.6 MB, 1,620 pages each
        del blocks

    for _ in range(3):   # the heap grows to hold them once
        one_edit()
    before = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
    for _ in range(20):
        one_edit()
    assert resource.getrusage(resource.RUSAGE_SELF).ru_minflt - before < 500


def test_a_small_pass_runs_on_one_thread_and_the_count_comes_back():
    """`cores_for`: a pass of few items runs on the calling thread alone (waking the others costs more than
    it takes), a large one on all of them; the thread count is restored after either, even on an error."""
    import numba

    from viewer.threads import SERIAL_BELOW, cores_for

    every = numba.get_num_threads()
    with cores_for(36):
        assert numba.get_num_threads() == 1
    assert numba.get_num_threads() == every
    with cores_for(SERIAL_BELOW):
        assert numba.get_num_threads() == every
    with pytest.raises(RuntimeError):
        with cores_for(1):
            raise RuntimeError("a failed pass")
    assert numba.get_num_threads() == every


@pytest.mark.parametrize("numpy_first", [False, True])
def test_numpys_products_run_on_one_thread_unless_the_user_says_otherwise(numpy_first):
    """Importing the viewer leaves numpy's BLAS one thread (its spinning threads would take the other core
    from the compiled passes that follow), whether numpy was imported before it or not; a user's own
    OPENBLAS_NUM_THREADS is kept."""
    import os
    import subprocess
    import sys

    first = "import numpy; import viewer" if numpy_first else "import viewer; import numpy"
    probe = (f"{first}; from threadpoolctl import threadpool_info; "
             "print(sorted({i['num_threads'] for i in threadpool_info() if i['user_api'] == 'blas'}))")
    env = {k: v for k, v in os.environ.items() if k != "OPENBLAS_NUM_THREADS"}

    def threads(environment):
        return subprocess.run([sys.executable, "-c", probe], env=environment, capture_output=True, text=True,
                              check=True).stdout.strip()

    assert threads(env) == "[1]"
    assert threads({**env, "OPENBLAS_NUM_THREADS": "2"}) == "[2]"

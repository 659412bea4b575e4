"""gi-viewer: real-time diffuse global illumination from voxels and SH light probes."""

import os

# numba's parallel loops (viewer.rays.dda, viewer.physical.relight) run on OpenMP threads, which by default spin while
# they wait for work. When the render loop or llvmpipe keeps the other core busy, the spinning threads
# take its time: a relight measured 190 ms instead of 57 ms under load (docs/PERFORMANCE.md). Waiting
# passively costs nothing on an idle machine. Set before any import loads the OpenMP runtime.
os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

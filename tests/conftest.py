"""Suite-wide settings.

The suite runs in two pytest-xdist workers on two cores; each worker's BLAS keeps to one thread,
otherwise the small dense solves in the physics fits contend for the cores and run several times
slower. Set before numpy is first imported in the worker.
"""

import os

for _var in ("OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

"""The ``streetaug`` command line (``streetaug.cli.main:main``)."""

import os

# Before numpy loads (any streetaug.cli import comes through here first): multi-threaded BLAS makes the
# renderer's many small (N, 3) @ (3, 3) products ~40x slower on a 2-core machine, and batch parallelism
# is by processes anyway.
for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

"""The ``streetaug`` command line: thin click commands that parse options, call one library function and print.

It owns the commands (``main.py``: the group, ``predict-light``, ``insert``, ``make-samples``; ``batch.py``,
``bench.py``, ``stability.py``, ``train.py``: one module per command family) and the options, parsing and
error handling they share (``common.py``: exit 0 on success, 2 on bad arguments, 1 on runtime errors with
a one-line cause, tracebacks with ``--debug``). The entry point is ``streetaug.cli.main:main``; nothing
else imports this package, so it exports no names of its own.

Start-up: ``main`` is a :class:`~.lazy_group.LazyGroup`, so a command's module is imported only when that
command is looked up, and every command imports its library code (torch, scipy, the dataset reader) in its
body (``insert`` and ``predict-light`` under :func:`~.common.library_imports`, the GC paused): ``streetaug
--help`` loads none of it (tests/test_startup.py).
"""

import os

# Before numpy loads (any streetaug.cli import comes through here first): multi-threaded BLAS makes the
# renderer's many small (N, 3) @ (3, 3) products ~40x slower on a 2-core machine, and batch parallelism
# is by processes anyway.
for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

__all__: list[str] = []

"""Run tasks inline, in local worker processes, or on a Dask cluster; yield results as they complete.

Every executor keeps at most ``2 x workers`` tasks in flight, so memory stays bounded however many
tasks there are. Results arrive in completion order; the batch's outputs do not depend on it
(per-item seeds). Worker processes inherit the environment: set ``OPENBLAS_NUM_THREADS=1`` (and
OMP/MKL) before they start (:func:`single_threaded_env`); Dask's nanny sets them by default.
"""

from __future__ import annotations

import atexit
import multiprocessing
import os
import sys
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from itertools import islice
from typing import Callable, Iterable, Iterator

from ..core import InputError
from ..core.lock import exit_with_parent

THREAD_VARS = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")


def single_threaded_env() -> None:
    """Make worker processes started from now on use one BLAS/OpenMP thread (parallelism is by processes)."""
    for var in THREAD_VARS:
        os.environ.setdefault(var, "1")


# glibc malloc tuning for workers (see :func:`tune_malloc`).
_M_TRIM_THRESHOLD, _M_MMAP_THRESHOLD = -1, -3
MMAP_THRESHOLD_BYTES = 64 * 2**20
TRIM_THRESHOLD_BYTES = 256 * 2**20
_malloc_tuned = False


def tune_malloc() -> bool:
    """Keep freed image-sized arrays in this process's heap instead of returning them to the OS.

    A worker allocates and frees many 10-50 MB arrays per image.  Dask's nanny sets
    ``MALLOC_TRIM_THRESHOLD_=65536``, which also switches off glibc's adaptive mmap threshold: every
    such array is then a fresh ``mmap`` whose pages fault in again, and a worker spends ~2x the CPU per
    image (measured: sys time 0.6 -> 3.2 s for the bundled scenes).  Setting the mmap threshold to 64 MiB
    and the trim threshold to 256 MiB restores reuse.  Idempotent; a no-op (False) without glibc.
    """
    global _malloc_tuned
    if _malloc_tuned:
        return True
    try:
        import ctypes

        libc = ctypes.CDLL("libc.so.6")
        ok = bool(libc.mallopt(_M_MMAP_THRESHOLD, MMAP_THRESHOLD_BYTES)) and bool(
            libc.mallopt(_M_TRIM_THRESHOLD, TRIM_THRESHOLD_BYTES))
    except (OSError, AttributeError):
        return False
    _malloc_tuned = ok
    return ok


def release_free_heap() -> bool:
    """Give the heap's free pages back to the OS (glibc ``malloc_trim(0)``); False without glibc.

    :func:`tune_malloc` keeps freed arrays in the heap so that a sample's images reuse them; between samples
    they are only free memory, yet resident: on scene-0916 a worker held 750-770 MB after a sample of which
    240 MB were live (the rest freed lighting volumes and render buffers), and the next sample's lighting
    peaked on top of it. Called once per sample: the pages fault in again in the next one. The worker's peak
    is then its lighting stage's within one sample (``lighting.multiview.choose_auto``: ~250 MB transient).
    """
    try:
        import ctypes

        return bool(ctypes.CDLL("libc.so.6").malloc_trim(0))
    except (OSError, AttributeError):
        return False


def _exit_without_teardown() -> None:
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(0)


def init_pool_worker() -> None:
    """Initializer of a worker process we start (local pool, Dask LocalCluster): it dies with its parent,
    malloc tuning, a fast exit.

    A SIGKILLed driver cannot stop its workers; :func:`exit_with_parent` makes each end by itself when its
    parent goes (instead of finishing its task, 1.3-1.5 GB each on scene-0916, for a minute or more).

    A spawned process ends with ``sys.exit``, i.e. a full interpreter teardown, which takes 0.45 s with
    torch and scipy loaded (2.3 s for a Dask LocalCluster's two workers; measured) -- paid at the end of
    every run, while the driver waits for its workers.  The worker has sent its last result by the time
    ``atexit`` runs (multiprocessing flushes its queues before), so it skips the teardown with ``os._exit``.
    """
    exit_with_parent()
    tune_malloc()
    atexit.register(_exit_without_teardown)


def run_inline(fn: Callable, tasks: Iterable[tuple]) -> Iterator:
    for args in tasks:
        yield fn(*args)


def run_processes(fn: Callable, tasks: Iterable[tuple], workers: int) -> Iterator:
    """``fn(*args)`` in ``workers`` spawned processes (spawn: no fork of a process holding threads)."""
    single_threaded_env()
    tasks = iter(tasks)
    with ProcessPoolExecutor(max_workers=workers, mp_context=multiprocessing.get_context("spawn"),
                             initializer=init_pool_worker) as pool:
        pending = {pool.submit(fn, *args) for args in islice(tasks, 2 * workers)}
        try:
            while pending:
                finished, pending = wait(pending, return_when=FIRST_COMPLETED)
                for future in finished:
                    yield future.result()
                    for args in islice(tasks, 1):
                        pending.add(pool.submit(fn, *args))
        except BaseException:
            for future in pending:
                future.cancel()
            raise


def run_dask(fn: Callable, tasks: Iterable[tuple], scheduler: str | None = None, local_workers: int | None = None,
             on_start: Callable[[str], None] | None = None) -> Iterator:
    """``fn(*args)`` on a Dask cluster: the scheduler at ``scheduler``, or a LocalCluster of ``local_workers``."""
    try:
        import dask
        from distributed import Client, LocalCluster, as_completed
    except ImportError:
        raise InputError("--scheduler/--dask-local need Dask: pip install 'streetaug[distributed]' "
                         "(dask and distributed)") from None
    single_threaded_env()
    cluster = None
    if scheduler is None:
        # No statistical profiler in our workers: it samples their stacks every 10 ms, at a few % of the CPU.
        with dask.config.set({"distributed.worker.profile.enabled": False}):
            cluster = LocalCluster(n_workers=local_workers or 1, threads_per_worker=1, processes=True,
                                   dashboard_address=":0")  # any free port: never clashes
    try:
        with Client(cluster if cluster is not None else scheduler) as client:
            if cluster is not None:  # our own workers: closing the cluster then takes 0.06 s instead of 2.3 s
                client.run(init_pool_worker)
            n_workers = max(1, len(client.scheduler_info().get("workers", {})))
            if on_start is not None:
                on_start(f"Dask: {n_workers} worker(s) at {client.scheduler.address}")
            tasks = iter(tasks)
            futures = [client.submit(fn, *args, pure=False) for args in islice(tasks, 2 * n_workers)]
            completed = as_completed(futures)
            try:
                for future in completed:
                    result = future.result()
                    future.release()
                    yield result
                    for args in islice(tasks, 1):
                        completed.add(client.submit(fn, *args, pure=False))
            except BaseException:
                client.cancel(futures)
                raise
    finally:
        if cluster is not None:
            cluster.close()

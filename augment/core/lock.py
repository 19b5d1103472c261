"""One run per output folder: a lock file held while a job writes, and workers that die with their parent.

``OUT/.streetaug.lock`` is created atomically (``O_EXCL``) with the owner's pid, host and start time. A second
run on the same folder is refused with a message naming the owner. A lock whose owner is gone (same host, pid
not alive, or the pid now belongs to another process started later) is stale: it is taken over and said so.
A lock from another host is never taken over silently: the message tells how to remove it.
"""

from __future__ import annotations

import ctypes
import json
import multiprocessing
import os
import signal
import socket
import threading
import time
from pathlib import Path
from types import TracebackType

from .errors import InputError

LOCK_NAME = ".streetaug.lock"


def _process_start_ticks(pid: int) -> int | None:
    """Start time of a process in clock ticks since boot (Linux ``/proc``), or None where unknown."""
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return None
    return int(stat.rpartition(")")[2].split()[19])


def pid_alive(pid: int) -> bool:
    """True if a process with this pid exists on this host."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


class OutputLock:
    """Context manager holding ``OUT/.streetaug.lock`` for the duration of a job.

    Example::

        with OutputLock(out_dir, command="batch"):
            run_the_job()

    Raises:
        InputError: another live run holds the lock (the message names its pid, host and start).
    """

    def __init__(self, folder: str | Path, command: str = "streetaug") -> None:
        self.path = Path(folder) / LOCK_NAME
        self.command = command
        self.took_over: dict | None = None

    def _owner_record(self) -> dict:
        return {"pid": os.getpid(), "host": socket.gethostname(), "command": self.command,
                "started_unix": time.time(), "start_ticks": _process_start_ticks(os.getpid())}

    def _is_stale(self, owner: dict) -> bool:
        if owner.get("host") != socket.gethostname():
            return False
        pid = int(owner.get("pid", -1))
        if pid <= 0 or not pid_alive(pid):
            return True
        ticks = owner.get("start_ticks")
        return ticks is not None and _process_start_ticks(pid) not in (None, ticks)  # pid reused

    def acquire(self) -> None:
        self.path.parent.mkdir(parents=True, exist_ok=True)
        record = json.dumps(self._owner_record()).encode()
        for _attempt in range(3):
            try:
                fd = os.open(self.path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o644)
            except FileExistsError:
                owner = self._read_owner()
                if owner is None or self._is_stale(owner):
                    self.took_over = owner or {}
                    self.path.unlink(missing_ok=True)
                    continue
                raise InputError(
                    f"{self.path.parent}: another streetaug {owner.get('command', 'run')} is writing here "
                    f"(pid {owner.get('pid')} on host {owner.get('host')}, started "
                    f"{time.strftime('%Y-%m-%d %H:%M:%S', time.localtime(owner.get('started_unix', 0)))}); "
                    f"wait for it to finish, or remove {self.path} if that run is gone") from None
            with os.fdopen(fd, "wb") as f:
                f.write(record)
            return
        raise InputError(f"{self.path}: could not take the lock (it kept reappearing); is another run starting?")

    def _read_owner(self) -> dict | None:
        try:
            owner = json.loads(self.path.read_text())
        except (OSError, ValueError):
            return None  # half-written by a run killed while creating it: treated as stale
        return owner if isinstance(owner, dict) else None

    def release(self) -> None:
        owner = self._read_owner()
        if owner is not None and owner.get("pid") == os.getpid() and owner.get("host") == socket.gethostname():
            self.path.unlink(missing_ok=True)

    def __enter__(self) -> "OutputLock":
        self.acquire()
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        self.release()


_PR_SET_PDEATHSIG = 1


def exit_with_parent(poll_s: float = 1.0) -> None:
    """Make this (worker) process end when its parent dies (call it first thing in a worker initialiser).

    The parent is the process that started this one (``multiprocessing.parent_process()`` for a spawned
    worker, else the current ``os.getppid()``): a spawned worker imports for seconds before its initialiser runs,
    and if the parent died meanwhile, ``getppid()`` already names init. On Linux the kernel then sends SIGTERM on
    the parent's death (``prctl(PR_SET_PDEATHSIG)``); elsewhere, and as a second guard, a daemon thread polls the
    parent pid and exits when it changes.
    """
    started_by = multiprocessing.parent_process()
    parent = started_by.pid if started_by is not None else os.getppid()
    if os.getppid() != parent:  # the parent is already gone
        os._exit(1)
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl(_PR_SET_PDEATHSIG, signal.SIGTERM, 0, 0, 0)
    except (OSError, AttributeError):
        pass
    if os.getppid() != parent:  # the parent died before prctl took effect
        os._exit(1)

    def watch() -> None:
        while True:
            time.sleep(poll_s)
            if os.getppid() != parent:
                os._exit(1)

    threading.Thread(target=watch, name="exit-with-parent", daemon=True).start()

"""CPU load for the demo and the soak test: N busy processes for the length of a ``with``.

The station's timing must hold when the machine is busy (the line PC also runs an HMI, a
database, antivirus scans): ``stationd demo --load N`` and the soak test run the station
beside N processes that spin at 100 % of a core each.  They are processes, not threads, so
they compete for the cores the way other programs do (no GIL in the way).

No leak is the contract, whatever happens to the run:

- leaving the ``with`` (normally or by an exception) terminates the workers and reaps them;
- SIGTERM to the process (systemd stopping the demo, ``timeout``) does the same, then acts
  as before (the previous handler is called; the default one exits with status 143);
- a worker whose parent is gone without cleaning up (SIGKILL) notices within 0.1 s and exits.

Workers are started with the ``spawn`` method: forking a process that runs threads (the
daemon's, the simulator's) can copy a held lock into the child.  Their module imports only
the standard library, so each starts in about 0.1 s and holds little memory.
"""

from __future__ import annotations

import multiprocessing
import os
import signal
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager
from multiprocessing.process import BaseProcess
from types import FrameType
from typing import Any

MAX_WORKERS = 64  # far more than any test machine has cores: a typo, not a load
_CHECK_PARENT_S = 0.1
_STOP_GRACE_S = 2.0


def busy(parent_pid: int) -> None:
    """Spin until the parent process is gone (a worker's whole life)."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C is the parent's to handle
    while os.getppid() == parent_pid:
        end = time.monotonic() + _CHECK_PARENT_S
        while time.monotonic() < end:
            pass


class CpuLoad:
    """``n`` busy worker processes; ``start()`` / ``stop()`` (idempotent), or use
    :func:`cpu_load`.  ``pids`` lists the running workers."""

    def __init__(self, n: int) -> None:
        if not isinstance(n, int) or isinstance(n, bool) or not 0 <= n <= MAX_WORKERS:
            raise ValueError(f"the load is a number of busy processes, 0-{MAX_WORKERS}, got {n!r}")
        self.n = n
        self._workers: list[BaseProcess] = []
        self._lock = threading.RLock()  # the SIGTERM handler may stop a start

    @property
    def pids(self) -> list[int]:
        with self._lock:
            return [p.pid for p in self._workers if p.pid is not None and p.is_alive()]

    def start(self) -> None:
        """Start the workers (a second call while running does nothing)."""
        ctx = multiprocessing.get_context("spawn")
        with self._lock:
            if self._workers:
                return
            try:
                for k in range(self.n):
                    p = ctx.Process(target=busy, args=(os.getpid(),), daemon=True,
                                    name=f"stationd-load-{k}")
                    p.start()
                    self._workers.append(p)
            except BaseException:
                self._stop_locked()
                raise

    def stop(self) -> None:
        """Terminate and reap every worker (SIGKILL for one that ignores SIGTERM)."""
        with self._lock:
            self._stop_locked()

    def _stop_locked(self) -> None:
        workers, self._workers = self._workers, []
        for p in workers:
            if p.is_alive():
                p.terminate()
        deadline = time.monotonic() + _STOP_GRACE_S
        for p in workers:
            p.join(max(deadline - time.monotonic(), 0.0))
            if p.is_alive():
                p.kill()
                p.join()
            p.close()


@contextmanager
def cpu_load(n: int) -> Iterator[CpuLoad]:
    """Run the body beside ``n`` busy processes (0: none); see the module's docstring for
    how they are stopped.  The SIGTERM handler is installed only from the main thread."""
    load = CpuLoad(n)
    previous: Any = None
    handled = n > 0 and threading.current_thread() is threading.main_thread()

    def on_term(signum: int, frame: FrameType | None) -> None:
        load.stop()
        if callable(previous):
            previous(signum, frame)
        elif previous != signal.SIG_IGN:
            raise SystemExit(128 + signum)

    if handled:
        previous = signal.signal(signal.SIGTERM, on_term)
    try:
        load.start()
        yield load
    finally:
        load.stop()
        if handled:  # a handler installed outside Python reads as None: default then
            signal.signal(signal.SIGTERM, signal.SIG_DFL if previous is None else previous)

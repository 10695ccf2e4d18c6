"""``stationd.sim.load``: N busy processes for a ``with``, none left behind however it ends."""

import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

from stationd.sim.load import CpuLoad, cpu_load

ROOT = Path(__file__).resolve().parents[2]


def _running(pid):
    """Whether ``pid`` is a live process (not a zombie waiting to be reaped)."""
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except (FileNotFoundError, ProcessLookupError):
        return False
    return state not in ("Z", "X")


def _gone(pids, within=10.0):
    """Wait (bounded) until none of ``pids`` runs; the ones still running."""
    end = time.monotonic() + within
    while (alive := [p for p in pids if _running(p)]) and time.monotonic() < end:
        time.sleep(0.05)
    return alive


def _cpu_ticks(pid):
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return int(fields[11]) + int(fields[12])  # utime + stime


def test_starts_n_busy_processes_and_stops_them_all():
    with cpu_load(2) as load:
        pids = load.pids
        assert len(pids) == 2 and os.getpid() not in pids and all(map(_running, pids))
        before = [_cpu_ticks(p) for p in pids]
        end = time.monotonic() + 60          # they spin: each gets CPU (later when busy)
        while not (spun := all(_cpu_ticks(p) > b for p, b in zip(pids, before, strict=True))) \
                and time.monotonic() < end:
            time.sleep(0.05)
        assert spun
    assert load.pids == [] and _gone(pids, within=0.0) == []  # reaped before the with ends
    assert signal.getsignal(signal.SIGTERM) == signal.SIG_DFL  # the handler is given back


def test_an_exception_in_the_body_stops_them_too():
    with pytest.raises(RuntimeError, match="demo failed"), cpu_load(1) as load:
        pids = load.pids
        raise RuntimeError("demo failed")
    assert len(pids) == 1 and _gone(pids, within=0.0) == []


def test_zero_is_no_load_and_bad_counts_are_refused():
    with cpu_load(0) as load:
        assert load.pids == []
    for bad in (-1, 65, 1.5, True):
        with pytest.raises(ValueError, match="number of busy processes"):
            CpuLoad(bad)


SCRIPT = textwrap.dedent("""
    import time
    from stationd.sim.load import cpu_load
    with cpu_load(2) as load:
        print(*load.pids, flush=True)
        time.sleep(60)
""")


@pytest.mark.parametrize("sig,status", [(signal.SIGTERM, 143), (signal.SIGKILL, -signal.SIGKILL)])
def test_sigterm_or_sigkill_of_the_parent_leaves_no_worker(sig, status):
    """SIGTERM: the workers are stopped and the process exits 143; SIGKILL (no cleanup at
    all): the workers notice their parent is gone and exit."""
    proc = subprocess.Popen([sys.executable, "-c", SCRIPT], cwd=ROOT, stdout=subprocess.PIPE,
                            text=True)
    try:
        pids = [int(p) for p in proc.stdout.readline().split()]
        assert len(pids) == 2 and all(map(_running, pids))
        proc.send_signal(sig)
        assert proc.wait(10) == status
        assert _gone(pids) == []
    finally:
        proc.kill()
        proc.wait()
        proc.stdout.close()

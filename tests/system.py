"""The suite's two speeds: unit and contract tests, and system tests.

``pytest -m "not system"`` runs the unit and contract tests (a function, a file, a device's
protocol against its simulator on loopback, the screens' server in the test process): under
a minute and a half on two cores four at a time (``-n 4``: they wait on devices' timeouts
much of their time; README: the figures).  ``pytest`` runs every test.  A **system
test** starts

* a whole daemon: the station's loop (``Station.run``; a station demo runs it too), or
  ``stationd run`` as systemd does,
* a demo (``stationd demo``; the vision demo's run, which renders its frames, is named),
* a browser (Chromium, Firefox) or a server: PostgreSQL, the OPC UA server with a client,
* another Python process: the commands as a user runs them (``python -m stationd ...``,
  ``stationd ...``), the simulators' processes, the checks of the whole tree (mypy,
  import-linter),

or belongs to a module of such tests.  ``tests/conftest.py`` marks it ``system``, before any
test runs (``pytest -m`` selects on that): by the fixtures it uses (:data:`FIXTURES`), by its
module (:data:`MODULES`), by its name (:data:`TESTS`: where a module mixes the two kinds), or
by ``@pytest.mark.system`` on the test.  That this marking is complete is checked while the
tests run (:class:`Guard`): a test that is not marked and starts one of the above fails,
naming what it started and how to mark it, so no test can be filed with the fast ones by
mistake.
"""

from __future__ import annotations

import functools
import importlib.abc
import importlib.machinery
import os
import re
import shlex
import shutil
import subprocess
import sys
from collections.abc import Callable, Sequence
from pathlib import Path
from types import ModuleType
from typing import Any

import pytest

HERE = Path(__file__).resolve().parent

#: fixtures that make a test a system test: a browser (``tests/web/conftest.py``), the test
#: process's PostgreSQL server (``tests/conftest.py``)
FIXTURES = frozenset({"page", "browsers", "shots", "pg_server", "pg_url"})

#: folders (ending in /) and modules under tests/ whose every test is a system test
MODULES: tuple[str, ...] = (
    "demo/",                                   # the demos
    # whole daemons: in the test process (tests/shell/daemons.py) or as systemd runs them
    "shell/test_calibration_daemon.py", "shell/test_commands_daemon.py",
    "shell/test_curves_daemon.py", "shell/test_daemon_faults.py", "shell/test_faults.py",
    "shell/test_gaps_daemon.py", "shell/test_idle.py", "shell/test_nok_daemon.py",
    "shell/test_operator_daemon.py", "shell/test_records.py",
    "shell/test_reload_results.py", "shell/test_restart.py",
    "shell/test_result_types_daemon.py", "shell/test_station_sim.py",
    "shell/test_keeper_hil.py", "opcua/test_daemon.py", "shell/test_serve_opcua.py",
    "sim/test_in_daemon.py",
    "test_forward_daemon.py",
    "shell/test_serve.py", "shell/test_serve_devicelocks.py", "shell/test_early_sighup.py",
    "test_teach_cli.py", "test_teach_hangup.py",
    "test_refcheck_cli.py",
    # the OPC UA server on loopback with an MES's client (in this process or its own)
    "opcua/test_server.py", "opcua/test_catchup.py", "opcua/test_curves.py",
    "opcua/test_security.py", "opcua/test_health.py", "opcua/test_dictionary.py",
    "opcua/test_stacks.py", "opcua/test_model.py",
    # the benchmarks' runs (a daemon, a PostgreSQL, a shift with disturbances)
    "bench/test_bench.py", "bench/test_line_bench.py", "bench/test_linkcut_bench.py",
    "bench/test_services.py", "bench/test_soak.py", "bench/test_station_bench.py",
    # the commands and the simulators as processes of their own
    "sim/test_devices_cli.py", "sim/test_load.py", "test_signals.py", "test_command_cli.py",
    "test_pgserver.py", "db/test_crash.py", "test_bootstrap.py", "test_systemd.py",
)

#: single tests, ``MODULE::NAME`` (parameters and all), in modules that mix the two kinds
#: (or ``@pytest.mark.system`` on the test itself)
TESTS: tuple[str, ...] = (
    "test_cli.py::test_console_script_usage_error_is_one_line",
    "test_cli.py::test_db_report_into_a_closed_pipe_is_quiet",
    "test_cli.py::test_demo_vision_save_writes_by_the_one_output_rule",
    "db/test_db_cli.py::test_reports_and_exports_open_the_database_read_only",
    "db/test_quality.py::test_spc_groups_by_bolt_and_pset_on_measured_results_and_counts_noks",
    "db/test_quality.py::test_a_parameter_change_starts_a_new_group_and_an_unknown_model_is_bad_input",
    "test_probe.py::test_probe_of_a_device_a_daemon_drives_is_refused_before_touching_it",
    "test_probe.py::test_probe_of_a_device_another_probe_holds_says_so",
    "test_imageio.py::test_detect_of_a_truncated_png_or_a_station_file_is_one_line_without_opencvs",
    "test_quality.py::test_mypy_clean",
    "test_quality.py::test_layers_hold",
    "test_lock.py::test_a_second_holder_is_refused_with_the_holders_pid",
    "test_lock.py::test_a_killed_holder_leaves_no_stale_lock",
    "test_lock.py::test_a_device_another_daemon_drives_is_refused_naming_its_pid_and_the_device",
    "test_lock.py::test_a_reload_takes_the_new_device_first_and_keeps_the_old_when_refused",
    "test_forward.py::test_a_line_database_that_is_not_postgresql_is_refused_by_the_check_and_the_start",
    "test_forward.py::test_the_line_commands_never_make_a_station_database_and_say_an_empty_quarantine",
    "drivers/wrench/sim/test_revisions.py::test_the_entry_point_serves_an_integrator",
    "drivers/wrench/sim/test_revisions.py::test_the_entry_point_says_what_is_wrong",
    "drivers/camera/test_aravis_modes.py::test_shutdown_order_at_process_end",
    "web/test_bench.py::test_screen_clients_under_sched_idle_run_every_browser_process_so",
)

#: programs that are a browser, a server or another client stack when a test starts them
SERVERS = frozenset({"chromium", "chromedriver", "firefox", "firefox-esr", "geckodriver",
                     "postgres", "initdb", "pg_ctl", "pg_ctlcluster", "node", "npm"})

MARK_HINT = ("a system test: name it in tests.system.TESTS or its module in MODULES, or "
             "mark it @pytest.mark.system")


def check_lists() -> None:
    """Every folder, module and test named in :data:`MODULES` and :data:`TESTS` exists (a
    renamed one would leave its tests unmarked: the guard would then fail them; this says
    why, before any test runs)."""
    gone = [m for m in MODULES if not (HERE / m).exists()]
    for name in TESTS:
        module, _, test = name.partition("::")
        path = HERE / module
        if not path.is_file() or not re.search(rf"^(async )?def {re.escape(test)}\(",
                                               path.read_text(), re.MULTILINE):
            gone.append(name)
    if gone:
        raise pytest.UsageError(f"tests/system.py names what does not exist: {gone}")


def is_system(item: pytest.Item) -> bool:
    """Whether ``item`` is a system test by its marker, its fixtures or its module."""
    if item.get_closest_marker("system") is not None:
        return True
    if FIXTURES.intersection(getattr(item, "fixturenames", ())):
        return True
    rel = Path(str(item.path)).resolve().relative_to(HERE).as_posix()
    if f"{rel}::{getattr(item, 'originalname', item.name)}" in TESTS:
        return True
    return any(rel == m or (m.endswith("/") and rel.startswith(m)) for m in MODULES)


def _argv(args: Any, shell: bool) -> list[str]:
    if isinstance(args, (str, bytes, os.PathLike)):
        text = os.fsdecode(args)
        return shlex.split(text) if shell else [text]
    return [os.fsdecode(a) for a in args]


def _is_python(program: str) -> bool:
    """Whether ``program`` is a Python interpreter or a script run by one (the venv's
    ``stationd``, ``mypy``, ``lint-imports``)."""
    path = shutil.which(program) or program
    if re.fullmatch(r"python[0-9.]*", os.path.basename(os.path.realpath(path))):
        return True
    try:
        with open(path, "rb") as f:
            head = f.readline(200)
    except OSError:
        return False
    return head.startswith(b"#!") and b"python" in head


def system_process(args: Any, executable: Any = None, shell: bool = False) -> str | None:
    """What a child process with ``args`` is, when it makes a test a system test (None: it
    does not, e.g. ``dpkg -L``, ``ruff``, ``mbpoll``)."""
    argv = _argv(args, shell)
    if not argv:
        return None
    program = os.fsdecode(executable) if executable is not None else argv[0]
    shown = " ".join(a if len(a) <= 40 else a[:37] + "..." for a in argv[:4]) + (
        " ..." if len(argv) > 4 else "")
    if SERVERS.intersection(os.path.basename(a) for a in (program, *argv)):
        return f"a browser, a server or another client stack ({shown})"
    if _is_python(program):
        return f"another Python process ({shown})"
    return None


class Guard:
    """Fails a test not marked system that starts what makes a test a system test.  The
    checks are installed once per test process (:meth:`install`); :meth:`enter` and
    :meth:`leave` say which test runs (its fixtures' setup and teardown included)."""

    def __init__(self) -> None:
        self.item: pytest.Item | None = None
        self.system = True          # outside a test (collection, xdist's own processes)
        self.seen: dict[str, list[str]] = {}   # nodeid -> what it started unmarked

    def enter(self, item: pytest.Item) -> None:
        self.item, self.system = item, is_system(item)

    def leave(self) -> None:
        self.item, self.system = None, True

    def starting(self, what: str) -> None:
        if self.system or self.item is None:
            return
        self.seen.setdefault(self.item.nodeid, []).append(what)
        pytest.fail(f"{self.item.nodeid} starts {what}: it is {MARK_HINT} (tests/system.py)",
                    pytrace=False)

    def install(self) -> None:
        popen_init = subprocess.Popen.__init__
        guard = self

        @functools.wraps(popen_init)
        def init(self: subprocess.Popen[Any], args: Any, *a: Any, **kw: Any) -> None:
            if not guard.system:
                what = system_process(args, kw.get("executable"), bool(kw.get("shell")))
                if what is not None:
                    guard.starting(what)
            popen_init(self, args, *a, **kw)

        subprocess.Popen.__init__ = init  # type: ignore[method-assign]
        after_import("stationd.shell.daemon", self._daemon)
        after_import("stationd.opcua.server", self._opcua)

    def _daemon(self, module: ModuleType) -> None:
        station = module.Station
        run = station.run
        guard = self

        @functools.wraps(run)
        async def guarded(self: Any, *a: Any, **kw: Any) -> Any:
            guard.starting("a whole daemon (the station's loop, Station.run)")
            return await run(self, *a, **kw)

        station.run = guarded

    def _opcua(self, module: ModuleType) -> None:
        server = module.OpcUaServer
        start = server.start
        guard = self

        @functools.wraps(start)
        async def guarded(self: Any, *a: Any, **kw: Any) -> Any:
            guard.starting("a server (OPC UA, OpcUaServer.start)")
            return await start(self, *a, **kw)

        server.start = guarded


class _AfterImport(importlib.abc.MetaPathFinder):
    """Calls ``patch(module)`` once module ``name`` has been imported (the guard patches
    what it checks without importing it into every test process)."""

    def __init__(self, name: str, patch: Callable[[ModuleType], None]) -> None:
        self.name, self.patch = name, patch

    def find_spec(self, fullname: str, path: Sequence[str] | None,
                  target: ModuleType | None = None) -> importlib.machinery.ModuleSpec | None:
        if fullname != self.name:
            return None
        for finder in sys.meta_path:
            if finder is self or not hasattr(finder, "find_spec"):
                continue
            spec = finder.find_spec(fullname, path, target)
            if spec is not None and spec.loader is not None:
                break
        else:
            return None
        loader, patch = spec.loader, self.patch
        exec_module = loader.exec_module

        def run(module: ModuleType) -> None:
            exec_module(module)
            patch(module)

        loader.exec_module = run  # type: ignore[method-assign]
        sys.meta_path.remove(self)   # once
        return spec


def after_import(name: str, patch: Callable[[ModuleType], None]) -> None:
    """``patch(module)`` now if ``name`` is imported, else as soon as it is."""
    if name in sys.modules:
        patch(sys.modules[name])
    else:
        sys.meta_path.insert(0, _AfterImport(name, patch))

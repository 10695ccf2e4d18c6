"""The suite's two speeds (tests/system.py): what makes a test a system test is decided the
same way for every test, and the lists that name modules and tests name ones that exist."""

from __future__ import annotations

import sys

import pytest

from tests.system import FIXTURES, check_lists, system_process


def test_another_python_process_a_browser_or_a_server_is_system_other_programs_are_not():
    assert system_process([sys.executable, "-m", "stationd", "db", "report"]) is not None
    assert system_process(["python3", "-c", "pass"]) is not None
    assert system_process(f"{sys.executable} -m stationd demo", shell=True) is not None  # noqa: S604
    assert system_process(["chromium", "--headless"]) is not None
    assert system_process(["/usr/lib/postgresql/15/bin/pg_ctl", "start"]) is not None
    assert system_process(["runuser", "-u", "postgres", "--", "/usr/bin/initdb"]) is not None
    for program in (["dpkg", "-L", "opencv-doc"], ["mbpoll", "-1"], ["true"]):
        assert system_process(program) is None, program


def test_a_script_run_by_python_is_another_python_process(tmp_path):
    script = tmp_path / "tool"
    script.write_text("#!/usr/bin/env python3\nprint(1)\n")
    shell = tmp_path / "other"
    shell.write_text("#!/bin/sh\necho 1\n")
    assert system_process([str(script)]) is not None
    assert system_process([str(shell)]) is None


def test_the_lists_name_what_exists():
    check_lists()
    assert {"page", "browsers", "pg_server", "pg_url"} <= FIXTURES


@pytest.mark.system
def test_the_marker_is_registered_and_selectable(request):
    assert request.node.get_closest_marker("system") is not None

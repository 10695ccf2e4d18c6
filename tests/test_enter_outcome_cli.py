"""``stationd enter-outcome``'s bad input, refused in one line before any daemon is asked (exit
2, no traceback): the verdict missing or both, a torque or angle that is no number a
controller shows, no comment saying what was checked."""

from __future__ import annotations

import pytest

from stationd.cli import main

#: nothing listens here: a command that got past its checks would say no daemon answers (3)
URL = "http://127.0.0.1:9/"
GOOD = ["VIN1", "B05", "--torque", "49.6", "--angle", "31", "--comment", "read there",
        "--user", "sam", "--url", URL]


@pytest.mark.parametrize(("args", "said"), [
    (GOOD, "one of the arguments --ok --nok is required"),
    ([*GOOD, "--ok", "--nok"], "not allowed with argument"),
    ([*GOOD[:2], "--ok", "--angle", "31", "--comment", "x", "--user", "sam"],
     "--torque"),
    ([*GOOD, "--ok", "--torque", "nan"], "--torque nan: a number from 0 to 100000"),
    ([*GOOD, "--ok", "--torque", "-1"], "--torque -1: a number from 0 to 100000"),
    ([*GOOD, "--ok", "--angle", "inf"], "--angle inf"),
    ([*GOOD, "--ok", "--torque", "lots"], "invalid float value: 'lots'"),
    ([*GOOD, "--nok", "--comment", " "], "--comment: what was checked on the controller"),
    # required, and said so by --help (a quality trial: shown optional, then refused)
    ([*GOOD[:6], "--nok", "--user", "sam"], "required: --comment"),
    ([*GOOD, "--nok", "--comment", "x" * 501], "--comment: at most 500 characters"),
    (["VIN1", " ", *GOOD[2:], "--ok"], "bolt ' '"),
])
def test_bad_input_is_one_line_and_exit_2(args, said, capsys):
    with pytest.raises(SystemExit) as exc:     # argparse's own refusals exit by themselves
        raise SystemExit(main(["enter-outcome", *args]))
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert said in err and "Traceback" not in err

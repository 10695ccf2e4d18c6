"""``python -m stationd.sim.timing``: bad arguments are one line and exit 2 (the measurement
itself renders 20 MP frames: it is a benchmark, run by hand)."""

from stationd.sim.timing import main


def test_bad_arguments_are_one_line_and_exit_2(capsys):
    for argv in (["--frames", "0"], ["--hold", "0"], ["--load", "65"], ["--load", "-1"]):
        assert main(argv) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and "--frames is 1-1000" in err

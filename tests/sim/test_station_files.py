"""``python -m stationd.sim.station_files``: its options.  The one argument was taken as the
folder whatever it was: ``--help`` printed "wrote 10 files to --help" and made that folder."""

from __future__ import annotations

import pytest

from stationd.sim.station_files import files, main


@pytest.mark.parametrize("option", ["--help", "-h"])
def test_help_prints_the_usage_and_writes_nothing(tmp_path, monkeypatch, capsys, option):
    monkeypatch.chdir(tmp_path)
    with pytest.raises(SystemExit) as ei:
        main([option])
    assert ei.value.code == 0
    out = capsys.readouterr().out
    assert out.startswith("usage: python -m stationd.sim.station_files [-h] [FOLDER]")
    assert "wrote" not in out
    assert list(tmp_path.iterdir()) == []


def test_an_unknown_option_is_refused_in_one_line_and_writes_nothing(tmp_path, monkeypatch,
                                                                    capsys):
    monkeypatch.chdir(tmp_path)
    with pytest.raises(SystemExit) as ei:
        main(["--bogus"])
    assert ei.value.code == 2
    err = capsys.readouterr().err
    assert err == "python -m stationd.sim.station_files: error: unrecognized arguments: " \
                  "--bogus (see --help)\n"
    assert list(tmp_path.iterdir()) == []


def test_a_folder_gets_the_files(tmp_path, capsys):
    target = tmp_path / "sim"
    assert main([str(target)]) == 0
    assert sorted(p.name for p in target.iterdir()) == sorted(files())
    assert capsys.readouterr().out == f"wrote {len(files())} files to {target}\n"

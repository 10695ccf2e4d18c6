"""``stationd teach``'s last step (``stationd.teach_cli.finish``): the taught table is
written, and it reads as ready only when the spacing rule holds; otherwise exit 1, naming
the pair, while the measurements stay in the file."""

from __future__ import annotations

import yaml

from stationd.teach_cli import finish

CAD = {"models": {"SIM-1": {"bolts": [
    {"id": "B01", "position": [0.0, 0.0, 0.0], "pset": 1},
    {"id": "B02", "position": [100.0, 0.0, 0.0], "pset": 1}]}}}


def _taught(x2: float) -> dict[str, dict[str, object]]:
    return {"B01": {"position_mm": [0.4, 0.0, 0.0], "dispersion_mm": 0.1},
            "B02": {"position_mm": [x2, 0.0, 0.0], "dispersion_mm": 0.1}}


def test_a_table_within_the_spacing_rule_is_ready(tmp_path, capsys):
    out = tmp_path / "taught.yaml"
    cad_at = {b["id"]: b["position"] for b in CAD["models"]["SIM-1"]["bolts"]}
    assert finish(out, CAD, "SIM-1", _taught(100.2), cad_at, 8.0) == 0
    said = capsys.readouterr()
    assert "2 bolts taught" in said.out and "reload" in said.out and not said.err
    bolts = yaml.safe_load(out.read_text())["models"]["SIM-1"]["bolts"]
    assert bolts[1]["position"] == [100.2, 0.0, 0.0]


def test_a_table_breaking_the_spacing_rule_is_written_but_not_ready(tmp_path, capsys):
    out = tmp_path / "taught.yaml"
    cad_at = {b["id"]: b["position"] for b in CAD["models"]["SIM-1"]["bolts"]}
    assert finish(out, CAD, "SIM-1", _taught(0.4), cad_at, 8.0) == 1
    said = capsys.readouterr()
    assert "spacing: B01 and B02 are 0.0 mm apart" in said.out
    assert "NOT READY" in said.err and "reload" not in said.out
    assert out.exists()     # the measurements are kept


def test_positions_alone_say_they_are_merged_by_hand(tmp_path, capsys):
    out = tmp_path / "taught.yaml"
    assert finish(out, {}, "SIM-1", _taught(100.2), {}, None) == 0
    assert "merge them into the bolt table by hand" in capsys.readouterr().out

"""Quality figures from the records: Cp/Cpk per bolt and pset on every measured tightening
(OK and NOK) against the limits sent, the NOK trend; and `stationd db spc`."""

from __future__ import annotations

import json
import math
import subprocess
import sys

import numpy as np
import pytest

from db.quality import capability
from stationd.boltfile import import_bolts
from tests.db.conftest import ROOT, record, url_of


def test_capability_is_the_textbook_formula_and_none_without_enough_results():
    v = [49.0, 50.0, 51.0, 50.0, 50.5, 49.5]
    got = capability(v, 45.0, 55.0)
    sigma = float(np.std(v, ddof=1))
    assert got["cp"] == pytest.approx(10 / (6 * sigma))
    assert got["cpk"] == pytest.approx(min(55 - np.mean(v), np.mean(v) - 45) / (3 * sigma))
    off = capability([x + 3 for x in v], 45.0, 55.0)        # off centre: Cpk below Cp
    assert off["cpk"] < off["cp"] == pytest.approx(got["cp"])
    assert capability(v[:4], 45.0, 55.0)["cp"] is None      # too few
    assert capability([50.0] * 6, 45.0, 55.0)["cp"] is None  # no spread
    assert capability(v, None, 55.0)["cpk"] is None


def test_spc_groups_by_bolt_and_pset_on_measured_results_and_counts_noks(repo, bolts_file,
                                                                          tmp_path):
    import_bolts(repo, bolts_file)
    rng = np.random.default_rng(3)
    for k in range(3):
        repo.start_vehicle(f"VIN{k}", "SEDAN")
        for i in range(4):
            record(repo, f"VIN{k}", "B1", tightening_id=100 * k + i,
                   torque_nm=float(rng.normal(50, 1)), angle_deg=35.0 + i)
        record(repo, f"VIN{k}", "B2", ok=False, tightening_id=100 * k + 9)
    doc = repo.spc()
    b1 = next(r for r in doc["bolts"] if r["bolt"] == "B1")
    assert b1["torque"]["n"] == 12 and b1["nok"] == 0
    assert b1["torque"]["lsl"] == 45 and b1["torque"]["usl"] == 55
    assert b1["torque"]["cpk"] is not None and math.isfinite(b1["torque"]["cpk"])
    b2 = next(r for r in doc["bolts"] if r["bolt"] == "B2")
    assert b2["nok"] == 3 and b2["torque"]["n"] == 3 and b2["torque"]["cp"] is None
    [day] = doc["trend"]
    assert (day["results"], day["nok"]) == (15, 3) and day["nok_rate"] == pytest.approx(0.2)
    assert repo.spc(model="WAGON")["bolts"] == []
    db = url_of(tmp_path / "station.db")
    out = subprocess.run([sys.executable, "-m", "stationd", "db", "spc", "--db", db, "--json"],
                         capture_output=True, text=True, cwd=ROOT, timeout=60, check=False)
    assert out.returncode == 0, out.stderr
    assert json.loads(out.stdout)["trend"][0]["nok"] == 3
    text = subprocess.run([sys.executable, "-m", "stationd", "db", "spc", "--db", db],
                          capture_output=True, text=True, cwd=ROOT, timeout=60, check=False)
    assert text.returncode == 0 and "B1" in text.stdout and "20.0 %" in text.stdout
    head = text.stdout.splitlines()[0].split()
    assert head[:5] == ["model", "bolt", "pset", "n", "NOK"]     # counts named by kind
    assert head[6:12] == ["torque", "Nm", "mean", "s", "Cp", "Cpk"]
    assert head[12:] == ["angle", "deg", "mean", "s", "Cp", "Cpk"]
    [b2_row] = [line.split() for line in text.stdout.splitlines() if " B2 " in f" {line} "]
    assert b2_row[3:5] == ["3", "3"]
    [b1_row] = [line.split() for line in text.stdout.splitlines() if " B1 " in f" {line} "]
    assert b1_row[6] == "45.0-55.0" and b1_row[10].endswith("*")   # 12 results: rough
    assert "* from fewer than 25 results: a rough figure" in text.stdout
    assert "(UTC): 15 results, 3 NOK (20.0 %)" in text.stdout


def test_the_noks_of_a_bolt_are_in_its_capability_as_its_oks_are(repo, bolts_file):
    """A quality trial: a bolt's OK results, cut at the limits, read Cpk 1.91; with its NOKs
    (the process made them too) 0.32.  An outcome a person entered stays out."""
    import_bolts(repo, bolts_file)
    repo.start_vehicle("VINQ", "SEDAN")
    oks = [49.0, 50.0, 51.0, 50.5, 49.5, 50.0]
    for i, t in enumerate(oks):
        record(repo, "VINQ", "B1", tightening_id=i + 1, torque_nm=t)
    record(repo, "VINQ", "B1", ok=False, tightening_id=20, torque_nm=57.5)   # above 55
    [b1] = [r for r in repo.spc()["bolts"] if r["bolt"] == "B1"]
    everything = capability([*oks, 57.5], 45.0, 55.0)
    assert b1["torque"]["n"] == 7 and b1["nok"] == 1
    assert b1["torque"]["cpk"] == pytest.approx(everything["cpk"])
    assert b1["torque"]["cpk"] < capability(oks, 45.0, 55.0)["cpk"] / 2


def test_a_parameter_change_starts_a_new_group_and_an_unknown_model_is_bad_input(
        repo, bolts_file, tmp_path):
    from tests.db.conftest import BASE

    import_bolts(repo, bolts_file)
    repo.start_vehicle("VINP1", "SEDAN")
    record(repo, "VINP1", "B1", tightening_id=1, torque_nm=50.0)
    bolts_file.write_text(BASE.replace("target: 50, min: 45, max: 55",
                                       "target: 52, min: 47, max: 57"))
    import_bolts(repo, bolts_file)
    repo.start_vehicle("VINP2", "SEDAN")
    record(repo, "VINP2", "B1", tightening_id=2, torque_nm=52.0)
    b1 = [r for r in repo.spc()["bolts"] if r["bolt"] == "B1"]
    assert sorted((r["torque"]["lsl"], r["torque"]["usl"]) for r in b1) == [(45, 55), (47, 57)]
    # the text's two rows of B1 are told apart: the version and the torque limits
    text = subprocess.run([sys.executable, "-m", "stationd", "db", "spc", "--db",
                           url_of(tmp_path / "station.db")],
                          capture_output=True, text=True, cwd=ROOT, timeout=60, check=False)
    rows = [line.split() for line in text.stdout.splitlines() if " B1 " in f" {line} "]
    assert text.stdout.splitlines()[0].split()[5:7] == ["v", "torque"]
    assert sorted((r[5], r[6]) for r in rows) == [("1", "45.0-55.0"), ("2", "47.0-57.0")]
    out = subprocess.run([sys.executable, "-m", "stationd", "db", "spc", "--db",
                          url_of(tmp_path / "station.db"), "--model", "NOPE"],
                         capture_output=True, text=True, cwd=ROOT, timeout=60, check=False)
    assert out.returncode == 2 and "no such model" in out.stderr


def test_each_group_carries_its_last_results_ok_and_nok_and_the_limits_of_its_version(
        repo, bolts_file):
    from tests.db.conftest import BASE

    import_bolts(repo, bolts_file)
    rng = np.random.default_rng(21)
    sent = []                                   # (torque, angle, ok) in the order recorded
    repo.start_vehicle("VINL1", "SEDAN")
    for i in range(35):
        ok = bool(rng.random() > 0.2)
        torque, angle = float(rng.normal(50, 1.5)), float(rng.normal(35, 4))
        record(repo, "VINL1", "B1", ok=ok, tightening_id=i, torque_nm=torque, angle_deg=angle)
        sent.append((torque, angle, ok))
    record(repo, "VINL1", "B2", ok=False, tightening_id=99, torque_nm=None, angle_deg=None)
    # version 2: only the target moves (the limits in force differ, so a new group)
    bolts_file.write_text(BASE.replace("target: 50, min: 45, max: 55",
                                       "target: 51, min: 45, max: 55"))
    import_bolts(repo, bolts_file)
    repo.start_vehicle("VINL2", "SEDAN")
    record(repo, "VINL2", "B1", tightening_id=200, torque_nm=51.0, angle_deg=33.0)
    # version 3: min and max too
    bolts_file.write_text(BASE.replace("target: 50, min: 45, max: 55",
                                       "target: 52, min: 47, max: 57"))
    import_bolts(repo, bolts_file)
    repo.start_vehicle("VINL3", "SEDAN")
    record(repo, "VINL3", "B1", ok=False, tightening_id=300, torque_nm=58.5, angle_deg=70.0)
    record(repo, "VINL3", "B1", tightening_id=301, torque_nm=52.2, angle_deg=36.0)

    b1 = [r for r in repo.spc()["bolts"] if r["bolt"] == "B1"]
    assert [r["parameter_version"] for r in b1] == [1, 2, 3]
    assert [r["limits"]["torque"] for r in b1] == [
        {"min": 45, "target": 50, "max": 55}, {"min": 45, "target": 51, "max": 55},
        {"min": 47, "target": 52, "max": 57}]
    assert all(r["limits"]["angle"] == {"min": 15, "target": 30, "max": 60} for r in b1)
    # the last 30 of 35, oldest first, NOKs included; the figures use every measured result
    v1 = b1[0]
    assert len(v1["last"]) == 30
    assert [p["ok"] for p in v1["last"]] == [ok for _, _, ok in sent[-30:]]
    assert [p["torque"] for p in v1["last"]] == pytest.approx([t for t, _, _ in sent[-30:]])
    assert [p["angle"] for p in v1["last"]] == pytest.approx([a for _, a, _ in sent[-30:]])
    assert v1["torque"]["n"] == len(sent)
    assert v1["nok"] == sum(not ok for _, _, ok in sent) > 0
    ats = [p["at"] for p in v1["last"]]
    assert ats == sorted(ats) and all("T" in a for a in ats)
    assert [(p["torque"], p["ok"]) for p in b1[1]["last"]] == [(51.0, True)]
    assert [(p["torque"], p["angle"], p["ok"]) for p in b1[2]["last"]] == [
        (58.5, 70.0, False), (52.2, 36.0, True)]
    # a NOK without values is still a result of the plot; B2's own limits, no pset
    b2 = next(r for r in repo.spc()["bolts"] if r["bolt"] == "B2")
    assert b2["pset"] is None and b2["limits"]["torque"] == {"min": 23, "target": 25, "max": 27}
    assert [(p["torque"], p["ok"]) for p in b2["last"]] == [(None, False)]
    # fewer asked for: the newest ones
    short = next(r for r in repo.spc(last=5)["bolts"] if r["bolt"] == "B1")
    assert [p["torque"] for p in short["last"]] == pytest.approx([t for t, _, _ in sent[-5:]])


def test_an_ok_entered_by_a_person_is_counted_apart_and_not_in_the_capability(
        repo, bolts_file, tmp_path, capsys):
    """A held bolt's outcome typed in from the controller's screen is no measurement: not in
    the mean, Cp or Cpk (a new user's trial: an entered 106.7 Nm in a bolt's mean); counted
    apart, marked in the plot's points, and in the day's results."""
    from datetime import UTC, datetime

    from db.entered import record_entered

    import_bolts(repo, bolts_file)
    repo.start_vehicle("VIN1", "SEDAN")
    for i, torque in enumerate((49.0, 50.0, 51.0, 50.0, 50.5, 49.5)):
        record(repo, "VIN1", "B1", tightening_id=i + 1, torque_nm=torque)
    before = repo.spc()["bolts"][0]["torque"]
    record_entered(repo, vin="VIN1", bolt="B1", ok=True, torque_nm=106.7, angle_deg=31.0,
                   at=datetime.now(UTC), user="sam", source="cli", comment="read on it")
    [b1] = [r for r in repo.spc()["bolts"] if r["bolt"] == "B1"]
    assert b1["torque"]["n"] == 6 and b1["torque"]["mean"] == pytest.approx(before["mean"])
    assert b1["entered_ok"] == 1 and b1["last"][-1]["entered"] is True
    assert not any(p["entered"] for p in b1["last"][:-1])
    assert repo.spc()["trend"][0]["results"] == 7
    from stationd import cli

    assert cli.main(["db", "spc", "--db", url_of(tmp_path / "station.db")]) == 0
    assert "SEDAN B1 pset 1: 1 OK entered by a person (not measured: not in n and the " \
        "figures)" in capsys.readouterr().out
    # an entered NOK: in the NOK column, said apart (a supervisor's trial: unsaid, it read
    # as a measured NOK missing from n)
    record_entered(repo, vin="VIN1", bolt="B1", ok=False, torque_nm=43.0, angle_deg=20.0,
                   at=datetime.now(UTC), user="sam", source="cli", comment="shows NOK")
    [b1] = [r for r in repo.spc()["bolts"] if r["bolt"] == "B1"]
    assert (b1["torque"]["n"], b1["nok"], b1["entered_ok"], b1["entered_nok"]) == (6, 1, 1, 1)
    assert cli.main(["db", "spc", "--db", url_of(tmp_path / "station.db")]) == 0
    assert "SEDAN B1 pset 1: 1 OK and 1 NOK entered by a person (not measured: not in n and " \
        "the figures; the NOK column counts them)" in capsys.readouterr().out
    # nothing in the span asked for: said, not a header alone (a supervisor's trial)
    assert cli.main(["db", "spc", "--db", url_of(tmp_path / "station.db"), "--since",
                     "2030-01-01"]) == 0
    assert capsys.readouterr().out == ("no tightening results since 2030-01-01T00:00:00+00:00: "
                                       "nothing to compute\n")

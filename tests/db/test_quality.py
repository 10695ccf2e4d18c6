"""Quality figures from the records: Cp/Cpk per bolt and pset on OK results against the
limits sent, the NOK trend; and `stationd db spc`."""

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


def test_spc_groups_by_bolt_and_pset_on_ok_results_and_counts_noks(repo, bolts_file, tmp_path):
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
    assert b2["nok"] == 3 and b2["torque"]["n"] == 0 and b2["torque"]["cp"] is None
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
    out = subprocess.run([sys.executable, "-m", "stationd", "db", "spc", "--db",
                          url_of(tmp_path / "station.db"), "--model", "NOPE"],
                         capture_output=True, text=True, cwd=ROOT, timeout=60, check=False)
    assert out.returncode == 2 and "no such model" in out.stderr

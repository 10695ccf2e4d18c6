"""The example station file documents every section: its optional ones (written as comments,
so the file checks clean without a line database, certificates or reference markers) read
without an error once uncommented, with the example's own pair and bolt table."""

from __future__ import annotations

import re
from pathlib import Path

from stationd.config import STATION_KEYS, load_station_config

ROOT = Path(__file__).resolve().parents[1]
EXAMPLE = ROOT / "config" / "station.example.yaml"


def _uncommented(text: str, sections: tuple[str, ...]) -> str:
    for name in sections:
        block = re.search(rf"^# {name}:\n(?:#   .*\n)+", text, re.M)
        assert block is not None, f"{name}: not in {EXAMPLE.name}"
        plain = re.sub(r"^# ?", "", block.group(0), flags=re.M)
        text = text.replace(block.group(0), plain)
    return text


def test_every_section_is_in_the_example_and_the_commented_ones_read(tmp_path):
    text = EXAMPLE.read_text()
    for key in STATION_KEYS:
        assert re.search(rf"^#? ?{key}:", text, re.M), f"{key}: not in {EXAMPLE.name}"
    optional = ("references", "nok", "line", "opcua", "http", "access", "localize")
    doc = _uncommented(text, optional)
    doc = doc.replace('password: "scrypt$16384$8$1$...$..."', "password: " + _hash())
    doc = doc.replace('users: {mes: "scrypt$16384$8$1$...$..."}', "users: {mes: " + _hash() + "}")
    doc = doc.replace("calibration: sim/", f"calibration: {ROOT}/config/sim/")
    doc = doc.replace("to_vehicle: sim/", f"to_vehicle: {ROOT}/config/sim/")
    doc = doc.replace("bolts: bolts.example.yaml", f"bolts: {ROOT}/config/bolts.example.yaml")
    path = tmp_path / "station.yaml"
    path.write_text(doc)
    cfg = load_station_config(path)
    assert cfg.references is not None and set(cfg.references.pairs) == {"front"}
    assert cfg.nok.default.loosen_pset == 90 and cfg.line is not None
    assert cfg.opcua is not None and cfg.opcua.certificates == Path("/var/lib/stationd/opcua")


def _hash() -> str:
    from stationd.access import hash_password

    return "'" + hash_password("an example password") + "'"

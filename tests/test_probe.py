"""``stationd probe``: real protocols on loopback, exit codes 0 / 1 / 2."""

import json
import socket

import pytest

from drivers.lift.sim import SimulatedPlc
from stationd.cli import main


def _free_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_probe_lift_reads_a_real_modbus_server(capsys):
    with SimulatedPlc() as plc:
        port = plc.start_tcp()
        plc.set_vehicle(7, "WVWZZZ1JZXW000001")
        plc.set_height(1800.0)
        code = main(["probe", "lift", f"modbus-tcp://127.0.0.1:{port}?unit=1", "--json"])
    obj = json.loads(capsys.readouterr().out)
    assert code == 0 and obj["ok"] is True
    assert obj["state"]["model_code"] == 7 and obj["state"]["vin"] == "WVWZZZ1JZXW000001"
    assert abs(obj["state"]["height_mm"] - 1800.0) < 0.1


def test_probe_lift_nothing_listening_exits_1(capsys):
    code = main(["probe", "lift", f"modbus-tcp://127.0.0.1:{_free_port()}?unit=1",
                 "--timeout", "0.5"])
    err = capsys.readouterr().err
    assert code == 1 and "refused" in err and err.count("\n") == 1


@pytest.mark.parametrize("url,needle", [("bogus://x", "unknown lift scheme"),
                                        ("modbus-tcp://127.0.0.1:502?unti=1", "unknown option")])
def test_probe_lift_bad_url_exits_2(capsys, url, needle):
    code = main(["probe", "lift", url])
    err = capsys.readouterr().err
    assert code == 2 and needle in err and err.count("\n") == 1


def test_station_config_lift_register_map(tmp_path):
    from stationd.config import load_station_config
    from stationd.errors import ConfigError

    cfg = tmp_path / "s.yaml"
    cfg.write_text("lift:\n  url: modbus-tcp://10.0.0.2:502?unit=3\n  registers:\n"
                   "    height: {address: 100}\n")
    lift = load_station_config(cfg).lift
    assert lift.url.startswith("modbus-tcp://") and lift.registers.height.address == 100
    cfg.write_text("lift:\n  registers:\n    heigth: {address: 100}\n")
    with pytest.raises(ConfigError, match=r"s.yaml:3: lift.registers.heigth: unknown key"):
        load_station_config(cfg)

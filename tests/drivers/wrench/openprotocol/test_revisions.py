"""MID 0061/0065 revisions 2-7 and MID 0002 revisions 1-7: parsed from messages written out
here by hand, parameter by parameter as the specification lists them (tag, then the value
typed out at its width), so the tables in ``op_result.py`` are checked against something
that does not share them."""

from __future__ import annotations

import re
from datetime import datetime

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from drivers.errors import ProtocolError
from drivers.wrench.base import ResultType, Status, TorqueUnit
from drivers.wrench.openprotocol.identity import parse_identity
from drivers.wrench.openprotocol.message import decode, identity, parse_result
from drivers.wrench.openprotocol.result import tagged_length
from drivers.wrench.sim.results import SimRecord, result_data
from drivers.wrench.sim.server import message

FAST = settings(max_examples=200, deadline=300, suppress_health_check=[HealthCheck.too_slow])

# MID 0061 revision 2, parameters 01-46, each value typed at its width
REV2 = [
    ("01", "0007"), ("02", "03"), ("03", "PF6000 Line 3".ljust(25)),
    ("04", "WVWZZZ1JZ3W386752".ljust(25)), ("05", "0012"), ("06", "005"), ("07", "02"),
    ("08", "00101"), ("09", "0004"), ("10", "0002"), ("11", "0"), ("12", "0"), ("13", "2"),
    ("14", "1"), ("15", "1"), ("16", "0"), ("17", "1"), ("18", "2"), ("19", "1"),
    ("20", "0000000008"),
    ("21", "002250"), ("22", "002750"), ("23", "002500"), ("24", "002790"),
    ("25", "00060"), ("26", "00120"), ("27", "00090"), ("28", "00097"),
    ("29", "00360"), ("30", "01800"), ("31", "00817"),
    ("32", "030"), ("33", "090"), ("34", "055"),
    ("35", "000000"), ("36", "000500"), ("37", "000150"),
    ("38", "000000"), ("39", "000300"), ("40", "000080"),
    ("41", "0000001234"), ("42", "00042"), ("43", "00000"), ("44", "B1234567890123"),
    ("45", "2025-03-14:08:15:42"), ("46", "2025-03-14:07:00:00"),
]
REV3 = [("47", "Wheel nut M14".ljust(25)), ("48", "1"), ("49", "02")]
REV4 = [("50", "PART-2".ljust(25)), ("51", "PART-3".ljust(25)), ("52", "".ljust(25))]
REV5 = [("53", "E042")]
REV6 = [("54", "000040"), ("55", "0000000016")]
REV7 = [("56", "0009730"), ("57", "0009725")]   # x 100, 7 digits (table 81)
APPENDED = [REV3, REV4, REV5, REV6, REV7]


def build(mid: int, revision: int, params: list[tuple[str, str]]) -> bytes:
    data = "".join(tag + value for tag, value in params)
    return f"{20 + len(data):04d}{mid:04d}{revision:03d}         {data}".encode()


def params_for(revision: int) -> list[tuple[str, str]]:
    out = list(REV2)
    for more in APPENDED[:revision - 2]:
        out += more
    return out


def test_documented_lengths():
    assert len(build(61, 2, REV2)) == 385          # the specification's 0061 revision 2
    assert len(build(61, 3, params_for(3))) == 419
    assert [tagged_length(61, r) for r in range(2, 8)] == [
        len(build(61, r, params_for(r))) for r in range(2, 8)]


def test_revision_2_reads_every_parameter():
    r = parse_result(build(61, 2, REV2))
    assert (r.revision, r.fetched, r.ok) == (2, False, False)
    assert (r.cell_id, r.channel_id, r.controller_name, r.vin, r.job, r.pset) == (
        7, 3, "PF6000 Line 3", "WVWZZZ1JZ3W386752", 12, 5)
    assert (r.strategy, r.strategy_options, r.batch_size, r.batch_counter,
            r.batch_status) == (2, 101, 4, 2, 0)
    assert (r.torque_status, r.angle_status) == (Status.HIGH, Status.OK)
    assert (r.rundown_angle_status, r.current_monitoring_status, r.selftap_status,
            r.prevail_torque_monitoring_status, r.prevail_torque_compensate_status) == (
        Status.OK, Status.LOW, Status.OK, Status.HIGH, Status.OK)
    assert r.tightening_error_status == 8
    assert (r.torque_min_nm, r.torque_max_nm, r.torque_target_nm, r.torque_nm) == (
        22.5, 27.5, 25.0, 27.9)
    assert (r.angle_min_deg, r.angle_max_deg, r.angle_target_deg, r.angle_deg) == (
        60.0, 120.0, 90.0, 97.0)
    assert (r.rundown_angle_min_deg, r.rundown_angle_max_deg, r.rundown_angle_deg) == (
        360.0, 1800.0, 817.0)
    assert (r.current_monitoring_min_pct, r.current_monitoring_max_pct,
            r.current_monitoring_pct) == (30.0, 90.0, 55.0)
    assert (r.selftap_min_nm, r.selftap_max_nm, r.selftap_nm) == (0.0, 5.0, 1.5)
    assert (r.prevail_torque_min_nm, r.prevail_torque_max_nm, r.prevail_torque_nm) == (
        0.0, 3.0, 0.8)
    assert (r.tightening_id, r.job_sequence_number, r.sync_tightening_id, r.tool_serial) == (
        1234, 42, 0, "B1234567890123")
    assert r.timestamp == datetime(2025, 3, 14, 8, 15, 42)
    assert r.pset_changed == datetime(2025, 3, 14, 7, 0, 0)
    assert (r.pset_name, r.torque_unit, r.result_type, r.identifiers) == ("", None, None, ())


@pytest.mark.parametrize("revision", [3, 4, 5, 6, 7])
def test_later_revisions_add_their_parameters(revision):
    r = parse_result(build(61, revision, params_for(revision)))
    assert r.revision == revision and r.tightening_id == 1234 and r.torque_nm == 27.9
    assert (r.pset_name, r.torque_unit, r.result_type) == (
        "Wheel nut M14", TorqueUnit.NM, ResultType.LOOSENING)
    assert r.identifiers == (("PART-2", "PART-3", "") if revision >= 4 else ())
    assert r.customer_error_code == ("E042" if revision >= 5 else "")
    assert (r.prevail_torque_compensate_nm, r.tightening_error_status2) == (
        (0.4, 16) if revision >= 6 else (None, None))
    assert (r.compensated_angle_deg, r.angle_decimal_deg) == (
        (97.3, 97.25) if revision == 7 else (None, None))


def test_parameters_are_read_by_tag_in_any_order():
    shuffled = list(reversed(params_for(7)))
    assert parse_result(build(61, 7, shuffled)) == parse_result(build(61, 7, params_for(7)))


def test_torques_are_converted_to_nm_from_the_controllers_unit():
    lbf_ft = [(t, "2" if t == "48" else v) for t, v in params_for(3)]
    r = parse_result(build(61, 3, lbf_ft))
    assert r.torque_unit is TorqueUnit.LBF_FT
    assert r.torque_nm == pytest.approx(27.9 * 1.3558179483, abs=1e-6)
    assert r.torque_max_nm == pytest.approx(27.5 * 1.3558179483, abs=1e-6)
    assert r.angle_deg == 97.0                                   # angles are not torques
    percent = [(t, "7" if t == "48" else v) for t, v in params_for(3)]
    assert parse_result(build(61, 3, percent)).torque_nm == 27.9   # not convertible: as sent


def test_an_unknown_result_type_or_unit_keeps_the_result():
    odd = [(t, "42" if t == "49" else "9" if t == "48" else v) for t, v in params_for(3)]
    r = parse_result(build(61, 3, odd))
    assert (r.result_type, r.torque_unit, r.tightening_id) == (None, None, 1234)


def test_optional_parameters_may_be_blank_core_ones_not():
    blank = [(t, " " * len(v) if t in ("31", "42", "46") else v) for t, v in REV2]
    r = parse_result(build(61, 2, blank))
    assert (r.rundown_angle_deg, r.job_sequence_number, r.pset_changed) == (None, None, None)
    no_torque = [(t, " " * 6 if t == "24" else v) for t, v in REV2]
    with pytest.raises(ProtocolError, match="MID 0061 revision 2 torque is empty"):
        parse_result(build(61, 2, no_torque))


@pytest.mark.parametrize(("params", "words"), [
    (REV2[:-1], "parameter missing: 46 (pset_changed)"),
    (params_for(3)[:-1], "parameter missing: 49 (result_type)"),
    ([*REV2, ("01", "0007")], "parameter 01 (cell_id) twice"),
    ([*REV2, ("58", "x")], "unknown parameter '58'"),
    ([(t, "x" * len(v) if t == "41" else v) for t, v in REV2],
     "tightening_id 'xxxxxxxxxx' is not a number"),
    ([(t, "5" if t == "13" else v) for t, v in REV2], "torque_status 5 is out of range"),
])
def test_bad_results_name_what_is_wrong(params, words):
    with pytest.raises(ProtocolError, match=re.escape(words)):
        parse_result(build(61, 2 if len(params) < 47 else 3, params))


def test_cut_short_and_unsupported_revisions():
    with pytest.raises(ProtocolError, match="cut short"):
        parse_result(build(61, 2, [*REV2[:-1], ("46", "2025-03-14")]))
    with pytest.raises(ProtocolError, match="revision 8 is not supported"):
        parse_result(build(61, 8, params_for(7)))


# MID 0065 revision 1: its own short list
OLD_REV1 = [("01", "0000001234"), ("02", "WVWZZZ1JZ3W386752".ljust(25)), ("03", "005"),
            ("04", "0002"), ("05", "1"), ("06", "1"), ("07", "1"), ("08", "002512"),
            ("09", "00097"), ("10", "2025-03-14:08:15:42"), ("11", "0")]


def test_old_result_revision_1_and_2():
    old1 = parse_result(build(65, 1, OLD_REV1))
    assert len(build(65, 1, OLD_REV1)) == 118
    assert (old1.fetched, old1.tightening_id, old1.vin, old1.pset, old1.batch_counter) == (
        True, 1234, "WVWZZZ1JZ3W386752", 5, 2)
    assert (old1.ok, old1.torque_nm, old1.angle_deg, old1.torque_min_nm) == (
        True, 25.12, 97.0, 0.0)                                 # rev 1 has no limits



# MID 0065 revision 2: a list of its own (the specification's table 86), not MID 0061's
OLD_REV2 = [("01", "0000001235"), ("02", "WVWZZZ1JZ3W386752".ljust(25)), ("03", "0012"),
            ("04", "005"), ("05", "02"), ("06", "00101"), ("07", "0004"), ("08", "0002"),
            ("09", "0"), ("10", "0"), ("11", "2"), ("12", "1"), ("13", "1"), ("14", "0"),
            ("15", "1"), ("16", "2"), ("17", "1"), ("18", "0000000008"), ("19", "002790"),
            ("20", "00097"), ("21", "00817"), ("22", "055"), ("23", "000150"),
            ("24", "000080"), ("25", "00060"), ("26", "00120"), ("27", "B1234567890123"),
            ("28", "2025-03-14:08:15:42")]
OLD_APPENDED = [[("29", "1"), ("30", "02")],                                  # revision 3
                [("31", "A".ljust(25)), ("32", "B".ljust(25)), ("33", "C".ljust(25))],
                [("34", "E042")], [("35", "000040"), ("36", "0000000001")],
                [("37", "0000000003"), ("38", "Line 3 station 7".ljust(25))]]


def test_old_result_revisions_2_to_7_are_the_specifications_own_lists():
    lengths = [226, 233, 314, 320, 340, 379]        # the last byte of tables 86-91
    for revision, length in zip(range(2, 8), lengths, strict=True):
        params = OLD_REV2 + [p for more in OLD_APPENDED[:revision - 2] for p in more]
        raw = build(65, revision, params)
        assert len(raw) == length == tagged_length(65, revision)
        r = parse_result(raw)
        assert (r.fetched, r.tightening_id, r.vin, r.job, r.pset, r.strategy) == (
            True, 1235, "WVWZZZ1JZ3W386752", 12, 5, 2)
        assert (r.ok, r.torque_nm, r.angle_deg, r.rundown_angle_deg) == (
            False, 27.9, 97.0, 817.0)
        assert (r.torque_status, r.angle_status, r.tightening_error_status) == (
            Status.HIGH, Status.OK, 8)
        assert (r.tool_serial, r.timestamp) == ("B1234567890123",
                                                datetime(2025, 3, 14, 8, 15, 42))
        assert (r.torque_min_nm, r.torque_max_nm, r.cell_id, r.controller_name) == (
            0.0, 0.0, 0, "")                            # none in MID 0065
        assert r.result_type == (ResultType.LOOSENING if revision >= 3 else None)
        assert r.customer_error_code == ("E042" if revision >= 5 else "")
    with pytest.raises(ProtocolError):                  # MID 0061's list is not MID 0065's
        parse_result(build(65, 2, REV2))


# -- the simulator's writer against the parser, every revision ---------------------------------
RECORD = SimRecord(
    tightening_id=77, cell=2, channel=1, name="Sim", vin="VIN77", pset=3,
    pset_name="Wheel", batch_size=4, batch_counter=2, batch_status=0, ok=False,
    torque_status=0, angle_status=1, torque_min=9900, torque_max=12100,
    torque_target=11000, torque=9750, angle_min=30, angle_max=60, angle_target=45,
    angle=47, angle_exact=46.8, timestamp=datetime(2025, 5, 6, 7, 8, 9),
    pset_changed=datetime(2025, 5, 6, 7, 0, 0), result_type=2)


@pytest.mark.parametrize("mid", [61, 65])
@pytest.mark.parametrize("revision", range(1, 8))
def test_simulator_and_client_agree_on_every_revision(mid, revision):
    raw = message(mid, result_data(mid, revision, RECORD), revision)
    assert len(raw) == tagged_length(mid, revision)
    r = parse_result(raw)
    assert (r.tightening_id, r.ok, r.torque_nm, r.angle_deg, r.pset, r.vin) == (
        77, False, 97.5, 47.0, 3, "VIN77")
    assert (r.torque_status, r.angle_status, r.timestamp) == (
        Status.LOW, Status.OK, datetime(2025, 5, 6, 7, 8, 9))
    if revision >= 3:
        assert (r.result_type, r.pset_name) == (ResultType.LOOSENING,
                                                "Wheel" if mid == 61 else "")
    if revision == 7 and mid == 61:
        assert (r.compensated_angle_deg, r.angle_decimal_deg) == (46.8, 46.8)


@FAST
@given(st.integers(2, 7), st.integers(20, 543), st.binary(min_size=1, max_size=6))
def test_parse_result_never_crashes_on_spliced_revisions(revision, pos, splice):
    good = build(61, revision, params_for(revision))
    spoiled = good[:pos] + splice + good[pos + len(splice):]
    for raw in (spoiled, spoiled[:pos]):
        try:
            parse_result(raw)
        except ProtocolError:
            pass


# -- MID 0002 ---------------------------------------------------------------------------------
IDENT = [("01", "0007"), ("02", "03"), ("03", "PF6000 Line 3".ljust(25)),     # rev 1
         ("04", "ACT"),                                                       # rev 2
         ("05", "2.8.0".ljust(19)), ("06", "PF6000 3.4.1".ljust(19)),         # rev 3
         ("07", "STB 2.0".ljust(19)),
         ("08", "Premium".ljust(24)), ("09", "A123456789"),                   # rev 4
         ("10", "003"), ("11", "001"),                                        # rev 5
         ("12", "1"), ("13", "0"),                                            # rev 6
         ("14", "ST01".ljust(10)), ("15", "Station 1".ljust(25)), ("16", "2")]  # rev 6 too
IDENT_COUNT = {1: 3, 2: 4, 3: 7, 4: 9, 5: 11, 6: 16, 7: 16}


@pytest.mark.parametrize("revision", range(1, 8))
def test_identity_of_every_revision(revision):
    data = "".join(t + v for t, v in IDENT[:IDENT_COUNT[revision]]).encode()
    ident = parse_identity(revision, data)
    assert (ident.revision, ident.cell_id, ident.channel_id, ident.controller_name) == (
        revision, 7, 3, "PF6000 Line 3")
    assert ident.supplier_code == ("ACT" if revision >= 2 else None)
    assert ident.controller_software_version == ("PF6000 3.4.1" if revision >= 3 else None)
    assert ident.controller_serial == ("A123456789" if revision >= 4 else None)
    assert ident.system_type == (3 if revision >= 5 else None)
    assert ident.sequence_number_support is (True if revision >= 6 else None)
    assert ident.linking_handling_support is (False if revision >= 6 else None)
    assert (ident.station_name, ident.client_id) == (
        ("Station 1", 2) if revision >= 6 else (None, None))
    assert ident.unread == ""


def test_identity_describes_itself_and_survives_odd_data():
    data = "".join(t + v for t, v in IDENT[:13]).encode()
    assert parse_identity(6, data).describe() == (
        "PF6000 Line 3 (cell 0007, channel 03): supplier ACT, Open Protocol 2.8.0, "
        "software PF6000 3.4.1, tool software STB 2.0, RBU Premium, serial A123456789, "
        "link-level ack yes")
    odd = parse_identity(1, b"010001020103Short name")          # name cut short
    assert (odd.cell_id, odd.channel_id, odd.controller_name, odd.unread) == (
        1, 1, "", "03Short name")
    assert parse_identity(1, b"hello").describe() == "hello"
    assert identity(decode(b"00200002001         ")) == "controller (MID 0002 revision 1)"


def test_identity_gives_the_nameplate_fields_an_mes_reads():
    """MID 0002 revision 4+ -> manufacturer (the supplier code), model (the name, with the
    RBU type), serial number, software revision; the words are ``describe()``'s, unchanged."""
    data = "".join(t + v for t, v in IDENT[:13]).encode()
    ident = parse_identity(6, data)
    plate = ident.device_identity()
    assert plate.words == ident.describe()
    assert (plate.manufacturer, plate.model, plate.serial_number, plate.software_revision) == (
        "ACT", "PF6000 Line 3 (RBU Premium)", "A123456789", "PF6000 3.4.1")
    # revision 1 says only its name: the rest is not said (None), never invented
    first = parse_identity(1, "".join(t + v for t, v in IDENT[:3]).encode()).device_identity()
    assert (first.manufacturer, first.model, first.serial_number, first.software_revision) == (
        None, "PF6000 Line 3", None, None)
    # blank (space-padded) fields are fields not said
    blank = parse_identity(4, b"010001020103" + b" " * 25 + b"04   ").device_identity()
    assert blank.manufacturer is None and blank.model is None

"""Link-level acknowledgement (MID 9997/9998) between the driver and the simulated controller
over TCP on 127.0.0.1 (and a pty for the basics): numbering, wrapping, resending, repeats
taken once, giving up."""

from __future__ import annotations

import logging
from collections.abc import Iterator

import pytest

from drivers.errors import DeviceTimeoutError, UrlError
from drivers.url import parse_url
from drivers.wrench import open_wrench
from drivers.wrench.openprotocol.client import OpenProtocolWrench
from drivers.wrench.openprotocol.link import RxSequence, answers, link_ack, next_seq
from drivers.wrench.openprotocol.message import Message
from drivers.wrench.sim.controller import SimController

from ..conftest import connect, reconnect_within, wait_until


@pytest.fixture
def lsim() -> Iterator[SimController]:
    """A controller that acknowledges at link level and resends after 0.2 s."""
    with SimController(seed=1, nok_rate=0.0, link_ack=True) as controller:
        controller.link_timeout = 0.2
        yield controller


def seqs(sim: SimController, mid: int) -> list[int | None]:
    return [r.sequence for r in sim.received(mid)]


def ready(w) -> None:
    w.select_pset(1)
    w.enable_tool()


def test_the_numbering_rules():
    assert [next_seq(s) for s in (0, 1, 98, 99)] == [1, 2, 99, 1]
    # a 9997 names the number after the one it acknowledges
    assert [link_ack(Message(61, sequence=s)).sequence for s in (1, 98, 99)] == [2, 99, 1]
    assert link_ack(Message(61)).sequence is None
    assert answers(2, 1) and answers(1, 99) and not answers(1, 1) and not answers(None, 1)
    rx = RxSequence()
    assert [rx.is_new(s) for s in (1, 2, 2, 3, None, None, 3)] == [
        True, True, False, True, True, True, False]
    assert rx.repeats == 2
    rx.reset()
    assert rx.is_new(3)


@pytest.mark.parametrize("transport", ["tcp", "serial"])
def test_link_level_is_on_when_the_controller_says_so(lsim, transport, tmp_path):
    with connect(lsim, transport, tmp_path) as w:
        assert w.link_level and w.controller_identity.sequence_number_support is True
        ready(w)
        lsim.pull_trigger()
        r = w.wait_result(1.0)
        assert r is not None and r.tightening_id == 1
        assert wait_until(lambda: lsim.acks == 1)
    # 0001 is not numbered; 0060, 0080 (the clock), 0018, 0043, 0062 are 1, 2, 3, 4, 5
    assert seqs(lsim, 1) == [None]
    assert [seqs(lsim, mid) for mid in (60, 80, 18, 43, 62)] == [[1], [2], [3], [4], [5]]
    # the controller's numbered messages (0005, 0081, 0005 x2, 0061: 1-5) each got a 9997
    # naming the number expected next (the specification's figures: "MID 9997 seq. 02" for
    # seq. 01)
    acks = [(r.data, r.sequence) for r in lsim.received(9997)]
    assert acks[:5] == [(b"0005", 2), (b"0081", 3), (b"0005", 4), (b"0005", 5),
                        (b"0061", 6)]
    assert lsim.errors == [] and lsim.resent == 0 and lsim.repeats == 0


def test_sequence_numbers_wrap_after_99_in_both_directions(lsim, tmp_path):
    with connect(lsim, "tcp", tmp_path) as w:
        for i in range(105):
            w.select_pset(1 + i % 3)
    sent = seqs(lsim, 18)                         # after 0060 (1) and 0080 (2)
    assert sent[:3] == [3, 4, 5] and sent[96:99] == [99, 1, 2] and len(sent) == 105
    answered = [r.sequence for r in lsim.received(9997)]   # 0005s numbered 98, 99, 1, 2
    assert answered[97:101] == [99, 1, 2, 3]
    assert lsim.errors == []


def test_numbering_restarts_with_each_session(lsim, tmp_path):
    with connect(lsim, "tcp", tmp_path) as w:
        w.select_pset(2)
        lsim.drop_connections()
        assert wait_until(lambda: not w.status().connected) and reconnect_within(w)
        w.select_pset(3)
    assert seqs(lsim, 60) == [1, 1] and seqs(lsim, 18) == [3, 3]


@pytest.mark.parametrize("transport", ["tcp", "serial"])
def test_a_result_repeated_by_the_controller_is_taken_once(lsim, transport, tmp_path, caplog):
    """The driver's 9997 is lost: the controller resends the 0061 with the same number."""
    caplog.set_level(logging.WARNING, logger="drivers.wrench.openprotocol.client")
    with connect(lsim, transport, tmp_path) as w:
        ready(w)
        lsim.link_fault("ignore_ack", 61)
        lsim.pull_trigger()
        first = w.wait_result(1.0)
        assert wait_until(lambda: lsim.resent == 1)
        assert w.wait_result(0.5) is None                      # not a second result
        assert wait_until(lambda: lsim.acks == 1)
        w.select_pset(2)                                       # the link goes on
    assert first is not None and first.tightening_id == 1
    result_acks = [r.sequence for r in lsim.received(9997) if r.data == b"0061"]
    assert len(result_acks) == 2 and result_acks[0] == result_acks[1]
    assert "MID 0061 repeated" in caplog.text


def test_a_message_the_controller_did_not_acknowledge_is_resent_and_handled_once(
        lsim, tmp_path):
    with connect(lsim, "tcp", tmp_path) as w:
        ready(w)
        lsim.pull_trigger()
        r = w.wait_result(1.0, acknowledge=False)
        assert r is not None
        lsim.link_fault("no_ack", 62)
        w.acknowledge_result(r)                    # returns once the resend is acknowledged
        assert lsim.acks == 1 and lsim.acked_ids == [1] and lsim.repeats == 1
    first, second = lsim.received(62)
    assert first.sequence == second.sequence == 5


def test_a_link_level_error_makes_the_driver_resend(lsim, tmp_path):
    with connect(lsim, "tcp", tmp_path) as w:
        lsim.link_fault("nak", 18)
        w.select_pset(3)
        assert lsim.pset == 3 and w.status().reconnects == 0
    assert seqs(lsim, 18) == [3, 3] and lsim.repeats == 0      # the first was refused
    assert [r.data for r in lsim.received(9997)][:1] == [b"0005"]


def test_a_controller_that_never_hears_the_acknowledgements_drops_the_link(lsim, tmp_path):
    with connect(lsim, "tcp", tmp_path) as w:
        ready(w)
        # deaf only once the enable's reply has its 9997 (armed before it arrived, the reply
        # was resent and the link dropped with the result never sent: a CI run)
        assert wait_until(lsim.link_quiet, 30.0)
        lsim.link_fault("deaf")
        lsim.pull_trigger()
        assert wait_until(lambda: not w.status().connected, 30.0)   # bounded generously
        assert lsim.resent == 3 and lsim.link_drops == 1
        first = w.wait_result(0.1)                 # received 4 times, queued once
        assert first is not None and first.tightening_id == 1
        assert w._results == type(w._results)()
        lsim.clear_link_faults()
        assert reconnect_within(w)
        w.select_pset(2)
        assert lsim.pset == 2


def test_the_driver_gives_up_after_three_resends(sim, tmp_path):
    """Forced on (``link_ack=1``) against a controller that does not acknowledge at link
    level: the first numbered message (0060) is sent 4 times, then the link is lost."""
    with pytest.raises(DeviceTimeoutError, match=r"open: communication start: MID 0060 "
                                                 r"sequence 1: no link-level acknowledgement "
                                                 r"within 0.2 s after 3 resends"):
        connect(sim, "tcp", tmp_path, link_ack="on", timeout=0.2)
    assert seqs(sim, 60) == [1, 1, 1, 1]


def test_link_ack_url_option():
    forced = OpenProtocolWrench.from_url(parse_url("openprotocol://10.0.0.9?link_ack=1"))
    never = OpenProtocolWrench.from_url(parse_url("openprotocol://10.0.0.9?link_ack=off"))
    auto = OpenProtocolWrench.from_url(parse_url("openprotocol://10.0.0.9"))
    assert (forced._link_ack_mode, never._link_ack_mode, auto._link_ack_mode) == (
        "on", "off", "auto")
    with pytest.raises(UrlError, match=r"option link_ack='maybe' is not valid: expected "
                                       r"auto, 1 or 0"):
        open_wrench("openprotocol://10.0.0.9?link_ack=maybe")

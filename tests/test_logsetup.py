"""The journal's lines (issue 30, item 5): a time stamp unless systemd's journal takes the
stream (``JOURNAL_STREAM`` names that very stream); asyncua's refused request and asyncio's
write to a closed connection said in the station's words, with the client and the request,
a closed connection once."""

from __future__ import annotations

import asyncio
import contextlib
import io
import logging
import os
import re
import socket
import struct
from collections.abc import Iterator
from pathlib import Path

import pytest

from stationd.logsetup import LibraryWords, StampedFormatter, setup_logging, under_journal
from tests.shell.daemons import free_port

STAMP = r"\d{4}-\d\d-\d\d \d\d:\d\d:\d\d\.\d{3}[+-]\d{4} "


@pytest.fixture
def journal() -> Iterator[io.StringIO]:
    """The station's handler on a string (no file: never the journal), restored after."""
    root = logging.getLogger()
    kept = (root.handlers[:], root.level)
    root.handlers.clear()
    out = io.StringIO()
    setup_logging(logging.INFO, out)
    yield out
    root.handlers[:] = kept[0]
    root.setLevel(kept[1])


def test_the_journal_stream_is_recognised_by_its_device_and_inode(tmp_path: Path,
                                                                 monkeypatch) -> None:
    with (tmp_path / "journal").open("w") as mine, (tmp_path / "other").open("w") as other:
        st = os.fstat(mine.fileno())
        monkeypatch.setenv("JOURNAL_STREAM", f"{st.st_dev}:{st.st_ino}")
        assert under_journal(mine)
        # the journal stamps each line itself: no stamp of the station's
        assert not isinstance(setup_logging(logging.INFO, mine).formatter, StampedFormatter)
        # a child whose standard error went elsewhere inherits the variable: not the journal
        assert not under_journal(other)
        assert isinstance(setup_logging(logging.INFO, other).formatter, StampedFormatter)
        monkeypatch.delenv("JOURNAL_STREAM")
        assert not under_journal(mine)
        assert isinstance(setup_logging(logging.INFO, mine).formatter, StampedFormatter)


def test_lines_in_the_journal_carry_their_priority(tmp_path: Path, monkeypatch) -> None:
    """``journalctl -u stationd -p warning`` (the README's way to find the station's faults)
    showed nothing: every line went to the journal at "info".  Under the journal each line
    begins with its syslog priority (sd-daemon), a traceback's lines too; elsewhere none."""
    root = logging.getLogger()
    kept = (root.handlers[:], root.level)
    try:
        with (tmp_path / "journal").open("w") as mine:
            st = os.fstat(mine.fileno())
            monkeypatch.setenv("JOURNAL_STREAM", f"{st.st_dev}:{st.st_ino}")
            root.handlers.clear()
            setup_logging(logging.DEBUG, mine)
            log = logging.getLogger("stationd")
            log.debug("frame 12 read")
            log.info("vehicle X opened")
            log.warning("vehicle X closed: bolts: 3 missing")
            log.error("fault: database: disk I/O error")
            log.critical("cannot go on")
            try:
                raise ValueError("a reason")
            except ValueError:
                log.exception("the loop failed")
        lines = (tmp_path / "journal").read_text().splitlines()
    finally:
        root.handlers[:] = kept[0]
        root.setLevel(kept[1])
    assert lines[:5] == ["<7>DEBUG frame 12 read", "<6>INFO vehicle X opened",
                         "<4>WARNING vehicle X closed: bolts: 3 missing",
                         "<3>ERROR fault: database: disk I/O error", "<2>CRITICAL cannot go on"]
    assert lines[5] == "<3>ERROR the loop failed" and len(lines) > 6
    assert all(line.startswith("<3>") for line in lines[6:]), lines[6:]
    assert lines[-1] == "<3>ValueError: a reason"


def test_lines_outside_the_journal_carry_their_time(journal: io.StringIO) -> None:
    logging.getLogger("stationd").info("vehicle X opened")
    assert re.fullmatch(STAMP + r"INFO vehicle X opened\n", journal.getvalue())


def test_a_write_to_a_closed_connection_is_said_once_with_its_client(
        journal: io.StringIO) -> None:
    async def main() -> str:
        written = asyncio.Event()
        peer: list[str] = []

        async def serve(reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
            peer.append("%s:%s" % writer.get_extra_info("peername")[:2])  # noqa: UP031
            with contextlib.suppress(ConnectionError):
                await reader.read(1)        # the client has gone (reset)
            for _ in range(12):             # asyncio says so from its 5th write on
                writer.write(b"x" * 1000)
                await asyncio.sleep(0)
            written.set()

        server = await asyncio.start_server(serve, "127.0.0.1", 0)
        port = server.sockets[0].getsockname()[1]
        s = socket.create_connection(("127.0.0.1", port))
        s.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, struct.pack("ii", 1, 0))
        s.close()                           # a reset: the server's writes fail
        await asyncio.wait_for(written.wait(), 30)
        server.close()
        await server.wait_closed()
        return peer[0]

    peer = asyncio.run(main())
    lines = [ln for ln in journal.getvalue().splitlines() if "connection" in ln]
    assert lines == [ln for ln in lines if re.fullmatch(
        STAMP + rf"INFO the client at {re.escape(peer)} closed its connection: what was "
        "still to be sent to it is dropped", ln)], journal.getvalue()
    assert len(lines) == 1, journal.getvalue()
    assert "socket.send() raised exception" not in journal.getvalue()


@pytest.mark.system
def test_a_refused_opc_ua_request_names_its_client_and_request(journal: io.StringIO) -> None:
    from asyncua.server.server import Server
    from asyncua.ua import uaerrors, uatypes
    from asyncua.ua.object_ids import ObjectIds
    from asyncua.ua.uaprotocol_auto import ReadParameters, ReadValueId

    from tests.uaclient import Client

    async def main() -> str:
        port = free_port()
        server = Server()
        await server.init()
        server.set_endpoint(f"opc.tcp://127.0.0.1:{port}/")
        async with server:
            client = Client(f"opc.tcp://127.0.0.1:{port}/", timeout=10)
            await client.connect()
            protocol = client.uaclient.protocol
            assert protocol is not None and protocol.transport is not None
            host, local_port = protocol.transport.get_extra_info("sockname")[:2]
            await client.close_session()        # its requests now need a session
            params = ReadParameters()
            rv = ReadValueId()
            rv.NodeId = uatypes.NodeId(uatypes.Int32(ObjectIds.Server_ServerStatus))
            rv.AttributeId = 13         # Value
            params.NodesToRead = [rv]
            with pytest.raises(uaerrors.UaStatusCodeError):
                await client.uaclient.read(params)
            protocol.transport.close()
        return f"{host}:{local_port}"

    local = asyncio.run(main())
    said = [ln for ln in journal.getvalue().splitlines() if "OPC UA" in ln]
    assert said, journal.getvalue()
    assert re.fullmatch(STAMP + rf"WARNING OPC UA: the client at {re.escape(local)}'s "
                        r"ReadRequest refused with Bad\w+: .+", said[0]), said
    assert "sending service fault response" not in journal.getvalue()


def test_other_lines_pass_unchanged() -> None:
    record = logging.LogRecord("asyncua.server", logging.ERROR, __file__, 1,
                               "something else: %s", ("x",), None)
    assert LibraryWords().filter(record) and record.getMessage() == "something else: x"

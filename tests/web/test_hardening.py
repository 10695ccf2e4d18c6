"""The screens' server against what a security review tried on it (over real HTTP on
loopback): connections that never finish a request, a guessed token, a token left in the
address bar, a page of another site reaching a server without a token, files beside the
images, hostile bodies, and the headers of every answer."""

from __future__ import annotations

import asyncio
import logging
import socket
import time

from aiohttp import ClientSession, CookieJar

from stationd.bus import EventBus
from stationd.web.server import SECURITY_HEADERS, WebServer

TOKEN = "a-long-enough-token-for-the-tests"  # noqa: S105 - the tests' own


def _serve(**kw) -> WebServer:
    return WebServer(EventBus(), listen="127.0.0.1:0", **kw)


async def _closed_by_server(sock: socket.socket, within_s: float) -> bool:
    """Whether the server closes ``sock`` (an empty read or a reset) within ``within_s``."""
    loop = asyncio.get_running_loop()
    sock.setblocking(False)
    deadline = time.monotonic() + within_s
    while time.monotonic() < deadline:
        try:
            data = await asyncio.wait_for(loop.sock_recv(sock, 1024), 0.5)
        except TimeoutError:
            continue
        except ConnectionResetError:
            return True
        if data == b"":
            return True
    return False


def test_connections_that_send_no_request_are_closed_and_counted(caplog):
    """A client holding connections open without a request could exhaust the daemon's file
    descriptors (no time limit, no count): each must send its request in time, and one
    over the limit is closed at once, told once in the journal, not once per refusal."""
    async def main():
        srv = _serve()
        await srv.start()
        assert srv.connections is not None
        srv.connections.most, srv.connections.first_request_s = 3, 1.0
        held = []
        try:
            for _ in range(3):
                held.append(socket.create_connection(("127.0.0.1", srv.port)))
            await asyncio.sleep(0.2)
            assert len(srv.connections.open) == 3
            over = [socket.create_connection(("127.0.0.1", srv.port)) for _ in range(5)]
            for s in over:
                assert await _closed_by_server(s, 10), "a connection over the limit is closed"
                s.close()
            assert srv.connections.refused == 5
            told = [r for r in caplog.records if "connection(s) refused" in r.getMessage()]
            assert len(told) == 1 and told[0].levelno == logging.WARNING
            # the three silent ones are closed once their time for a request is over
            for s in held:
                assert await _closed_by_server(s, 15)
            # and the screens answer again
            async with ClientSession() as http, http.get(srv.url + "healthz") as r:
                assert r.status == 200
            # a connection that sent its request is kept after the first-request time
            async with ClientSession() as http:
                async with http.get(srv.url + "healthz") as r:
                    assert r.status == 200
                await asyncio.sleep(1.5)
                async with http.get(srv.url + "api/status") as r:
                    assert r.status == 200
        finally:
            for s in held:
                s.close()
            await srv.stop()
    caplog.set_level(logging.WARNING, logger="stationd.web")
    asyncio.run(main())


def test_every_answer_carries_the_security_headers_and_no_server_version():
    async def main():
        srv = _serve()
        await srv.start()
        try:
            async with ClientSession() as http:
                for path in ("", "api/status", "healthz", "static/app.css", "nowhere"):
                    async with http.get(srv.url + path) as r:
                        for name, value in SECURITY_HEADERS.items():
                            assert r.headers.get(name) == value, (path, name)
                        assert r.headers["Server"] == "stationd", path
                async with http.get(srv.url + "api/events") as stream:   # a stream too
                    assert stream.headers["X-Frame-Options"] == "DENY"
        finally:
            await srv.stop()
    asyncio.run(main())


def test_a_token_in_a_browsers_address_is_taken_as_a_cookie_and_removed(caplog):
    """Opening /vehicles?token=... in a browser kept the token in the address bar (and the
    history); a wrong token guessed 300 times wrote nothing in the journal."""
    async def main():
        srv = _serve(token=TOKEN)
        await srv.start()
        try:
            async with ClientSession(cookie_jar=CookieJar(unsafe=True)) as http:  # (an IP's)
                async with http.get(srv.url + f"vehicles?token={TOKEN}&x=1",
                                    headers={"Accept": "text/html"},
                                    allow_redirects=False) as r:
                    assert r.status == 303
                    assert r.headers["Location"] == "/vehicles?x=1"
                    assert "token=" in r.headers["Set-Cookie"]
                    assert "HttpOnly" in r.headers["Set-Cookie"]
                    # Lax: a link followed from another site keeps it on the redirect
                    assert "SameSite=Lax" in r.headers["Set-Cookie"]
                # the address sent on stays on this server whatever path was asked
                async with http.get(srv.url.rstrip("/") + f"//evil.example/x?token={TOKEN}",
                                    headers={"Accept": "text/html"},
                                    allow_redirects=False) as r:
                    assert r.status == 303
                    assert r.headers["Location"] == "/evil.example/x", r.headers["Location"]
                async with http.get(srv.url + "vehicles?x=1") as r:       # the cookie kept
                    assert r.status == 200
            async with ClientSession() as http:   # a program asking with ?token= is answered
                async with http.get(srv.url + f"api/status?token={TOKEN}") as r:
                    assert r.status == 200
                for i in range(30):
                    async with http.get(srv.url + "api/status",
                                        headers={"Authorization": f"Bearer guess{i}"}) as r:
                        assert r.status == 401
                        # a refusal ends its connection: it keeps no slot
                        assert r.headers.get("Connection", "").lower() == "close"
        finally:
            await srv.stop()
    caplog.set_level(logging.WARNING, logger="stationd.web")
    asyncio.run(main())
    told = [r.getMessage() for r in caplog.records if "wrong token" in r.getMessage()]
    # the first at once; the others (a minute later, or as here as the server stops)
    assert [t.rsplit(": ", 1)[1] for t in told] == ["1 from 127.0.0.1", "29 from 127.0.0.1"]
    assert TOKEN not in " ".join(r.getMessage() for r in caplog.records)


def test_a_server_without_a_token_answers_only_requests_for_its_own_address():
    """Without a token the server listens on loopback only; a page of another site whose
    name resolves to 127.0.0.1 (DNS rebinding) made the browser of someone on this machine
    read the station."""
    async def main():
        srv = _serve()
        await srv.start()
        try:
            async with ClientSession() as http:
                for host in ("evil.example", f"evil.example:{srv.port}"):
                    async with http.get(srv.url + "api/status", headers={"Host": host}) as r:
                        assert r.status == 421, host
                for host in (f"127.0.0.1:{srv.port}", f"localhost:{srv.port}", "127.0.0.1",
                             f"[::1]:{srv.port}", f"LOCALHOST:{srv.port}",
                             f"{socket.gethostname()}:{srv.port}"):
                    async with http.get(srv.url + "api/status", headers={"Host": host}) as r:
                        assert r.status == 200, host
                # a monitoring probe asks /healthz by whatever name it was given
                async with http.get(srv.url + "healthz",
                                    headers={"Host": "station.plant.example"}) as r:
                    assert r.status == 200
        finally:
            await srv.stop()
    asyncio.run(main())


def test_only_images_are_served_from_the_images_folder(tmp_path):
    """A images folder that also held the database and the OPC UA server's key served them
    to any holder of the token."""
    (tmp_path / "VIN1").mkdir()
    (tmp_path / "VIN1" / "B1-7-pair1-left.png").write_bytes(b"\x89PNG\r\n\x1a\n")
    (tmp_path / "stationd.db").write_bytes(b"SQLite format 3\x00")
    (tmp_path / "opcua").mkdir()
    (tmp_path / "opcua" / "server-key.pem").write_text("-----BEGIN PRIVATE KEY-----\n")

    async def main():
        srv = _serve(token=TOKEN, images_dir=tmp_path)
        await srv.start()
        try:
            async with ClientSession(headers={"Authorization": f"Bearer {TOKEN}"}) as http:
                async with http.get(srv.url + "images/VIN1/B1-7-pair1-left.png") as r:
                    assert r.status == 200
                for path in ("stationd.db", "opcua/server-key.pem", "VIN1"):
                    async with http.get(srv.url + "images/" + path) as r:
                        assert r.status == 404, path
                        assert b"KEY" not in await r.read()
        finally:
            await srv.stop()
    asyncio.run(main())


def test_hostile_requests_are_one_bad_request_each_and_no_traceback(caplog):
    """A body nested past Python's depth was a 500 with a RecursionError's traceback; a
    header over 8 KiB a 400 with a nine-line traceback at ERROR: anyone reaching the port
    could fill the journal."""
    async def main():
        srv = _serve()
        await srv.start()
        try:
            async with ClientSession() as http:
                async with http.post(srv.url + "api/login", data="[" * 100_000,
                                     headers={"Content-Type": "application/json"}) as r:
                    assert r.status == 400
                    assert "not JSON" in await r.text()
            loop = asyncio.get_running_loop()
            with socket.create_connection(("127.0.0.1", srv.port)) as s:
                s.setblocking(False)
                await loop.sock_sendall(s, b"GET /healthz HTTP/1.1\r\nHost: 127.0.0.1\r\n"
                                           b"X-Big: " + b"a" * 10_000 + b"\r\n\r\n")
                answer = await asyncio.wait_for(loop.sock_recv(s, 100), 10)
                assert answer.startswith(b"HTTP/1.0 400") or answer.startswith(b"HTTP/1.1 400")
        finally:
            await srv.stop()
    caplog.set_level(logging.DEBUG)
    asyncio.run(main())
    assert not [r for r in caplog.records if r.levelno >= logging.ERROR]


def test_the_rest_of_a_burst_of_wrong_tokens_is_told_when_the_minute_is_over(caplog,
                                                                          monkeypatch):
    """A review: 300 wrong tokens then silence told "1 from X", the 299 others never."""
    import stationd.web.connections as connections

    monkeypatch.setattr(connections, "WARN_EVERY_S", 0.5)

    async def main():
        srv = _serve(token=TOKEN)
        await srv.start()
        try:
            async with ClientSession() as http:
                for i in range(5):
                    async with http.get(srv.url + "api/status",
                                        headers={"Authorization": f"Bearer guess{i}"}) as r:
                        assert r.status == 401
            for _ in range(100):
                if len([r for r in caplog.records if "wrong token" in r.getMessage()]) > 1:
                    break
                await asyncio.sleep(0.1)
        finally:
            await srv.stop()
    caplog.set_level(logging.WARNING, logger="stationd.web")
    asyncio.run(main())
    told = [r.getMessage() for r in caplog.records if "wrong token" in r.getMessage()]
    assert told == ["screens: requests with a wrong token refused: 1 from 127.0.0.1",
                    "screens: requests with a wrong token refused: 4 from 127.0.0.1"]


class _Transport:
    """Enough of a TCP transport for :class:`Connections`: its peer, and whether it was
    closed."""

    def __init__(self, address: str) -> None:
        self.address, self.aborted = address, False

    def get_extra_info(self, name: str) -> object:
        return (self.address, 40000) if name == "peername" else None

    def abort(self) -> None:
        self.aborted = True

    def is_closing(self) -> bool:
        return self.aborted


def test_one_address_off_the_machine_cannot_take_every_connection():
    """A review: 128 connections from one client shut every screen and /healthz out."""
    from stationd.web.connections import MOST_PER_ADDRESS, Connections

    async def main():
        conns = Connections(lambda: None)
        made = [_Transport("10.0.0.9") for _ in range(MOST_PER_ADDRESS + 3)]
        kept = [t for t in made if conns._made(t)]
        assert len(kept) == MOST_PER_ADDRESS and all(t.aborted for t in made[len(kept):])
        other = _Transport("10.0.0.10")
        assert conns._made(other)                  
        local = [_Transport("127.0.0.1") for _ in range(MOST_PER_ADDRESS + 3)]
        assert all(conns._made(t) for t in local)  
        conns._lost(kept[0])                       
        assert conns._made(_Transport("10.0.0.9")) 
        assert conns.refused == 3
        for t in [*kept, other, *local]:
            conns._lost(t)                         
    asyncio.run(main())

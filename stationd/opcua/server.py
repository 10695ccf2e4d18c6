"""The station as an OPC UA server in the joining-system companion model: one ``JoiningSystem``
(OPC 40450-1) with its identification and the station's state, every recorded rundown fired as
a result event, the last results for GetLatestResult and GetResultById.

Why this shape: the results feed (:mod:`db.ledger`) is the truth, so the server reads it from
the last number it published, every second (sooner when the bus says a result was recorded):
a result stored while no client listened is still there for GetResultById, RequestResults and
RequestUnacknowledgedResults (:mod:`stationd.opcua.catchup`), and nothing is published that was
not committed.  A rundown's curves, stored after it, are joined to its result before its event
goes out (:mod:`stationd.opcua.curves`); the devices' health is the JoiningSystem's assets
(:mod:`stationd.opcua.health`), written from the station's events as its state is.  The
server is fed by the station, never a second place where rules live: nothing a client does
reaches the station (no variable is writable); the one method that changes anything,
AcknowledgeResults, changes only the MES's own bookkeeping of what it stored, and only a
configured user may call it.

The workarounds for asyncua 2.1.0 (``../shared/design/PROTOCOLS.md``), beside those of
:mod:`stationd.opcua.model`:

5. events reach only monitored items on the emitting node: results are fired on the Server
   object (where MES clients subscribe), on the JoiningSystem and on its ResultManagement
   (event notifiers in the model), with the JoiningSystem as their SourceNode;
6. JoiningSystemResultReadyEventType is abstract: a concrete subtype of it,
   ``StationResultReadyEventType`` in this server's namespace, is fired;
7. security: asyncua lets everyone write (PermissiveUserManager), its role ruleset lets an
   anonymous client do nothing, and without a validator it accepts any client certificate.
   Here: :class:`ReadOnlyRuleset` (browse, read, subscribe, call for everyone, except the
   methods that change something, AcknowledgeResults, for users only; no write and no node
   management for anyone), :class:`StationUsers` (anonymous, or a configured user with the
   right password), a trust list for client certificates;
8. a Republish of a message the server does not hold is answered Good with an empty
   message (``SubscriptionService.republish``): the standard's answer is
   BadMessageNotAvailable (BadSubscriptionIdInvalid for a subscription it does not know),
   the one a stock node-opcua client waits for before it stops asking.  After a reload (a
   new server, sessions and subscriptions gone) such a client recreated its subscription,
   then asked again for its first message some 1,300 times a second, never received another
   event, and kept two thirds of a core of the station busy: :func:`_republish_by_the_standard`;
9. an event filter's ``OfType`` matches the type named alone, not its subtypes: an MES
   subscribing with ``OfType(JoiningSystemResultReadyEventType)`` got no result (the station
   fires its subtype, 6): :func:`stationd.opcua.oftype.follow_subtypes`.

And (4): the optional methods RequestResults, RequestUnacknowledgedResults (IJT Base) and
AcknowledgeResults (Machinery Result) are not instantiated with the JoiningSystem: they are
added to its ResultManagement with the arguments their type declares.  RequestResults and
RequestUnacknowledgedResults are reads (they send stored results again as events and change
nothing, like GetResultById): anonymous clients may call them.  The last result they sent is
also ``Results/RequestedResult``, where the working group's conformance client reads it.

Beside the modern DataTypeDefinitions the server publishes OPC Binary dictionaries generated
from them (:mod:`stationd.opcua.dictionary`): that client, and MES code built like it, decode
results only through those.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import os
import socket
import time
from collections import OrderedDict
from collections.abc import Callable, Coroutine
from contextvars import ContextVar
from dataclasses import replace
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from asyncua.common.instantiate_util import instantiate
from asyncua.common.node import Node
from asyncua.common.utils import ServiceError
from asyncua.crypto.permission_rules import USER_TYPES, SimpleRoleRuleset, User, UserRole
from asyncua.crypto.truststore import TrustStore
from asyncua.crypto.validator import CertificateValidator, CertificateValidatorOptions
from asyncua.server.internal_session import InternalSession
from asyncua.server.server import Server
from asyncua.server.user_managers import UserManager
from asyncua.ua.ua_binary import struct_from_binary

from db.curves import curves_for
from db.ledger import RUNDOWN, Series, is_result
from db.repository import Repository
from drivers.identity import DeviceIdentity
from stationd.access import password_matches
from stationd.bus import EventBus
from stationd.logsetup import Sparing
from stationd.opcua.catchup import CatchUp
from stationd.opcua.config import OpcUaConfig
from stationd.opcua.curves import CurveJoin
from stationd.opcua.health import FAILURE, LINE_LINK, NORMAL, OFF_SPEC, DeviceAssets
from stationd.opcua.model import (
    DI_URI,
    IJT_URI,
    MACHINERY_URI,
    RESULT_URI,
    init_server,
    load_model,
    publish_dictionaries,
)
from stationd.opcua.oftype import follow_subtypes
from stationd.opcua.results import JOINING_TECHNOLOGY, any_message, any_result
from stationd.opcua.uatypes import ua
from stationd.outfile import write_atomic
from stationd.station.events import (
    DeviceHealth,
    DeviceIdentified,
    LineLinkChanged,
    ResultRecorded,
    State,
    StateChanged,
    StationEvent,
)
from stationd.words import state_words

log = logging.getLogger("stationd")
NAMESPACE = "urn:stationd:opcua"
POLL_S = 1.0
HELD_POLL_S = 0.02           # the feed read while a result waits for its curves
MANUFACTURER = "stationd"
#: the Identification's ManufacturerUri: instantiated with the type, so served; left empty, a
#: client reads None where DI says a URI
MANUFACTURER_URI = "urn:stationd"
JOINING_SYSTEM_TYPE, RESULT_READY_EVENT_TYPE = 1005, 1007   # in IJT Base
REQUESTED_RESULT_EVENT_TYPE = 1035                            # in IJT Base
REQUEST_RESULTS, REQUEST_UNACKNOWLEDGED = 7074, 7092          # in IJT Base
ACKNOWLEDGE_RESULTS = 7009                                    # in Machinery Result
JOINING_SYSTEM_RESULT_TYPE = 2014                             # in IJT Base
MACHINES_FOLDER = 1001                                        # in Machinery
SOFTWARE_VERSION = "0.1.0"
_NO_ERROR = 0


#: the user of the request being served: asyncua calls the ruleset, then the method, in the
#: same task, and tells a method nothing of its caller (kept for the acknowledgements' record)
CALLER: ContextVar[User | None] = ContextVar("opcua_caller", default=None)
_CALL = ua.NodeId(ua.ObjectIds.CallRequest_Encoding_DefaultBinary)


class ReadOnlyRuleset(SimpleRoleRuleset):
    """Browse, read, subscribe and call the read-only methods, for anonymous clients and users
    alike; the methods in :attr:`changing` for users only; writing a value or changing the
    address space for nobody."""

    def __init__(self) -> None:
        super().__init__()  # type: ignore[no-untyped-call]
        allowed = {ua.NodeId(t) for t in USER_TYPES} - {
            ua.NodeId(ua.ObjectIds.WriteRequest_Encoding_DefaultBinary)}
        self._allowed = frozenset(allowed)
        self.changing: set[ua.NodeId] = set()   # filled when the address space is built

    def check_validity(self, user: User, action_type_id: ua.NodeId, body: Any) -> bool:
        CALLER.set(user)
        if user.role not in (UserRole.Anonymous, UserRole.User) or \
                action_type_id not in self._allowed:
            return False
        if action_type_id == _CALL and user.role != UserRole.User and self.changing:
            return not self._calls_changing(body)
        return True

    def _calls_changing(self, body: Any) -> bool:
        """Whether a call request (undecoded: asyncua decodes it after this check) calls a
        method in :attr:`changing`; one that does not decode is refused here too."""
        try:
            params = struct_from_binary(ua.CallParameters, body.copy())
        except Exception:   # malformed: asyncua would refuse it as well
            return True
        return any(m.MethodId in self.changing for m in params.MethodsToCall or [])


class StationUsers(UserManager):
    """Anonymous, or a user of the ``opcua.users`` section with their password.

    asyncua asks this on the daemon's own loop, and a password's scrypt takes 50-60 ms: at
    most :data:`CHECKS_PER_S` password checks a second (a burst of :data:`CHECKS_BURST`), the
    others refused unchecked, so a client trying passwords can neither stall the station's
    loop nor guess fast (a review: a lock-out per user let anyone keep the MES out, and
    names never tried were checked without limit).  An unknown user is checked against a
    dummy hash (the answer's time does not tell the names apart); refusals are told in the
    journal with the user's name, at most one line a minute beyond the first."""

    def __init__(self, users: dict[str, str], *, anonymous: bool = True,
                 clock: Callable[[], float] = time.monotonic) -> None:
        self._users, self.anonymous, self._clock = users, anonymous, clock
        self._tokens, self._filled = float(CHECKS_BURST), clock()
        self._told = Sparing(log, clock=clock)

    def get_user(self, iserver: Any, username: str | None = None,
                 password: str | None = None, certificate: Any = None) -> User | None:
        if username is None:
            if not self.anonymous:
                self._refused("an anonymous client refused (opcua.anonymous: false)")
                return None
            return User(role=UserRole.Anonymous)
        name = username[:64]
        if not self._take():
            # (no name: one line for them all, whatever names a guesser tries)
            self._refused(f"logins refused unchecked: more than {CHECKS_PER_S} a second")
            return None
        if not password_matches(password or "", self._users.get(username)):
            self._refused(f"user {name!r} refused: wrong user or password")
            return None
        return User(role=UserRole.User, name=username)

    def _refused(self, line: str) -> None:
        self._told.tell(line, f"OPC UA: {line}")

    def _take(self) -> bool:
        """One password check from the budget (refilled at :data:`CHECKS_PER_S`)."""
        now = self._clock()
        self._tokens = min(float(CHECKS_BURST),
                           self._tokens + (now - self._filled) * CHECKS_PER_S)
        self._filled = now
        if self._tokens < 1.0:
            return False
        self._tokens -= 1.0
        return True


#: password checks a second, and the burst allowed (an MES logs in once per session)
CHECKS_PER_S, CHECKS_BURST = 2, 5


_POLICIES = {
    "none": ua.SecurityPolicyType.NoSecurity,
    "sign": ua.SecurityPolicyType.Basic256Sha256_Sign,
    "encrypt": ua.SecurityPolicyType.Basic256Sha256_SignAndEncrypt,
}


def _private_key(key: Path, cert: Path) -> None:
    """The server's private key at ``key``, readable by its owner alone: made here when it is
    not there (asyncua's helper writes it under the umask: 0644 by hand, 0640 under the
    unit, where the ``stationd`` group an engineer joins to read the database could read
    it), and an existing one's group and others' bits taken away (a key an earlier release
    made).  A new key's old certificate is removed, for asyncua to make the key's own."""
    if key.is_file():
        if os.stat(key).st_mode & 0o077:
            with contextlib.suppress(OSError):   # not the daemon's to change: as it is
                os.chmod(key, 0o600)
        return
    from asyncua.crypto.cert_gen import dump_private_key_as_pem, generate_private_key

    # written whole, 0600 from its first byte (its temporary file is made so)
    write_atomic(key, dump_private_key_as_pem(generate_private_key()), mode=0o600)
    cert.unlink(missing_ok=True)


class OpcUaServer:
    """The OPC UA server of one station: :meth:`start`, then :meth:`run` until its stop
    event, :meth:`stop` (safe twice)."""

    def __init__(self, cfg: OpcUaConfig, *, bus: EventBus | None = None,
                 simulated: bool = False, devices: tuple[str, ...] = ()) -> None:
        self.cfg, self.bus, self.simulated = cfg, bus, simulated
        self.devices = devices      # assets made at start (others when an event names them)
        self.join = CurveJoin(cfg.keep)
        self._repo: Repository | None = None
        self.assets = DeviceAssets()
        self._loop: asyncio.AbstractEventLoop | None = None
        self._pending: set[asyncio.Task[None]] = set()
        self.server: Server | None = None
        self.joining_system: Node | None = None
        self.published = 0          # result events fired (this process)
        self.cursor = 0             # the last feed entry read
        self.series = Series("")   # each record's id, as the line keeps it (:meth:`_follow`)
        self._follow_at = 0.0
        self._results: OrderedDict[str, Any] = OrderedDict()   # ResultId -> ResultDataType
        self._event: list[Any] = []        # the result event's generators
        self._requested: list[Any] = []    # the requested results' generators
        self.ruleset = ReadOnlyRuleset()
        self.catchup = CatchUp(self._fire_requested)
        self._state: Node | None = None
        self._requested_result: Node | None = None
        self._reason: Node | None = None
        self._wake = asyncio.Event()
        self._unsubscribe: Callable[[], None] | None = None

    @property
    def url(self) -> str:
        return self.cfg.endpoint

    # -- lifecycle ------------------------------------------------------------------------------
    async def start(self) -> None:
        """Load the model, build the JoiningSystem and listen.  ``OSError`` for a port in
        use."""
        if self.server is not None:
            return
        server = Server(user_manager=StationUsers(self.cfg.users,
                                                  anonymous=self.cfg.anonymous))
        await init_server(server)
        _republish_by_the_standard()
        follow_subtypes()
        server.set_endpoint(self.cfg.endpoint)
        server.set_server_name(f"stationd {self.cfg.station_id}")
        await server.set_application_uri(f"urn:stationd:{self.cfg.station_id}")
        await self._security(server)
        types = await load_model(server)
        idx = await server.register_namespace(NAMESPACE)
        await publish_dictionaries(server, types, idx)
        await self._build(server, idx)
        _filtered(logging.getLogger("asyncua.server.server"), _StartFailure)
        await server.start()
        self.server = server
        self._loop = asyncio.get_running_loop()
        if self.bus is not None:
            # what the station said before this server listened (its state, a device's
            # fault, the controller's nameplate: said once, at its start) is said now
            self._unsubscribe = self.bus.subscribe(self._on_event, replay=current)
        log.info("OPC UA: %s (%s)", self.cfg.endpoint, ", ".join(self.cfg.security))

    async def stop(self) -> None:
        server, self.server = self.server, None
        if self._unsubscribe is not None:
            self._unsubscribe()
            self._unsubscribe = None
        for t in list(self._pending):
            t.cancel()
        await self.catchup.close()
        if server is not None:
            await server.stop()

    async def _security(self, server: Server) -> None:
        policies = [_POLICIES[s] for s in self.cfg.security]
        server.set_security_policy(policies, permission_ruleset=self.ruleset)
        # (anonymous: false: not even offered, so a client asks for a user at once)
        tokens: list[type] = [ua.AnonymousIdentityToken] if self.cfg.anonymous else []
        if self.cfg.users:
            tokens.append(ua.UserNameIdentityToken)
        server.set_identity_tokens(tokens)
        if self.cfg.certificates is None:
            return
        from asyncua.crypto.cert_gen import setup_self_signed_certificate
        from cryptography.x509.oid import ExtendedKeyUsageOID

        folder = self.cfg.certificates
        trusted = folder / "trusted"
        trusted.mkdir(parents=True, exist_ok=True)
        key, cert = folder / "server-key.pem", folder / "server-cert.der"
        _private_key(key, cert)
        host = socket.gethostname()
        await setup_self_signed_certificate(
            key, cert, f"urn:stationd:{self.cfg.station_id}", host,
            [ExtendedKeyUsageOID.CLIENT_AUTH, ExtendedKeyUsageOID.SERVER_AUTH],
            {"commonName": f"stationd {self.cfg.station_id}", "organizationName": "stationd"})
        await server.load_certificate(str(cert))
        await server.load_private_key(str(key))
        if not any(trusted.iterdir()):
            # nothing trusted yet (a first start): no client certificate is accepted, rather
            # than every one (asyncua's store cannot be empty)
            # a warning only where such sessions are offered (an IT administrator's trial:
            # said at every start of a server configured with security [none])
            signed = any(s != "none" for s in self.cfg.security)
            (log.warning if signed else log.info)(
                "OPC UA: no client certificate in %s yet: signed and encrypted sessions are "
                "refused until one is placed there", trusted)
            server.set_certificate_validator(_refuse_every_certificate)
            return
        store = TrustStore([trusted], [])
        await store.load()
        _filtered(logging.getLogger("asyncuagds.validate"), _NoTraceback)   # truststore's
        server.set_certificate_validator(CertificateValidator(
            CertificateValidatorOptions.TRUSTED_VALIDATION |
            CertificateValidatorOptions.PEER_CLIENT, store))

    # -- the address space -----------------------------------------------------------------------
    async def _build(self, server: Server, idx: int) -> None:
        uris = await server.get_namespace_array()
        ijt, mach = uris.index(IJT_URI), uris.index(MACHINERY_URI)
        folder = server.get_node(ua.NodeId(MACHINES_FOLDER, mach))
        parent = folder if await _exists(folder) else server.nodes.objects
        sid = self.cfg.station_id
        js = await parent.add_object(ua.NodeId(f"JoiningSystem.{sid}", idx),
                                     ua.QualifiedName(sid, idx),
                                     objecttype=ua.NodeId(JOINING_SYSTEM_TYPE, ijt))
        self.joining_system = js
        ident = await js.get_child([f"{uris.index(DI_URI)}:Identification"])
        for name, value in (("Manufacturer", MANUFACTURER), ("ManufacturerUri", MANUFACTURER_URI),
                            ("Model", "stationd"),
                            ("SystemId", sid), ("Name", sid),
                            ("Description", "vision-guided bolt-tightening station"),
                            ("JoiningTechnology", JOINING_TECHNOLOGY),
                            ("ProductInstanceUri", f"urn:stationd:{sid}")):
            await _set(ident, name, value, uris)
        await ident.add_property(uris.index(DI_URI), "SoftwareRevision", SOFTWARE_VERSION,
                                 ua.VariantType.String)
        await _one_building_block(js, ident, uris)
        self._state = await js.add_variable(ua.NodeId(f"JoiningSystem.{sid}.State", idx),
                                            ua.QualifiedName("State", idx), "unknown",
                                            varianttype=ua.VariantType.String)
        self._reason = await js.add_variable(ua.NodeId(f"JoiningSystem.{sid}.StateReason", idx),
                                             ua.QualifiedName("StateReason", idx), "",
                                             varianttype=ua.VariantType.String)
        await self.assets.build(server, js, idx, f"JoiningSystem.{sid}", self.devices)
        mr = uris.index(RESULT_URI)
        rm = await js.get_child([f"{mr}:ResultManagement"])
        await _one_building_block(js, rm, uris)
        self._requested_result = await _requested_result_variable(
            server, rm, (f"JoiningSystem.{sid}.ResultManagement", idx), mr, ijt)
        gens: list[list[Any]] = []
        for name, base in (("StationResultReadyEventType", RESULT_READY_EVENT_TYPE),
                           ("StationRequestedResultEventType", REQUESTED_RESULT_EVENT_TYPE)):
            etype = await server.create_custom_event_type(idx, name, ua.NodeId(base, ijt))
            gens.append([])
            # asyncua does not pass events up the notifier hierarchy: fired at the Server
            # object (where MES clients subscribe), at the JoiningSystem (an event notifier:
            # the working group's client checks its SubscribeToEvents bit) and at the
            # ResultManagement that makes them
            for emitter in (server.nodes.server.nodeid, js.nodeid, rm.nodeid):
                gen = await server.get_event_generator(etype, emitter)
                gen.event.SourceNode = js.nodeid
                gen.event.SourceName = sid
                gen.event.Severity = 100
                gens[-1].append(gen)
        self._event, self._requested = gens
        for name, cb in (("GetLatestResult", self._get_latest),
                         ("GetResultById", self._get_by_id)):
            node = await rm.get_child([f"{mr}:{name}"])
            server.link_method(node, _counted(cb, len(await _arguments(node))))
        for declared, cb in ((ua.NodeId(REQUEST_RESULTS, ijt), self.catchup.request_results),
                             (ua.NodeId(REQUEST_UNACKNOWLEDGED, ijt),
                              self.catchup.request_unacknowledged),
                             (ua.NodeId(ACKNOWLEDGE_RESULTS, mr), self._acknowledge)):
            method = await _add_declared_method(
                server, rm, (f"JoiningSystem.{sid}.ResultManagement", idx), declared, cb)
            if declared.Identifier == ACKNOWLEDGE_RESULTS:
                self.ruleset.changing |= {method.nodeid, declared}

    # -- methods (read only) ---------------------------------------------------------------------
    async def _get_latest(self, parent: ua.NodeId, *args: Any) -> list[ua.Variant]:
        if not self._results:
            return _answer(None, 1)
        return _answer(next(reversed(self._results.values())), _NO_ERROR)

    async def _get_by_id(self, parent: ua.NodeId, result_id: Any = None, *args: Any) -> Any:
        """The result kept under ``result_id``; an id that is not one (empty, not text)
        is refused with BadInvalidArgument on the call and on that argument, as Part 4 has
        a method refuse an argument outside its domain (asyncua turns an exception raised
        here into BadUnexpectedError, so the status is returned); a well-formed id of no
        kept result answers with Error 1 (the standard's "not found", the call good)."""
        rid = result_id.Value if isinstance(result_id, ua.Variant) else result_id
        if not isinstance(rid, str) or not rid.strip():
            return _invalid(0, 1 + len(args))
        found = self._results.get(rid)
        return _answer(found, _NO_ERROR if found is not None else 1)

    async def _acknowledge(self, parent: ua.NodeId, result_ids: Any = None, *args: Any) -> \
            list[ua.Variant]:
        user = CALLER.get()
        return await self.catchup.acknowledge(result_ids, (user.name if user else None) or "?")

    # -- the station's events and its feed -------------------------------------------------------
    def _on_event(self, event: StationEvent) -> None:
        """The bus's callback (the publisher's thread): the nodes are written in the
        server's loop, in the order the events came."""
        if isinstance(event, ResultRecorded):
            self._soon(self._wake.set)
        elif isinstance(event, StateChanged):
            self._soon(self._task, self.set_state(event.state, state_words(event.reason)))
        elif isinstance(event, DeviceHealth):
            self._soon(self._task, self.assets.report(
                event.device, NORMAL if event.ok else FAILURE, event.reason or event.kind,
                event.t))
        elif isinstance(event, LineLinkChanged):
            health = FAILURE if not event.up else OFF_SPEC if event.alarm else NORMAL
            self._soon(self._task, self.assets.report(
                LINE_LINK, health, event.alarm or event.reason, event.t))
        elif isinstance(event, DeviceIdentified):
            self._soon(self._task, self.assets.identified(
                event.device, event.identification or DeviceIdentity(event.identity)))

    def _soon(self, fn: Callable[..., Any], *args: Any) -> None:
        loop = self._loop
        if self.server is None or loop is None or loop.is_closed():
            for a in args:   # never run: not left unawaited
                if asyncio.iscoroutine(a):
                    a.close()
            return
        loop.call_soon_threadsafe(fn, *args)

    def _task(self, job: Coroutine[Any, Any, None]) -> None:
        task = asyncio.get_running_loop().create_task(self._quietly(job))
        self._pending.add(task)
        task.add_done_callback(self._pending.discard)

    @staticmethod
    async def _quietly(job: Coroutine[Any, Any, None]) -> None:
        try:
            await job
        except Exception as exc:   # a node not written: journaled, never the station's fault
            log.warning("OPC UA: updating the address space: %s", exc)

    async def set_state(self, state: str, reason: str = "") -> None:
        if self._state is not None and self._reason is not None:
            await self._state.write_value(state)
            await self._reason.write_value(reason)

    async def run(self, stop: asyncio.Event, repo: Repository) -> None:
        """Publish every result recorded from now on until ``stop``; the last ``keep``
        recorded before are kept for the methods."""
        loop = asyncio.get_running_loop()
        self.series = await loop.run_in_executor(None, repo.ledger.series)
        self.catchup.attach(repo, self.series)
        self._repo = repo
        last = await loop.run_in_executor(None, repo.ledger.last_seq)
        await self._preload(repo, last)
        self.cursor = last
        while not stop.is_set():
            try:
                entries = await loop.run_in_executor(None, repo.ledger.since, self.cursor)
            except Exception as exc:   # a database busy or away: tried again, never fatal
                log.warning("OPC UA: reading the results feed: %s", exc)
                entries = []
            if loop.time() >= self._follow_at:   # at the feed's pace, not the curves' 20 ms
                self._follow_at = loop.time() + POLL_S
                await self._follow(repo)
            for e in entries:
                self.cursor = e["seq"]
                self._take(e, loop.time(), hold=True)
            for e in self.join.ready(loop.time()):
                await self._publish(e)
            if len(entries) >= 1000:   # behind: read on at once
                continue
            self._wake.clear()
            wait = POLL_S
            deadline = self.join.next_deadline()
            if deadline is not None:   # a result waits for its curves (they wake nothing)
                wait = max(0.0, min(HELD_POLL_S, deadline - loop.time()))
            with contextlib.suppress(TimeoutError):
                await asyncio.wait_for(_first(stop, self._wake), wait)
        for e in self.join.ready(float("inf")):   # stopping: no result kept back
            await self._publish(e)

    def _id(self, seq: int) -> str:
        """The ResultId of feed entry ``seq``: under the id the line keeps that record
        (after a backup put back, the records before it keep the database's earlier id)."""
        return self.series.result_id(seq)

    async def _follow(self, repo: Repository) -> None:
        """The database's series read again: the forwarder renews its id when it finds the
        database was put back from a copy (:meth:`db.ledger.Ledger.renew_db_id`); the
        results kept for the methods take the ids their records have from then on."""
        try:
            series = await asyncio.get_running_loop().run_in_executor(None, repo.ledger.series)
        except Exception as exc:   # a database busy or away: the ids as they were
            log.warning("OPC UA: reading the database's id: %s", exc)
            return
        if series == self.series:
            return
        log.info("OPC UA: the database's id is %s from result %d on (put back from a copy)",
                 series.db_id, series.from_seq)
        self.series = self.catchup.series = series
        kept = list(self._results.values())
        self._results.clear()
        for result in kept:
            meta = result.ResultMetaData
            meta.ResultId = self._id(meta.SequenceNumber)
            self._results[meta.ResultId] = result

    def _take(self, entry: dict[str, Any], now: float, *, hold: bool) -> None:
        """A feed entry: a rundown kept for the methods (and held for its event), a curve
        joined to its rundown's result (:mod:`stationd.opcua.curves`)."""
        changed = self.join.take(entry, now, hold=hold)
        if is_result(entry):
            self._rebuild(entry)
        elif changed is not None and \
                self._id(changed["seq"]) in self._results:   # still kept
            self._rebuild(changed)

    def _rebuild(self, entry: dict[str, Any]) -> Any:
        result = any_result(self.series.id_of(entry["seq"]), entry, simulated=self.simulated,
                            curves=self.join.curves(int(entry["record"]["id"]))
                            if entry["kind"] == RUNDOWN else None)
        self._keep(result)
        return result

    async def _preload(self, repo: Repository, last: int) -> None:
        loop = asyncio.get_running_loop()
        seq = max(0, last - 5 * self.cfg.keep)
        while seq < last:
            entries = await loop.run_in_executor(None, repo.ledger.since, seq)
            if not entries:
                break
            for e in entries:
                seq = e["seq"]
                if seq <= last:
                    self._take(e, 0.0, hold=False)
        self.join.settle()

    def _keep(self, result: Any) -> None:
        self._results[result.ResultMetaData.ResultId] = result
        while len(self._results) > self.cfg.keep:
            self._results.popitem(last=False)

    async def _publish(self, entry: dict[str, Any]) -> None:
        # the result kept when the rundown was taken, rebuilt there as its curves came
        result = self._results.get(self._id(entry["seq"])) or self._rebuild(entry)
        await _fire(self._event, result, entry)
        self.published += 1

    async def _fire_requested(self, entry: dict[str, Any]) -> None:
        """A stored rundown asked for again (RequestResults, RequestUnacknowledgedResults),
        with its curves (read from the station's records when it is not among those kept)."""
        if self.server is None:
            return
        rid = int(entry["record"]["id"])
        curves = self.join.curves(rid) if entry["kind"] == RUNDOWN else []
        if curves is None and self._repo is not None:
            curves = await asyncio.get_running_loop().run_in_executor(
                None, lambda: curves_for(self._repo, record_id=rid))   # type: ignore[arg-type]
        result = any_result(self.series.id_of(entry["seq"]), entry, simulated=self.simulated,
                            curves=curves)
        if self._requested_result is not None:
            await _write_result(self._requested_result, result)
        await _fire(self._requested, result, entry)


async def _fire(gens: list[Any], result: Any, entry: dict[str, Any]) -> None:
    for gen in gens:
        ev = gen.event
        ev.add_variable("Result", result, ua.VariantType.ExtensionObject)
        ev.Message = ua.LocalizedText(any_message(entry))
        await gen.trigger()


async def _write_result(var: Node, result: Any) -> None:
    """``result`` into a JoiningSystemResultType variable and its ResultMetaData (the
    sub-variable the type declares), stamped now."""
    now = datetime.now(UTC)
    await var.write_value(ua.DataValue(ua.Variant(result, ua.VariantType.ExtensionObject),
                                       SourceTimestamp=now))
    for child in await var.get_children(refs=ua.ObjectIds.HasComponent):
        if (await child.read_browse_name()).Name == "ResultMetaData":
            await child.write_value(ua.DataValue(
                ua.Variant(result.ResultMetaData, ua.VariantType.ExtensionObject),
                SourceTimestamp=now))


async def _requested_result_variable(server: Server, rm: Node, prefix: tuple[str, int],
                                    mr: int, ijt: int) -> Node:
    """``Results/RequestedResult`` under the ResultManagement: the result last sent again by
    RequestResults or RequestUnacknowledgedResults (the working group's reading of the
    Request Results conformance unit: the client reads it after a request; the 1.01 files
    declare no such variable, so it is the station's, browse name in IJT Base as that
    client looks for it), a JoiningSystemResultType as a stored result's variable is.  The
    Results folder (optional in Machinery Result) is made when the type did not instantiate
    it."""
    try:
        folder = await rm.get_child([f"{mr}:Results"])
    except ua.UaError:
        folder = await rm.add_folder(ua.NodeId(f"{prefix[0]}.Results", prefix[1]),
                                     ua.QualifiedName("Results", mr))
    # asyncua warns of each attribute a variable type lacks (UserAccessLevel ...) on copying
    quiet = logging.getLogger("asyncua.common.copy_node_util")
    level = quiet.level
    quiet.setLevel(logging.ERROR)
    try:
        made = await instantiate(
            folder, server.get_node(ua.NodeId(JOINING_SYSTEM_RESULT_TYPE, ijt)),
            nodeid=ua.NodeId(f"{prefix[0]}.Results.RequestedResult", prefix[1]),
            bname=ua.QualifiedName("RequestedResult", ijt), instantiate_optional=False)
    finally:
        quiet.setLevel(level)
    var = server.get_node(made[0])
    read = ua.DataValue(ua.Variant(ua.AccessLevel.CurrentRead.mask, ua.VariantType.Byte))
    await var.write_attribute(ua.AttributeIds.AccessLevel, read)
    await var.write_attribute(ua.AttributeIds.UserAccessLevel, read)
    return var


async def _add_declared_method(server: Server, parent: Node, prefix: tuple[str, int],
                               declared: ua.NodeId, callback: Callable[..., Any]) -> Node:
    """The optional method ``declared`` (a method of a type) on the instance ``parent``
    (its NodeId ``prefix.Name`` in namespace ``prefix[1]``), with the browse name and
    arguments its declaration has, calling ``callback``."""
    decl = server.get_node(declared)
    name = await decl.read_browse_name()
    inputs, outputs = await _arguments(decl), await _arguments(decl, "OutputArguments")
    nodeid = ua.NodeId(f"{prefix[0]}.{name.Name}", prefix[1])
    return await parent.add_method(nodeid, name, _counted(callback, len(inputs)), inputs,
                                   outputs)


async def _arguments(method: Node, prop: str = "InputArguments") -> list[Any]:
    """The arguments a method declares (``prop``: its inputs, or ``OutputArguments``); none
    where it has no such property."""
    try:
        return list(await (await method.get_child([f"0:{prop}"])).read_value())
    except ua.UaError:
        return []


def _counted(callback: Callable[..., Any], count: int) -> Callable[..., Any]:
    """``callback`` called only with the ``count`` input arguments its method declares:
    fewer is BadArgumentsMissing, more BadTooManyArguments (Part 4, Call), as asyncua does
    not check (an MES integrator's trial: RequestResults with no argument was answered Good
    and sent every result from the first, GetResultById without its Timeout Good)."""
    async def call(parent: Any, *args: Any) -> Any:
        if len(args) == count:
            return await callback(parent, *args)
        res = ua.CallMethodResult()
        res.StatusCode = ua.StatusCode(ua.StatusCodes.BadArgumentsMissing if len(args) < count
                                       else ua.StatusCodes.BadTooManyArguments)
        return res

    return call


def _invalid(index: int, count: int) -> Any:
    """A call refused for its argument ``index`` (of ``count``): BadInvalidArgument."""
    bad = ua.StatusCode(ua.StatusCodes.BadInvalidArgument)
    res = ua.CallMethodResult()
    res.StatusCode = bad
    res.InputArgumentResults = [bad if i == index else ua.StatusCode() for i in range(count)]
    return res


def _answer(result: Any, error: int) -> list[ua.Variant]:
    return [ua.Variant(0, ua.VariantType.UInt32),
            ua.Variant(result, ua.VariantType.ExtensionObject),
            ua.Variant(error, ua.VariantType.Int32)]


async def _first(stop: asyncio.Event, wake: asyncio.Event) -> None:
    tasks = {asyncio.create_task(stop.wait()), asyncio.create_task(wake.wait())}
    try:
        await asyncio.wait(tasks, return_when=asyncio.FIRST_COMPLETED)
    finally:
        for t in tasks:
            t.cancel()


async def _exists(node: Node) -> bool:
    try:
        await node.read_browse_name()
    except ua.UaError:
        return False
    return True


async def _set(parent: Node, name: str, value: str, uris: list[str]) -> None:
    """Write ``value`` to the child ``name`` (any of the model's namespaces) in its data
    type (LocalizedText or String)."""
    for ns in (DI_URI, IJT_URI, MACHINERY_URI):
        try:
            node = await parent.get_child([f"{uris.index(ns)}:{name}"])
        except ua.UaError:
            continue
        dtype = await node.read_data_type()
        v = ua.LocalizedText(value) if dtype == ua.NodeId(ua.ObjectIds.LocalizedText) \
            else value
        vt = ua.VariantType.LocalizedText if isinstance(v, ua.LocalizedText) \
            else ua.VariantType.String
        await node.write_value(ua.DataValue(ua.Variant(v, vt)))
        return


def _republish_by_the_standard() -> None:
    """Workaround (8): a Republish answered with the message asked for, or the standard's
    fault (the processor sends a ServiceError as a ServiceFault): BadSubscriptionIdInvalid
    for a subscription this session does not own (subscription numbers start again at each
    server start: after a reload, an MES asking about its old one must not be handed another
    session's message, which that session would then never get), BadMessageNotAvailable for
    a message not held.  Set on asyncua's session class once: the process serves one
    station's server at a time, each session answered alike."""
    if getattr(InternalSession.republish, "by_the_standard", False):
        return

    def republish(session: InternalSession, params: ua.RepublishParameters
                  ) -> ua.NotificationMessage:
        sub = session.subscription_service.subscriptions.get(params.SubscriptionId)
        if sub is None or sub.session_id != session.session_id:
            raise ServiceError(ua.StatusCodes.BadSubscriptionIdInvalid)
        message: ua.NotificationMessage = sub.republish(params.RetransmitSequenceNumber)
        if message.SequenceNumber != params.RetransmitSequenceNumber:
            raise ServiceError(ua.StatusCodes.BadMessageNotAvailable)
        return message

    republish.by_the_standard = True  # type: ignore[attr-defined]
    InternalSession.republish = republish  # type: ignore[method-assign,assignment]


async def _one_building_block(js: Node, block: Node, uris: list[str]) -> None:
    """MachineryBuildingBlocks' Identification and ResultManagement are the machine's own
    (OPC 40001-1: the building block references the same AddIn); asyncua's instantiation made
    second copies there: an Identification with every value None (a newcomer's client read
    it), a ResultManagement with no result (GetLatestResult BadNothingToDo, no events, no
    RequestResults: an MES trial's generic Machinery Result client found nothing).  Removed,
    with what is under them, and the building block references the one that works."""
    try:
        blocks = await js.get_child([f"{uris.index(MACHINERY_URI)}:MachineryBuildingBlocks"])
    except ua.UaError:
        return   # the type has none: nothing to tell apart
    name = await block.read_browse_name()
    try:
        copy = await blocks.get_child([f"{name.NamespaceIndex}:{name.Name}"])
    except ua.UaError:
        copy = None
    if copy is not None and copy.nodeid != block.nodeid:
        await copy.delete(recursive=True)
    await blocks.add_reference(block.nodeid, ua.ObjectIds.HasAddIn, forward=True,
                               bidirectional=False)


__all__ = ["NAMESPACE", "OpcUaServer", "ReadOnlyRuleset", "StationUsers"]


class _NoTraceback(logging.Filter):
    """asyncua logs a client certificate outside the trust list with a traceback: a client's
    refusal is the line alone in the station's journal."""

    def filter(self, record: logging.LogRecord) -> bool:
        record.exc_info, record.exc_text = None, None
        return True




class _StartFailure(logging.Filter):
    """asyncua logs its failure to listen (a port in use) with a traceback before raising it;
    the station's journal has its own line for it ("OPC UA: not served on ..."), so the
    library's is dropped (only that one: its other records pass)."""

    def filter(self, record: logging.LogRecord) -> bool:
        return not str(record.msg).endswith("error starting server")


def _filtered(logger: logging.Logger, kind: type[logging.Filter]) -> None:
    """``logger`` with a filter of ``kind``, added once (each server's start asks again)."""
    if not any(isinstance(f, kind) for f in logger.filters):
        logger.addFilter(kind())


async def _refuse_every_certificate(cert: Any, app: Any) -> None:
    """No client certificate is trusted yet."""
    raise ua.uaerrors.BadCertificateUntrusted()


def current(history: list[StationEvent]) -> list[StationEvent]:
    """The events of ``history`` that say what is true now, oldest first: the last state, each
    device's last health and nameplate, the line link's last word, of the station running
    (since its last start: a reload's station reports its own devices).  A rundown is not
    among them: results are the feed's, read by sequence."""
    # from the newest back to the running station's start: the bus lives as long as the
    # daemon, and this runs under its lock (the publisher waits)
    latest: dict[tuple[str, str], tuple[int, StationEvent]] = {}
    for i in range(len(history) - 1, -1, -1):
        e = history[i]
        match e:
            case StateChanged() | LineLinkChanged():
                latest.setdefault((type(e).__name__, ""), (i, e))
            case DeviceHealth() | DeviceIdentified():
                latest.setdefault((type(e).__name__, e.device), (i, e))
        if isinstance(e, StateChanged) and e.state == State.STARTING:
            break
    for key, (i, e) in latest.items():
        if isinstance(e, DeviceHealth) and not e.ok:
            latest[key] = (i, replace(e, t=_failing_since(history, i, e)))
    return [e for _, e in sorted(latest.values(), key=lambda ie: ie[0])]


def _failing_since(history: list[StationEvent], i: int, health: DeviceHealth) -> float:
    """When the device of ``health`` (not ok, at ``history[i]``) went out of order: its
    ErrorTimestamp.  A device down across a reload was stamped with the reload's time (the
    new station reports it again, and the server restarts with it: an MES trial read the
    failure hours late); reports before the last start count here, back to the device's
    last word that it was ok."""
    since = health.t
    for e in reversed(history[:i]):
        if isinstance(e, DeviceHealth) and e.device == health.device:
            if e.ok:
                break
            since = e.t
    return since

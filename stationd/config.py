"""The station configuration file: YAML -> one typed, validated object.

It holds the marker, the vision parameters, the stereo pairs (calibration file, transform to
the vehicle frame) and the tool geometry; devices, the database and the cycle join it with the
daemon.  Unknown keys are errors that name file, line and key; relative paths are relative to
the config file (for a symbolic link, to the file it points to: :func:`station_base`); there
are no hidden sources (no environment variables, no merged dotfiles).

:func:`load_station_config` raises the first error (the daemon needs a yes or no);
:func:`read_all` reads the same sections with the same code and lists every error, with
those of the files the config names and its device URLs (``stationd config check``).
"""

from __future__ import annotations

from collections.abc import Callable, Collection
from dataclasses import dataclass, field, replace
from functools import partial
from pathlib import Path
from typing import TYPE_CHECKING, Any, ParamSpec, TypeVar

import numpy as np

from db.location import NOT_SQLITE, missing_folder, sqlite_problem
from drivers.devices import Kind, world_view
from drivers.devices import check_url as check_device_url
from drivers.errors import UrlError
from drivers.lift.base import RegisterMap
from drivers.wrench import takes_register_map
from drivers.wrench.modbus_map import WrenchRegisterMap
from stationd.access import AccessConfig
from stationd.devicekey import device_key
from stationd.devicemaps import lift_map, wrench_map
from stationd.errors import ConfigError
from stationd.filekind import expect
from stationd.forward import LineConfig
from stationd.geometry.camera import StereoPair
from stationd.geometry.frames import REGISTRATION_KEYS, Transform
from stationd.geometry.tool import ToolGeometry
from stationd.localize import LocalizeConfig
from stationd.localize.references import References
from stationd.opcua import OpcUaConfig
from stationd.station.matching import MatchingConfig
from stationd.station.policy import NokPolicy, table_errors
from stationd.vision.marker import MarkerSpec
from stationd.vision.params import VisionParams
from stationd.web.config import HttpConfig
from stationd.yamlio import YamlNode

if TYPE_CHECKING:
    pass

T = TypeVar("T")
P = ParamSpec("P")

#: what a station file must name: a file without them would run simulated devices unnoticed
REQUIRED_KEYS = ("cameras", "pairs", "lift", "wrench")
BASELINE_MM = (20.0, 2000.0)    # plausible stereo baselines, millimetres
METRES_LIKE_MM = 10.0           # a pair-to-vehicle translation shorter than this is in metres
#: plausible limits of a pair's exposure skew, ms: under 0.1 it is seconds written as ms (or 0,
#: which no two exposures meet); at 100 ms a wrench moved by hand has moved centimetres
MAX_SKEW_MS = (0.1, 100.0)
STATION_KEYS = ("marker", "vision", "cameras", "pairs", "tool", "lift", "wrench", "matching",
                "database", "bolts", "records", "http", "access", "localize", "line", "nok",
                "opcua", "references")
PAIR_KEYS = ("calibration", "to_vehicle", "left", "right", "max_skew_ms")
#: the most errors told of one section (each found by reading it again without the last)
MAX_SECTION_ERRORS = 50


@dataclass(frozen=True)
class WrenchConfig:
    """The tightening controller: its URL, and for a register-driven one (``modbus-tcp://``,
    ``modbus-rtu://``: its driver says, ``drivers.wrench.takes_register_map``) its register
    map (``drivers/wrench/modbus_map.py``; None: defaults)."""

    url: str = "sim://wrench"
    registers: WrenchRegisterMap | None = None

    @classmethod
    def from_node(cls, node: YamlNode, *, check_url: bool = False) -> WrenchConfig:
        """``check_url``: check the URL's form and scheme now (see :func:`device_url`)."""
        m = node.mapping(("url", "registers", "poll_ms"))
        url = device_url(m["url"], "wrench", check=check_url) if "url" in m else cls.url
        regs = wrench_map(m["registers"]) if "registers" in m else None
        if regs is not None and not takes_register_map(url):
            raise m["registers"].error(f"a register map is for a Modbus controller, not "
                                       f"{url}")
        return cls(url, regs)

    def open_options(self) -> dict[str, Any]:
        """Keywords for ``open_wrench``: the register map when one is configured."""
        return {} if self.registers is None else {"register_map": self.registers}


@dataclass(frozen=True)
class RecordsConfig:
    """Where tightening records keep their evidence: the stereo frames of each selection."""

    images_dir: Path | None = None
    save_images: bool = False


@dataclass(frozen=True)
class LiftConfig:
    """The lift PLC: its URL and register map (``drivers.lift.RegisterMap``)."""

    url: str = "sim://lift"
    registers: RegisterMap = field(default_factory=RegisterMap)
    poll_ms: float = 100.0  # a PLC serves an HMI and a line controller too: read this often

    @classmethod
    def from_node(cls, node: YamlNode, *, check_url: bool = False) -> LiftConfig:
        """``check_url``: check the URL's form and scheme now (see :func:`device_url`)."""
        m = node.mapping(("url", "registers", "poll_ms"))
        url = device_url(m["url"], "lift", check=check_url) if "url" in m else cls.url
        regs = lift_map(m["registers"]) if "registers" in m else RegisterMap()
        poll = m["poll_ms"].number(lo=10.0, hi=5000.0) if "poll_ms" in m else cls.poll_ms
        return cls(url=url, registers=regs, poll_ms=poll)


@dataclass(frozen=True, eq=False)
class PairConfig:
    """One stereo pair: its cameras, calibration and, once registered, its map to the vehicle
    frame.  ``left``/``right`` name entries of ``cameras`` (None: not wired to devices yet).

    ``to_vehicle_path`` is where ``stationd calibrate vehicle`` writes the transform (a file of
    its own, so the hand-written station config is never rewritten); ``to_vehicle`` is None
    until that file exists.
    """

    name: str
    calibration_path: Path
    calibration: StereoPair
    to_vehicle_path: Path
    to_vehicle: Transform | None
    left: str | None = None
    right: str | None = None
    max_skew_s: float = 0.005


@dataclass(frozen=True)
class StationConfig:
    marker: MarkerSpec = field(default_factory=MarkerSpec)
    vision: VisionParams = field(default_factory=VisionParams)
    pairs: dict[str, PairConfig] = field(default_factory=dict)
    tool: ToolGeometry = field(default_factory=ToolGeometry)
    lift: LiftConfig = field(default_factory=LiftConfig)
    cameras: dict[str, str] = field(default_factory=dict)  # name -> URL
    wrench: WrenchConfig = field(default_factory=WrenchConfig)
    matching: MatchingConfig = field(default_factory=MatchingConfig)
    database_url: str = "sqlite:///stationd.db"
    bolts_path: Path | None = None
    records: RecordsConfig = field(default_factory=RecordsConfig)
    http: HttpConfig | None = None  # the screens (stationd.web); None: not served
    access: AccessConfig = field(default_factory=AccessConfig)  # who may give commands
    localize: LocalizeConfig = field(default_factory=LocalizeConfig)  # how pairs are fused
    line: LineConfig | None = None  # the line's database the records are forwarded to
    nok: NokPolicy = field(default_factory=NokPolicy)  # after a NOK: lock, skip or repeat
    opcua: OpcUaConfig | None = None  # the OPC UA server for the MES; None: not served
    # the reference markers of the calibration check; None: none (every pair trusted)
    references: References | None = None
    path: Path | None = None


def station_identity(cfg: StationConfig) -> dict[str, str | None]:
    """Which station this is, as its daemon says in ``/api/status`` and a command given the
    station file checks before it acts (``stationd status --config``...).

    ``id``: the name the plant gives the station, the one its records carry to the line
    (``line.station_id``), else its OPC UA JoiningSystem's (``opcua.station_id``, when
    written); None without either.  ``config``: its station file, resolved (a link and its
    target are one file).  Why both: two stations on one PC without ids are told apart by
    their files; a copy of a station's file on an engineer's PC names the same station by
    its id."""
    sid = cfg.line.station_id if cfg.line is not None else None
    if sid is None and cfg.opcua is not None and cfg.opcua.station_id != OpcUaConfig.station_id:
        sid = cfg.opcua.station_id
    return {"id": sid, "config": None if cfg.path is None else str(Path(cfg.path).resolve())}


def device_url(node: YamlNode, kind: str, *, check: bool = False, sources: bool = False
               ) -> str:
    """A device URL of ``kind`` (camera, lift, wrench).

    With ``check``, the device is built, not opened: its form and scheme are checked against
    the driver's registry, its options with their ranges (a camera's by its backend, which
    parses its URL before loading any SDK; the lift's and the controller's likewise), so a
    URL that can never work is a configuration error, not a station in fault for good.
    ``stationd config check`` and the daemon's loader (``station=True``: the first start and
    every reload) check; other readers of a station file (tools, benchmarks) do not need to.
    ``sources`` (the checker only): what a device reads must exist now (a camera replay's
    files); the daemon starts in fault on it instead, retried as a device that is down.
    """
    url = node.text()
    if check:
        try:
            check_device_url(Kind(kind), url, sources=sources)
        except UrlError as exc:   # the line shows the URL: the message need not repeat it
            text = str(exc)
            if exc.device and text.startswith(f"{exc.device}: "):
                text = text[len(exc.device) + 2:]
            raise node.error(text) from None
    return url


def _max_skew_ms(node: YamlNode) -> float:
    """A pair's exposure skew limit, in milliseconds: below :data:`MAX_SKEW_MS` it is seconds
    (0.005 for 5 ms) or 0 (no two exposures are ever that close: the pair never localizes);
    above, the wrench moves more than a bolt's tolerance between its two images."""
    skew = node.number()
    if not MAX_SKEW_MS[0] <= skew <= MAX_SKEW_MS[1]:
        hint = f"; in seconds? write {skew * 1e3:g} for {skew * 1e3:g} ms" \
            if 0 < skew < MAX_SKEW_MS[0] <= skew * 1e3 else \
            "; 0 accepts no pair of frames: the pair would never localize" if skew == 0 else ""
        raise node.error(f"{skew:g} ms is not plausible: the two exposures of a pair may be "
                         f"{MAX_SKEW_MS[0]:g}-{MAX_SKEW_MS[1]:g} ms apart (milliseconds, 5 by "
                         f"default{hint})")
    return skew


def _path(node: YamlNode, base: Path) -> Path:
    p = Path(node.text())
    return p if p.is_absolute() else base / p


def _existing(node: YamlNode, base: Path, what: str, note: str = "") -> Path:
    """A path (relative to the config file) that must name an existing file; ``note`` is
    added to the message (where relative paths were read from, for a linked station file)."""
    p = _path(node, base)
    if not p.exists():
        raise node.error(f"{what} {p} does not exist{note}")
    return p


def station_base(path: Path) -> Path:
    """The folder the relative paths of the station file at ``path`` are relative to: its
    own, or for a symbolic link (``/etc/stationd/station.yaml -> /opt/line/station.yaml``,
    the natural install) the folder of the file it points to, where its calibrations and
    bolt table are kept with it (``/opt/line``), wherever the link is."""
    return path.resolve().parent if path.is_symlink() else path.parent


def _link_note(path: Path) -> str:
    """What a missing relative path's message adds when the station file is a link: both
    names, and which folder was read."""
    if not path.is_symlink():
        return ""
    target = path.resolve()
    return (f" (relative paths are read from {target.parent}, the folder of {target}, which "
            f"the station file {path} links to)")


def _camera_url(node: YamlNode, *, check: bool, sources: bool = False) -> str:
    return device_url(node.mapping(("url",), required=("url",))["url"], "camera", check=check,
                      sources=sources)


def _refuse(error: ConfigError) -> None:
    """Raise ``error`` (through ``guard``: recorded when collecting)."""
    raise error


def _one_device_each(lift_url: str, wrench_url: str, wrench: YamlNode) -> None:
    """The lift and the controller must be two devices (keys of ``stationd.devicekey``: two
    URLs that reach one endpoint are one device, as for the device locks).  One Modbus
    endpoint and unit as both would take the controller's registers for the lift's, and the
    lift's for a bolt's parameters; one serial line opened twice garbles both."""
    key = device_key(lift_url)
    if key is None or key != device_key(wrench_url):
        return
    where = wrench.mapping(("url", "registers", "poll_ms"))["url"]
    if key.startswith("serial "):
        raise where.error(f"the same serial line as lift.url ({key.removeprefix('serial ')}): "
                          "the lift and the controller would each open it and garble each "
                          "other's frames (give the controller its own port)")
    raise where.error(f"the same device as lift.url ({key}): the lift PLC and the tightening "
                      "controller are two devices (give the controller its own address, "
                      "port or unit)")


def _camera_ref(node: YamlNode, cameras: Collection[str] | None) -> str:
    """A camera name of a pair; ``cameras`` None: the section is unreadable, not checked."""
    cam = node.text()
    if cameras is not None and cam not in cameras:
        raise node.error(f"no camera {cam!r} under cameras "
                         f"(cameras: {', '.join(cameras) or 'none'})")
    return cam


def _load_transform(path: Path) -> Transform:
    """A pair -> vehicle transform; a translation that looks like metres is refused (the pairs
    are a metre or more from the vehicle origin: |t| < 10 can only be metres for millimetres)."""
    node = YamlNode.load(path)
    expect(node, "registration", REGISTRATION_KEYS)
    tf = Transform.from_node(node)
    norm = float(np.linalg.norm(tf.t))
    if norm < METRES_LIKE_MM:
        raise node.error(f"translation t {[round(float(v), 4) for v in tf.t]} (|t| = "
                         f"{norm:.3g}) looks like metres: the vehicle frame is in millimetres")
    return tf


def _baseline(calibration: StereoPair, node: YamlNode) -> StereoPair:
    """A pair whose baseline is not 20-2000 mm has a calibration in other units (metres); one
    whose right camera is to the left of its left one was calibrated from swapped images."""
    b = float(np.linalg.norm(calibration.T))
    if not BASELINE_MM[0] <= b <= BASELINE_MM[1]:
        raise node.error(f"stereo baseline {b:.4g} mm is not plausible "
                         f"({BASELINE_MM[0]:g}-{BASELINE_MM[1]:g} mm): T must be in millimetres")
    swapped = calibration.swapped()
    if swapped is not None:
        raise node.error(f"{swapped} (calibrate the pair again with --left and --right the "
                         "other way round)")
    return calibration


def _database_url(node: YamlNode, base: Path, check: bool = False, checker: bool = False
                  ) -> str:
    """The database URL; a relative SQLite path is relative to the station file, like every
    other path in it (not to the daemon's working directory).  With ``check``, the URL must
    parse and name a database whose driver is installed (nothing is connected), and an SQLite
    one a file that can keep the results (:func:`db.location.sqlite_problem`).

    ``checker`` (``config check``) differs from the daemon's start in two cases: a missing
    :data:`STATE_DIRECTORY` is no error there (the check may run before the service is
    installed; systemd creates it at the service's start), and a file that is not a database
    is an error there, while the daemon starts in fault on it ("database: file is not a
    database") and opens it once it is replaced (the disk fixed: tests/shell/test_serve.py)."""
    url_node = node.mapping(("url",), required=("url",))["url"]
    url = url_node.text()
    prefix = "sqlite:///"
    if url.startswith(prefix) and not url.startswith(prefix + "/") \
            and url[len(prefix):] not in ("", ":memory:"):
        url = prefix + str(base.resolve() / url[len(prefix):])
    if check:
        from db.engine import make_engine
        from db.errors import DbError

        try:
            make_engine(url).dispose()
        except DbError as exc:
            raise url_node.error(_station_forms(str(exc), base)) from None
        # only the checker (its own process) reads the file: the daemon validates a reload
        # while its connections hold SQLite's locks, and closing any descriptor of that file
        # drops every POSIX lock the process holds on it (a db import then deleted the WAL)
        problem = sqlite_problem(url, read_header=checker, as_writer=not checker)
        if problem is None or (not checker and problem.startswith(NOT_SQLITE)):
            pass
        elif checker and problem == missing_folder(STATE_DIRECTORY):
            pass
        else:
            raise url_node.error(problem)
    return url


def _station_forms(message: str, base: Path) -> str:
    """A database URL's message in a station file's terms: the URL forms the db layer gives
    say an SQLite file name is relative to the current folder, which is true of ``--db``;
    in a station file it is relative to the station file's folder (:func:`_database_url`),
    where a daemon under systemd, whose current folder is ``/``, makes it."""
    from db.engine import URL_FORMS

    said = URL_FORMS.replace("relative to the current folder",
                             f"relative to the station file's folder ({base.resolve()})")
    return message.replace(URL_FORMS, said)


#: the service's own folder (systemd/stationd.service: StateDirectory=stationd), made by
#: systemd when the service starts
STATE_DIRECTORY = Path("/var/lib/stationd")


def _records(node: YamlNode, base: Path) -> RecordsConfig:
    r = node.mapping(("images_dir", "save_images"))
    images = _path(r["images_dir"], base) if "images_dir" in r else None
    if images is not None and images.exists() and not images.is_dir():
        # issue 19: accepted with SQLite, and then no selection's images could ever be saved
        raise r["images_dir"].error(f"{images} is a file, not a folder (name the folder the "
                                    "selections' images go to)")
    return RecordsConfig(images, r["save_images"].flag() if "save_images" in r else False)


def _missing(root: YamlNode, key: str) -> None:
    """A required section is missing: never fall back to simulated devices silently."""
    raise root.error(f"missing section '{key}': a station file names its {key} "
                     "(write sim:// URLs explicitly for a simulated station)")


def _left_out(error: ConfigError, told: list[ConfigError]) -> bool:
    """Whether ``error`` is about what :meth:`_Reader.section` changed by leaving out the
    entries it told: it is at one of them or at a mapping holding one (a required key left
    out is missing; a pair sees no reference once the one it saw, mistyped, is left out),
    not a second mistake of the file."""
    if error.key is None:
        return False
    return any(e.key is not None and (e.key == error.key or e.key.startswith(
        (error.key + ".", error.key + "["))) for e in told)


def _pair_items(node: YamlNode) -> list[tuple[str, YamlNode]]:
    """A mapping name -> settings (pairs, cameras); any names, the settings are checked."""
    items = node.named()
    if not items:
        raise node.error("expected a mapping of names to their settings")
    return items


class _Reader:
    """Reads the sections of one station file, for the loader and the checker alike.

    Why one reader for both: the daemon wants the first error (:func:`load_station_config`), a
    person checking a file wants all of them (:func:`read_all`).  The sections are parsed
    by the same code and only what happens to an error differs: with ``collect`` it is recorded
    and reading goes on with the default, each section, camera and pair on its own, so
    independent mistakes are all reported; without, it is raised as before.  Collecting also
    checks device URLs against the driver registries (see :func:`device_url`).
    """

    def __init__(self, base: Path, *, collect: bool, require_devices: bool = False,
                 note: str = "", unregistered: str | None = None) -> None:
        self.base = base
        # a pair whose registration is about to be written anew: not read (a broken one
        # must not stop `calibrate vehicle` from replacing it)
        self.unregistered = unregistered
        self.note = note   # added where a relative path names nothing (a linked file)
        self.collect = collect
        self.require_devices = require_devices
        self.unreadable = False   # the top-level mapping could not be read (all reported)
        self.errors: list[ConfigError] = []
        self.warnings: list[ConfigError] = []
        self.top: dict[str, YamlNode] = {}
        self.camera_urls: dict[str, tuple[str, YamlNode]] = {}  # name -> (URL, its node)

    def guard(self, default: T, fn: Callable[P, T], *args: P.args, **kwargs: P.kwargs) -> T:
        """``fn(...)``; when collecting, an error is recorded and ``default`` returned."""
        if not self.collect:
            return fn(*args, **kwargs)
        try:
            return fn(*args, **kwargs)
        except ConfigError as exc:
            self.errors.append(exc)
            return default

    def section(self, key: str, default: T, parse: Callable[[YamlNode], T]) -> T:
        """The section ``key`` parsed (``default`` without it).  When collecting, each error
        is recorded and the section read again without the entry it names, until it reads
        or an error is the section's own: every error of a section is told, not the first
        (a typo'd key hid ``max_age_s: 500`` below it), and the default is returned."""
        if key not in self.top:
            return default
        if not self.collect:
            return parse(self.top[key])
        node: YamlNode | None = self.top[key]
        found: list[ConfigError] = []
        while node is not None and len(found) < MAX_SECTION_ERRORS:
            try:
                value = parse(node)
            except ConfigError as exc:
                if any(str(exc) == str(e) for e in found):
                    break      # nothing new: stop
                if not _left_out(exc, found):
                    found.append(exc)
                # what leaving an entry out did (a user without the role told wrong misses
                # it) is not told, and the mapping holding it is left out in turn: the
                # entries after it are still read (five bad users were told one a run)
                node = node.without(exc)
                continue
            if not found:
                return value
            break
        self.errors.extend(found)
        return default

    def sections(self, root: YamlNode) -> dict[str, YamlNode]:
        """The top-level sections.  ``YamlNode.mapping`` stops at the first unknown key; when
        collecting, each unknown key is reported at its own line (the known sections are still
        read) by accepting it and reading the mapping again."""
        # another kind of file given as the station: one line, not one per unknown section
        expect(root, "station", STATION_KEYS)
        unknown: set[str] = set()
        while True:
            try:
                m = root.mapping((*STATION_KEYS, *unknown))
                return {k: v for k, v in m.items() if k not in unknown}
            except ConfigError as exc:
                if not self.collect:
                    raise
                key = exc.key
                if key is None or key in STATION_KEYS or key in unknown:
                    self.errors.append(exc)  # not a mapping, a duplicate or a non-string key
                    self.unreadable = True   # its sections are not "missing": not read
                    return {}
                unknown.add(key)
                self.errors.append(ConfigError(
                    f"unknown key (accepted: {', '.join(sorted(STATION_KEYS))})",
                    path=exc.path, line=exc.line, key=key))

    def read(self, path: Path) -> StationConfig:
        """The config of the file at ``path``; an unreadable or malformed file is raised.

        The sections are read in this order (the loader's first error is the first here)."""
        root = YamlNode.load(path)
        self.top = self.sections(root)
        # URLs are checked (form, scheme, database driver) by the checker and for a station
        # the daemon runs: a typo is refused at the start and by a reload, never run in fault
        d, base, check = StationConfig(), self.base, self.collect or self.require_devices
        marker = self.section("marker", d.marker, MarkerSpec.from_node)
        vision = self.section("vision", d.vision, partial(VisionParams.from_node, base_dir=base))
        cameras, names = self.cameras(self.top["cameras"]) if "cameras" in self.top \
            else ({}, [])
        pairs = self.pairs(self.top["pairs"], names) if "pairs" in self.top else {}
        config = StationConfig(
            marker=marker, vision=vision, cameras=cameras, pairs=pairs,
            tool=self.section("tool", d.tool, ToolGeometry.from_node),
            lift=self.section("lift", d.lift, partial(LiftConfig.from_node, check_url=check)),
            wrench=self.section("wrench", d.wrench,
                                partial(WrenchConfig.from_node, check_url=check)),
            matching=self.section("matching", d.matching, MatchingConfig.from_node),
            database_url=self.section("database", d.database_url,
                                      partial(_database_url, base=base, check=check,
                                              checker=self.collect)),
            bolts_path=self.section("bolts", d.bolts_path,
                                    partial(_existing, base=base, what="bolt file",
                                            note=self.note)),
            records=self.section("records", d.records, partial(_records, base=base)),
            http=self.section("http", d.http, HttpConfig.from_node),
            access=self.section("access", d.access, AccessConfig.from_node),
            localize=self.section("localize", d.localize, LocalizeConfig.from_node),
            line=self.section("line", d.line, LineConfig.from_node),
            nok=self.section("nok", d.nok, NokPolicy.from_node),
            opcua=self.section("opcua", d.opcua, partial(OpcUaConfig.from_node, base_dir=base)),
            path=path)
        if check and "lift" in self.top and "wrench" in self.top:
            self.guard(None, _one_device_each, config.lift.url, config.wrench.url,
                       self.top["wrench"])
        if "references" in self.top:   # projected with the pairs' calibrations: after them
            refs = self.section("references", None, partial(
                References.from_node, marker=marker,
                matching_tolerance_mm=config.matching.tolerance_mm,
                pairs={n: (p.calibration, p.to_vehicle) for n, p in pairs.items()}))
            config = replace(config, references=refs)
        # after the sections: a mistake written in the file is told before what is missing
        if self.require_devices and isinstance(root.value(), dict) and not self.unreadable:
            for key in REQUIRED_KEYS:
                if key not in self.top:
                    self.guard(None, _missing, root, key)
        return config

    def cameras(self, node: YamlNode) -> tuple[dict[str, str], list[str] | None]:
        """Name -> URL, and every name defined, a camera with errors included (a pair naming
        it is not also told it is undefined); None when the section itself is unreadable."""
        items = self.guard(None, _pair_items, node)
        if items is None:
            return {}, None
        urls: dict[str, str] = {}
        device: dict[str, str] = {}   # the URL without its options -> the camera naming it
        for name, item in items:
            url = self.guard(None, _camera_url, item,
                             check=self.collect or self.require_devices,
                             sources=self.collect)
            if url is None:
                continue
            same = device.setdefault(url.split("?", 1)[0], name)
            if same != name:   # one camera as two: a pair would triangulate one image twice
                self.guard(None, _refuse, item.error(
                    f"the same camera as {same!r} ({url.split('?', 1)[0]}): every camera "
                    "is one device"))
                continue
            urls[name] = url
            self.camera_urls[name] = (url, item.mapping(("url",))["url"])
        return urls, [name for name, _ in items]

    def pairs(self, node: YamlNode, cameras: Collection[str] | None) -> dict[str, PairConfig]:
        out: dict[str, PairConfig] = {}
        used: dict[str, str] = {}   # camera -> "the left camera of pair P"
        for name, item in self.guard([], _pair_items, node):
            pair = self.guard(None, self.pair, name, item, cameras)
            if pair is None:
                continue
            taken = False
            for side, cam in (("left", pair.left), ("right", pair.right)):
                if cam is None:
                    continue
                if cam in used:   # both images of a pair, or two pairs, from one camera
                    self.guard(None, _refuse, item.mapping(PAIR_KEYS)[side].error(
                        f"camera {cam!r} is already {used[cam]}: a pair needs two cameras "
                        "of its own (one image triangulated with itself gives a confident, "
                        "wrong point)"))
                    taken = True
                used.setdefault(cam, f"the {side} camera of pair {name!r}")
            if not taken:
                out[name] = pair
                if self.collect or self.require_devices:
                    self.sim_cameras(pair, node)
        return out

    def sim_cameras(self, pair: PairConfig, pairs: YamlNode) -> None:
        """A simulated camera shows the view of the pair it names, which the simulated world
        renders for each pair of this file through its calibration: ``sim://PAIR/SIDE`` must
        be the pair and side it serves (another pair's view, or a pair the world does not
        have, leaves the pair in fault for good)."""
        names = list(pairs.mapping(tuple(str(k) for k in pairs.value()))) \
            if isinstance(pairs.value(), dict) else []
        for side, cam in (("left", pair.left), ("right", pair.right)):
            if cam is None or cam not in self.camera_urls:
                continue
            url, url_node = self.camera_urls[cam]
            view = world_view(url)   # the URL was checked with the camera
            if view is None or view == (pair.name, side):
                continue
            sim_pair, sim_side = view
            what = f"the simulated world's {sim_side} view of pair {sim_pair!r}" \
                if sim_pair in names else \
                f"pair {sim_pair!r}, which the simulated world does not have (it renders " \
                f"this file's pairs: {', '.join(names)})"
            self.guard(None, _refuse, url_node.error(
                f"camera {cam!r} is the {side} camera of pair {pair.name!r} but shows "
                f"{what}: write sim://{pair.name}/{side}"))

    def pair(self, name: str, node: YamlNode, cameras: Collection[str] | None,
             ) -> PairConfig | None:
        """One pair; None when collecting and any part of it has errors (all reported)."""
        m = node.mapping(PAIR_KEYS, required=("calibration",))
        errors_before = len(self.errors)
        sides = {side: self.guard(None, _camera_ref, m[side], cameras) if side in m else None
                 for side in ("left", "right")}
        skew_ms = self.guard(None, _max_skew_ms, m["max_skew_ms"]) \
            if "max_skew_ms" in m else 5.0
        cal_path = self.guard(None, _existing, m["calibration"], self.base, "calibration file",
                              self.note)
        tv_path = self.guard(None, _path, m["to_vehicle"], self.base) if "to_vehicle" in m \
            else self.base / f"{name}.vehicle.yaml"
        tv = None
        if tv_path is not None and tv_path.exists() and name != self.unregistered:
            tv = self.guard(None, _load_transform, tv_path)
        calibration = self.guard(None, StereoPair.load, cal_path) \
            if cal_path is not None else None
        if calibration is not None:
            calibration = self.guard(None, _baseline, calibration, m["calibration"])
        if len(self.errors) > errors_before or skew_ms is None or cal_path is None \
                or calibration is None or tv_path is None:
            return None
        if tv is None:  # a pair with errors is told those, not this
            self.warnings.append(m.get("to_vehicle", node).error(
                f"{tv_path} does not exist: the pair is not registered into the vehicle "
                f"frame yet (stationd calibrate vehicle writes it){self.note}"))
        return PairConfig(name, cal_path, calibration, tv_path, tv, sides["left"],
                          sides["right"], skew_ms / 1e3)


def load_station_config(path: str | Path | None, *, station: bool = False,
                        unregistered: str | None = None) -> StationConfig:
    """Read a station config; ``None`` gives the built-in defaults.  The first error is raised
    (a :class:`ConfigError` naming file, line and key); :func:`read_all` lists them all.

    ``station``: the file runs a station (the daemon), so its devices (``cameras``, ``pairs``,
    ``lift``, ``wrench``) must be written; tools that only read its vision or pairs
    (``detect``, ``localize``) take a file without them.  ``unregistered``: a pair whose
    vehicle registration is not read (``calibrate vehicle`` writing it anew)."""
    if path is None:
        return StationConfig()
    p = Path(path)
    reader = _Reader(station_base(p), collect=False, require_devices=station,
                     note=_link_note(p), unregistered=unregistered)
    cfg = reader.read(p)
    if station and cfg.bolts_path is not None and "nok" in reader.top:
        # the NOK policy against the bolt table it applies to: a start or a reload with an
        # override no table has is refused (the running station kept)
        from stationd.boltfile import load_bolts

        table = load_bolts(cfg.bolts_path, tolerance_mm=cfg.matching.tolerance_mm)
        errors = table_errors(reader.top["nok"], table, str(cfg.bolts_path))
        if errors:
            raise errors[0]
    return cfg


@dataclass
class ReadAll:
    """A station file read with every error collected (see :func:`read_all`)."""

    #: the settings, read with defaults where a section was wrong (None: the file itself
    #: could not be read; ``errors`` has why)
    config: StationConfig | None
    #: in the file's line order, then those of the files it names, in the order found
    errors: list[ConfigError]
    #: what the daemon accepts but a person setting the station up wants to know
    warnings: list[ConfigError]
    #: the file's top-level sections, for a check to point at
    sections: dict[str, YamlNode]


def read_all(path: str | Path) -> ReadAll:
    """Read a station file as a person checking it wants it: each section, camera and pair on
    its own, so independent mistakes are reported together; so are the files it names and
    its device URLs (form and scheme; no device is opened).  What needs the bolt table, a
    database or a device is checked by :mod:`stationd.stationcheck`, not here."""
    p = Path(path)
    reader = _Reader(station_base(p), collect=True, require_devices=True, note=_link_note(p))
    try:
        cfg = reader.read(p)
    except ConfigError as exc:
        return ReadAll(None, [exc], [], {})
    return ReadAll(cfg, _in_order(reader.errors, str(p)), reader.warnings, reader.top)


def _in_order(errors: list[ConfigError], path: str) -> list[ConfigError]:
    """The errors of the file at ``path`` in line order (its sections are read in a fixed
    order, not the file's), then those of the files it names, in the order found."""
    own = sorted((e for e in errors if e.path == path), key=lambda e: e.line or 0)
    return own + [e for e in errors if e.path != path]

"""The station file: which section is read by which component, into one typed object.

The station's assembly, above its components: each section is parsed by the component it
configures, its schema beside its code (``MarkerSpec.from_node``, ``NokPolicy.from_node``,
``OpcUaConfig.from_node``...; the devices' by :mod:`stationd.deviceconfig`), through the
generic reader (:mod:`stationd.configread`: raise the first error or collect them all, every
message with file, line and key).  Unknown keys are errors; relative paths are relative to
the station file (for a symbolic link, to the file it points to); there are no hidden sources
(no environment variables, no merged dotfiles).

:func:`load_station_config` raises the first error (the daemon needs a yes or no);
:func:`read_all` reads the same sections with the same code and lists every error, with
those of the files the config names and its device URLs (``stationd config check``).  What
needs more than the file (its NOK policy against the bolt table it names or the tables of
its database) is checked where the station is validated: :mod:`stationd.stationcheck`.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from functools import partial
from pathlib import Path

from db.location import NOT_SQLITE, missing_folder, sqlite_problem
from stationd.access import AccessConfig
from stationd.configread import (
    SectionReader,
    base_folder,
    existing_file,
    in_order,
    link_note,
    present,
    relative_path,
)
from stationd.deviceconfig import (
    DeviceSections,
    LiftConfig,
    PairConfig,
    WrenchConfig,
    one_device_each,
)
from stationd.errors import ConfigError
from stationd.geometry.tool import ToolGeometry
from stationd.lineconfig import LineConfig
from stationd.localize import LocalizeConfig
from stationd.localize.references import References
from stationd.opcua import OpcUaConfig
from stationd.station.matching import MatchingConfig
from stationd.station.policy import NokPolicy
from stationd.vision.marker import MarkerSpec
from stationd.vision.params import VisionParams
from stationd.web.config import HttpConfig
from stationd.yamlio import YamlNode

#: what a station file must name: a file without them would run simulated devices unnoticed
REQUIRED_KEYS = ("cameras", "pairs", "lift", "wrench")
STATION_KEYS = ("marker", "vision", "cameras", "pairs", "tool", "lift", "wrench", "matching",
                "database", "bolts", "records", "http", "access", "localize", "line", "nok",
                "opcua", "references")


@dataclass(frozen=True)
class RecordsConfig:
    """Where tightening records keep their evidence: the stereo frames of each selection."""

    images_dir: Path | None = None
    save_images: bool = False
    #: MB left free on the images' file system: below it a selection's images are not
    #: saved (its tightening is recorded all the same), so that they never fill the disk the
    #: database writes to (an IT administrator's trial: ~400 KB a tightening, the disk
    #: full, the database in fault and the tool off)
    images_keep_free_mb: int = 1024


@dataclass(frozen=True)
class StationConfig:
    """The station's settings, one typed value per section (the defaults where a section is
    not written); ``path``: the file they were read from."""

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


def _database_url(node: YamlNode, base: Path, check: bool = False, checker: bool = False,
                  header: bool = True) -> str:
    """The database URL; a relative SQLite path is relative to the station file, like every
    other path in it (not to the daemon's working directory).  With ``check``, the URL must
    parse and name a database whose driver is installed (nothing is connected), and an SQLite
    one a file that can keep the results (:func:`db.location.sqlite_problem`).

    ``checker`` (``config check``) differs from the daemon's start in two cases: a missing
    :data:`STATE_DIRECTORY` is no error there (the check may run before the service is
    installed; systemd creates it at the service's start), and a file that is not a database
    is an error there, while the daemon starts in fault on it ("database: file is not a
    database") and opens it once it is replaced (the disk fixed: tests/shell/test_serve.py).
    ``header``: the checker reads the file's header; not in the daemon's own process (a
    refused reload's list of further errors), whose connections hold the file's locks."""
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
        # only the checker in its own process reads the file: the daemon validates a reload
        # while its connections hold SQLite's locks, and closing any descriptor of that file
        # drops every POSIX lock the process holds on it (a db import then deleted the WAL)
        problem = sqlite_problem(url, read_header=checker and header, as_writer=not checker)
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


def _records(node: YamlNode, base: Path, check: bool = False,
             checker: bool = False, database_url: str | None = None) -> RecordsConfig:
    """The records' section.  With ``check`` (the checker, the daemon's start and reload),
    the images folder (or, not made yet, its nearest folder that is there) must take files,
    as the database's folder must (:func:`db.location.unwritable_folder`; ``checker``: only
    one nobody may write, the check being run by any user): one the daemon could not write
    was taken, and every selection wrote two warnings ("image ... not saved: Permission
    denied") for as long as it ran.  Only a folder the daemon writes: with ``save_images``,
    or the station's lock there (``database_url`` not an SQLite file); else it only reads
    the images saved earlier (a read-only archive is refused nothing: a start refused,
    exit 2, is not restarted)."""
    r = node.mapping(("images_dir", "save_images", "images_keep_free_mb"))
    images = relative_path(r["images_dir"], base) if "images_dir" in r else None
    there = images is not None and present(r["images_dir"], images, "folder")
    if images is not None and there and not images.is_dir():
        # issue 19: accepted with SQLite, and then no selection's images could ever be saved
        raise r["images_dir"].error(f"{images} is a file, not a folder (name the folder the "
                                    "selections' images go to)")
    save = r["save_images"].flag() if "save_images" in r else False
    if check and images is not None and (save or _lock_there(database_url, images)):
        from db.location import unwritable_folder

        folder = images if there else _nearest_folder(images)
        why = None if folder is None else unwritable_folder(folder, as_writer=not checker)
        if why is not None:
            made = "" if folder == images else f" (where {images} is to be made)"
            raise r["images_dir"].error(f"{why}{made}: the selections' images and, with a "
                                        "database server, the station's lock go there")
    keep = r["images_keep_free_mb"].integer(lo=0) if "images_keep_free_mb" in r \
        else RecordsConfig.images_keep_free_mb
    return RecordsConfig(images, save, keep)


def _lock_there(database_url: str | None, images: Path) -> bool:
    """Whether the station's lock goes in the images folder (a database server's station:
    :func:`stationd.lock.lock_path`)."""
    from stationd.lock import LOCK_NAME, lock_path

    return lock_path(database_url or "", images) == images / LOCK_NAME


def _nearest_folder(path: Path) -> Path | None:
    """The nearest folder above ``path`` that is there (None: none can be looked at)."""
    for up in path.parents:
        try:
            if up.is_dir():
                return up
        except OSError:
            return None
    return None


def _missing(root: YamlNode, key: str) -> None:
    """A required section is missing: never fall back to simulated devices silently."""
    raise root.error(f"missing section '{key}': a station file names its {key} "
                     "(write sim:// URLs explicitly for a simulated station)")



class _StationReader(SectionReader):
    """Reads the sections of one station file, for the loader and the checker alike (the
    generic reader's ``collect``).  ``require_devices``: the file runs a station, so its
    devices must be written and their URLs are checked, as they are when collecting."""

    def __init__(self, path: Path, *, collect: bool, require_devices: bool = False,
                 unregistered: str | None = None, header: bool = True) -> None:
        super().__init__(collect=collect)
        self.header = header     # the database file's header read (collecting, not beside it)
        self.path = path
        self.base = base_folder(path)
        self.note = link_note(path, "the station file")  # where a relative path names nothing
        self.require_devices = require_devices
        self.unregistered = unregistered

    def read(self) -> StationConfig:
        """The config of the file; an unreadable or malformed file is raised.

        The sections are read in this order (the loader's first error is the first here)."""
        path = self.path
        root = YamlNode.load(path)
        self.sections(root, "station", STATION_KEYS)
        # URLs are checked (form, scheme, database driver) by the checker and for a station
        # the daemon runs: a typo is refused at the start and by a reload, never run in fault
        d, base, check = StationConfig(), self.base, self.collect or self.require_devices
        devices = DeviceSections(self, base, check=check, sources=self.collect, note=self.note,
                                 unregistered=self.unregistered)
        marker = self.section("marker", d.marker, MarkerSpec.from_node)
        vision = self.section("vision", d.vision, partial(VisionParams.from_node, base_dir=base))
        cameras, names = devices.cameras(self.top["cameras"]) if "cameras" in self.top \
            else ({}, [])
        pairs = devices.pairs(self.top["pairs"], names) if "pairs" in self.top else {}
        config = StationConfig(
            marker=marker, vision=vision, cameras=cameras, pairs=pairs,
            tool=self.section("tool", d.tool, ToolGeometry.from_node),
            lift=self.section("lift", d.lift, partial(LiftConfig.from_node, check_url=check)),
            wrench=self.section("wrench", d.wrench,
                                partial(WrenchConfig.from_node, check_url=check)),
            matching=self.section("matching", d.matching, MatchingConfig.from_node),
            # (named: the records' folder holds the lock of a database server's station)
            database_url=(database_url := self.section(
                "database", d.database_url, partial(_database_url, base=base, check=check,
                                                    checker=self.collect, header=self.header))),
            bolts_path=self.section("bolts", d.bolts_path,
                                    partial(existing_file, base=base, what="bolt file",
                                            note=self.note)),
            records=self.section("records", d.records, partial(_records, base=base,
                                                               check=check,
                                                               checker=self.collect,
                                                               database_url=database_url)),
            http=self.section("http", d.http, HttpConfig.from_node),
            access=self.section("access", d.access, AccessConfig.from_node),
            localize=self.section("localize", d.localize, LocalizeConfig.from_node),
            line=self.section("line", d.line, LineConfig.from_node),
            nok=self.section("nok", d.nok, NokPolicy.from_node),
            opcua=self.section("opcua", d.opcua, partial(OpcUaConfig.from_node, base_dir=base)),
            path=path)
        if check and "lift" in self.top and "wrench" in self.top:
            self.guard(None, one_device_each, config.lift.url, config.wrench.url,
                       self.top["wrench"])
        if "references" in self.top:   # projected with the pairs' calibrations: after them
            refs = self.section("references", None, partial(
                References.from_node, marker=marker,
                matching_tolerance_mm=config.matching.tolerance_mm,
                pairs={n: (p.calibration, p.to_vehicle) for n, p in pairs.items()},
                registering=self.unregistered))
            config = replace(config, references=refs)
        # after the sections: a mistake written in the file is told before what is missing
        if self.require_devices and isinstance(root.value(), dict) and not self.unreadable:
            for key in REQUIRED_KEYS:
                if key not in self.top:
                    self.guard(None, _missing, root, key)
        return config


@dataclass(frozen=True)
class StationFile:
    """A station file read: its settings, and the sections they were read from, for a check
    of the station against what the file names (its bolt table) to point at their lines."""

    config: StationConfig
    sections: dict[str, YamlNode]


def read_station(path: str | Path, *, station: bool = False,
                 unregistered: str | None = None) -> StationFile:
    """Read a station file, raising the first error (a :class:`ConfigError` naming file,
    line and key); :func:`load_station_config`'s arguments."""
    reader = _StationReader(Path(path), collect=False, require_devices=station,
                            unregistered=unregistered)
    config = reader.read()
    return StationFile(config, reader.top)


def load_station_config(path: str | Path | None, *, station: bool = False,
                        unregistered: str | None = None) -> StationConfig:
    """Read a station config; ``None`` gives the built-in defaults.  The first error is raised
    (a :class:`ConfigError` naming file, line and key); :func:`read_all` lists them all.

    ``station``: the file runs a station (the daemon), so its devices (``cameras``, ``pairs``,
    ``lift``, ``wrench``) must be written and their URLs are checked; tools that only read
    its vision or pairs (``detect``, ``localize``) take a file without them.  What needs the
    bolt table is the station's validation (``stationd.stationcheck.validate_station``: the
    daemon's start and reload).  ``unregistered``: a pair whose vehicle registration is not
    read (``calibrate vehicle`` writing it anew)."""
    if path is None:
        return StationConfig()
    return read_station(path, station=station, unregistered=unregistered).config


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


def read_all(path: str | Path, *, header: bool = True) -> ReadAll:
    """Read a station file as a person checking it wants it: each section, camera and pair on
    its own, so independent mistakes are reported together; so are the files it names and
    its device URLs (form and scheme; no device is opened).  What needs the bolt table, a
    database or a device is checked by :mod:`stationd.stationcheck`, not here.  ``header``
    False: the database file is never opened here (the daemon's own process: see
    :func:`stationd.stationcheck.more_errors`)."""
    p = Path(path)
    reader = _StationReader(p, collect=True, require_devices=True, header=header)
    try:
        cfg = reader.read()
    except ConfigError as exc:
        return ReadAll(None, [exc], [], {})
    return ReadAll(cfg, in_order(reader.errors, str(p)), reader.warnings, reader.top)

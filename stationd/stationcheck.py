"""A station validated as a whole: the station file and what it names beyond itself.

Two callers, one set of checks.  ``stationd config check`` (:func:`check_station`) lists
every error: the file's (:func:`stationd.config.read_all`), the bolt table it names (with
the station's own matching tolerance), the NOK policy's overrides against that table or the
station's database, and warns of bolts without a pset on a controller that takes psets only
(its driver says) and of OPC UA users without security.  The daemon's start and every reload
(:func:`validate_station`) raise the first: the file, the bolt table, the overrides.

Why apart from the configuration reader: the reader turns YAML into typed settings; what
opens a bolt table or a database is the validation of a station, run where it is
validated (here), so both callers check the overrides with the same code
(:func:`table_checks`)."""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from db.location import sqlite_path
from drivers.counting import counted
from drivers.errors import DriverError
from drivers.wrench import takes_targets
from stationd.config import STATE_DIRECTORY, StationConfig, read_all, read_station
from stationd.errors import ConfigError, InputError
from stationd.geometry.tool import marker_upright
from stationd.localize.references import REFERENCES_KEYS
from stationd.station.policy import table_errors
from stationd.yamlio import YamlNode

if TYPE_CHECKING:
    from db.bolts import BoltSpec, BoltTable
    from stationd.boltfile import BoltCheck


@dataclass(frozen=True)
class StationCheck:
    """The outcome of checking a station file: the config when it is valid, else every error.

    ``warnings`` do not make the file invalid: they are what the daemon accepts but a person
    setting the station up wants to know (a pair not registered into the vehicle frame yet).
    ``bolts`` is the check of the bolt table the file names, when it names an existing one;
    its errors are among ``errors``.
    """

    path: str
    config: StationConfig | None
    errors: list[ConfigError] = field(default_factory=list)
    warnings: list[ConfigError] = field(default_factory=list)
    bolts: BoltCheck | None = None

    @property
    def ok(self) -> bool:
        return not self.errors


def validate_station(path: str | Path, warn: Callable[[str], object] | None = None
                     ) -> StationConfig:
    """The whole station, checked before it is used, for the daemon's first start and every
    reload: the file and every file it names (the reader loads calibrations and transforms,
    and checks device URLs), the bolt table with the station's own matching tolerance, the
    NOK policy against that table (an override no table has is refused: at a reload, the
    running station is kept), and its bolts against its controller (a bolt without a pset on
    one that selects psets only).  Raises the first error (one line, file and key).
    ``warn``: told of bolts no pair sees and of references beside a bolt's marker (the
    daemon's journal: a line engineer's reload said only "B51 added", and B51 was missing on
    every vehicle after it)."""
    from stationd.boltfile import check_bolts

    read = read_station(path, station=True)
    cfg = read.config
    if cfg.bolts_path is not None:
        bolts = check_bolts(cfg.bolts_path, tolerance_mm=cfg.matching.tolerance_mm)
        if bolts.table is None:
            raise bolts.errors[0]
        errors = [*table_checks(read.sections, bolts.table, str(cfg.bolts_path)),
                  *psets_only_errors(cfg.wrench.url, bolts)]
        if errors:
            raise errors[0]
        if warn is not None:   # (the daemon's journal, at its start and every reload)
            unseen = _unseen_bolts_warning(cfg, bolts)
            for warning in ([unseen] if unseen is not None else []) + \
                    _references_near_bolts(cfg, bolts, read.sections):
                warn(str(warning))
    return cfg


def more_errors(path: str | Path) -> str:
    """What follows the first error a start or reload refused ``path`` with: ``" (and 2 more
    errors: stationd config check --config PATH lists them)"``, or "" when it was the only
    one (or the file cannot be checked at all).  Why: the refusal names one error, and an
    engineer who fixes it would meet the next at the next reload, one at a time.

    Checked without reading the database file's header: this runs in the daemon, whose
    connections hold SQLite's locks on that file, and closing any other descriptor of it
    drops every POSIX lock the process holds on it; the next program to close its own
    connection (a `db import`, a backup) then took itself for the last one and deleted the
    daemon's WAL, with the results written since (a newcomer's trial)."""
    try:
        n = len(check_station(path, header=False).errors) - 1
    except Exception:     # a bug in a checker must not hide the refusal
        return ""
    if n <= 0:
        return ""
    return f" (and {counted(n, 'more error')}: stationd config check --config {path} lists " \
        "them)"


def table_checks(sections: Mapping[str, YamlNode], table: BoltTable, source: str
                 ) -> list[ConfigError]:
    """What the station file's ``sections`` (already read) say that the bolt tables the
    station runs with (``table``, read from ``source``) contradict: the NOK policy's
    overrides of a pset or a bolt no table has, a loosen pset a bolt is tightened with
    (:func:`stationd.station.policy.table_errors`).  Each error has its line."""
    if "nok" not in sections:
        return []
    return table_errors(sections["nok"], table, source)


def check_station(path: str | Path, *, header: bool = True) -> StationCheck:
    """Check a station file and collect all its errors, for ``stationd config check``.

    Each section, camera and pair is checked on its own, so independent mistakes are reported
    together; so are the files it names (calibration, to_vehicle, HSV, bolt table) and device
    URLs (form and scheme; no device is opened).  The bolt table is checked with the station's
    own matching tolerance, the one its bolts must be told apart with.  An unreadable or
    malformed file is one error.  ``header`` False: the database file is opened only through
    SQLite (:func:`more_errors`).
    """
    p = Path(path)
    read = read_all(p, header=header)
    cfg, errors, warnings, top = read.config, read.errors, read.warnings, read.sections
    if cfg is None:
        return StationCheck(str(p), None, errors)
    bolts = None
    if cfg.bolts_path is not None:
        from stationd.boltfile import check_bolts

        try:
            bolts = check_bolts(cfg.bolts_path, tolerance_mm=cfg.matching.tolerance_mm)
            errors += bolts.errors
        except InputError as exc:  # a tolerance of 0: the loader takes it, the check cannot
            errors.append(top["matching"].error(f"{exc}; the bolt table cannot be "
                                                       "checked"))
    # without a bolt table, the station's database has its tables (read once, for both)
    stored = _database_table(cfg) if cfg.bolts_path is None else None
    if "nok" in top:
        try:
            errors += _nok_errors(top, cfg, bolts, stored)
        except ConfigError:   # the section's own errors are told above (an unknown key hid
            pass              # every other error of the file): its overrides wait for them
    if "nok" in top and not errors:
        from stationd.station.policy import unused_loosen_psets

        warnings += unused_loosen_psets(top["nok"], cfg.nok)
    if bolts is not None and bolts.table is not None and "wrench" in top:
        errors += psets_only_errors(cfg.wrench.url, bolts)
    if bolts is not None and bolts.table is not None and "pairs" in top:
        warning = _unseen_bolts_warning(cfg, bolts)
        if warning is not None:
            warnings.append(warning)
    if bolts is not None and bolts.table is not None:
        warnings += _references_near_bolts(cfg, bolts, top)
    if cfg.bolts_path is None and not read.errors:
        # (a file with errors is read in part: a duplicated key drops its sections, and a
        # station read without its bolts: and database: lines would warn of what it has)
        warning = _no_models_warning(stored, str(p))
        if warning is not None:
            warnings.append(warning)
    warning = _not_mine_warning(cfg.database_url, str(p))
    if warning is not None and not errors:
        warnings.append(warning)
    if _in_missing_state_directory(cfg.database_url) and "database" in top:
        # no error here (systemd makes it), but `stationd run` by hand refused the file the
        # check had called ok (a line engineer's trial)
        warnings.append(top["database"].mapping(("url",), required=("url",))["url"].error(
            f"folder {STATE_DIRECTORY} does not exist yet: systemd makes it when the service "
            "starts (StateDirectory=stationd); create it, owned by the user the station runs "
            "as, to run the daemon by hand (stationd run)"))
    if cfg.opcua is not None and cfg.opcua.users and cfg.opcua.security == ("none",):
        # served, but the MES's user passwords would cross the plant network in clear text
        warnings.append(top["opcua"].error(
            "users with security [none] only: their passwords cross the network in clear "
            "text (the client says 'Sending plain-text password'); offer sign or encrypt too "
            "(with certificates)"))
    warnings += _exposure_warnings(cfg, top, p)
    warnings += _baud_warnings(cfg, top)
    return StationCheck(str(p), cfg if not errors else None, errors, warnings, bolts)


def _exposure_warnings(cfg: StationConfig, top: Mapping[str, YamlNode],
                       path: Path) -> list[ConfigError]:
    """What a security review found the station gave away, each a warning (the daemon runs
    as written): a station file holding the screens' token that every user of the machine
    may read; an images folder (served to the token's holders) holding the database or the
    OPC UA server's key; an OPC UA server anonymous clients read from the network."""
    found: list[ConfigError] = []
    if cfg.http is not None and cfg.http.token and "http" in top:
        try:
            readable = path.stat().st_mode & 0o004
        except OSError:
            readable = 0
        if readable:
            found.append(top["http"].error(
                f"the token is in a file every user of this machine may read ({path}): "
                f"chmod 640 {path} (and chgrp stationd: the daemon's group reads it)"))
    images = cfg.records.images_dir
    if images is not None and "records" in top:
        inside = [(what, there) for what, there in (
            ("the station's database", sqlite_path(cfg.database_url)),
            ("the OPC UA server's key and certificates",
             cfg.opcua.certificates if cfg.opcua is not None else None))
            if there is not None and there.resolve().is_relative_to(images.resolve())]
        for what, there in inside:
            found.append(top["records"].error(
                f"images_dir {images} holds {what} ({there}): the screens serve that folder "
                f"(images only) to every holder of the token; give the images a folder of "
                f"their own (e.g. {images / 'images'})"))
    if cfg.opcua is not None and cfg.opcua.anonymous and not cfg.opcua.on_loopback \
            and "opcua" in top:
        found.append(top["opcua"].error(
            f"anonymous clients may browse, read and subscribe at {cfg.opcua.endpoint} from "
            "the network (the results carry VINs and operators' names): give the MES a user "
            "(users) and write 'anonymous: false', or listen on 127.0.0.1"))
    return found


def _nok_errors(top: Mapping[str, YamlNode], cfg: StationConfig, bolts: Any,
                stored: tuple[BoltTable, str] | str | None) -> list[ConfigError]:
    """The NOK policy's overrides against the bolt tables the station loads: its bolt file's
    (checked), else the tables of its database (``stored``: :func:`_database_table`'s)."""
    if cfg.bolts_path is not None:   # a table with errors is told those, not these
        return [] if bolts is None or bolts.table is None \
            else table_checks(top, bolts.table, str(cfg.bolts_path))
    if stored is None or isinstance(stored, str):
        return []
    table, where = stored
    return table_checks(top, table, where)


def _database_table(cfg: StationConfig) -> tuple[BoltTable, str] | str | None:
    """The bolt tables of the station's database and where they are, when it is an SQLite
    file that opens (read only); where it would be made when it does not exist yet (None:
    another database, or one that does not open: the daemon's to report)."""
    from sqlalchemy.engine import make_url

    from db.errors import DbError
    from db.repository import Repository

    url = make_url(cfg.database_url)
    if url.get_backend_name() != "sqlite" or not url.database:
        return None
    try:
        if not Path(url.database).is_file():
            return url.database
    except OSError:   # cannot be looked at: the file's check says why
        return None
    try:
        with Repository.open(cfg.database_url, read_only=True) as repo:
            return repo.table(), f"the database {url.database}"
    except DbError:
        return None


def _in_missing_state_directory(url: str) -> bool:
    """Whether ``url`` is an SQLite file in the service's own folder, which does not exist
    (yet: :data:`stationd.config.STATE_DIRECTORY`): the very problem the reader lets the
    checker pass (``stationd.config._database_url``), found as the reader finds it."""
    from db.location import missing_folder, sqlite_problem

    return sqlite_problem(url, read_header=False, as_writer=False) == \
        missing_folder(STATE_DIRECTORY)


def _baud_warnings(cfg: StationConfig, top: Mapping[str, YamlNode]) -> list[ConfigError]:
    """A serial link's speed off the standard ones (the lift's, the controller's): taken,
    but said with the speed meant (a technician's trial: ``baud=96000`` passed the check)."""
    from drivers.link import baud_warning
    from drivers.url import parse_url

    out = []
    for section, url in (("lift", cfg.lift.url), ("wrench", cfg.wrench.url)):
        try:
            baud = int(parse_url(str(url)).options.get("baud", ""))
        except (DriverError, ValueError):
            continue      # none, or an error told already
        words = baud_warning(baud)
        if words is not None and section in top:
            out.append(top[section].mapping(("url",), required=("url",))["url"].error(words))
    return out


def _not_mine_warning(url: str, path: str) -> ConfigError | None:
    """The database's folder cannot be written by the user running the check: not an error
    (the check may be run by another user than the service's, which the file does not name),
    but a daemon started by this user would refuse the file, so it is said."""
    from sqlalchemy.engine import make_url
    from sqlalchemy.exc import ArgumentError

    from db.location import unwritable_folder

    try:
        parsed = make_url(url)
    except ArgumentError:
        return None
    if parsed.get_backend_name() != "sqlite" or not parsed.database \
            or parsed.database.startswith("file:") or parsed.database == ":memory:":
        return None
    folder = Path(parsed.database).resolve().parent
    if unwritable_folder(folder, as_writer=False) is not None:
        return None     # nobody can write it: an error of the reader's, told already
    why = unwritable_folder(folder, as_writer=True)
    if why is None:
        return None
    return ConfigError(f"{why} (fine when the service runs as another user, the unit's "
                       "User=: a daemon started by this user would refuse it)", path=path)


def _no_models_warning(found: tuple[BoltTable, str] | str | None,
                       path: str) -> ConfigError | None:
    """A station without a bolt table whose database knows no vehicle model (``found``:
    :func:`_database_table`'s) would refuse every vehicle ("unknown vehicle model code"):
    said before it runs."""
    if found is None or (not isinstance(found, str) and found[0].models):
        return None
    where = f"the database {found} does not exist yet" if isinstance(found, str) \
        else f"{found[1]} has no vehicle model"
    return ConfigError(f"no bolt table (bolts:) and {where}: every vehicle would be refused "
                       "(unknown vehicle model code); name a bolt table, or import one "
                       f"(stationd db import BOLTS.yaml --config {path})", path=path)


def _unseen_bolts_warning(cfg: StationConfig, bolts: BoltCheck) -> ConfigError | None:
    """Bolts that no registered pair would see the wrench's marker on (the wrench upright on
    the bolt, its marker ``tool.length_mm`` below it, projected with each pair's calibration
    as the reference markers are): a position typed in metres, or in another frame, would be
    missing on every vehicle, and ``config check`` called it ok (an engineer's trial).  A
    warning: a pair not registered yet, or a tilted wrench, may still see it.  At the first
    such bolt's line in the bolt file (where it is fixed)."""
    from stationd.localize.references import project

    table = bolts.table
    pairs = [(p.calibration, p.to_vehicle) for p in cfg.pairs.values()
             if p.to_vehicle is not None]
    if table is None or not pairs or len(pairs) < len(cfg.pairs):
        return None     # a pair not registered yet (warned of) may be the one that sees it
    unseen = [(m.name, b) for m in table.models for b in m.bolts
              if not any(project(cal, tv, marker_upright(b.position, cfg.tool), cfg.marker)
                         is not None for cal, tv in pairs)]
    if not unseen:
        return None
    said = [f"{b.bolt_id} ({m}) at {[round(v, 4) for v in b.position]}" for m, b in unseen]
    more = f" and {len(said) - 3} more" if len(said) > 3 else ""
    return _at_bolt(bolts, *unseen[0], (
        f"{'; '.join(said[:3])}{more}: seen by no registered pair (the wrench's marker, "
        f"{cfg.tool.length_mm:g} mm below the bolt with the wrench upright, is not in front "
        "of both cameras and inside both images): check the positions (vehicle frame, mm)"))


def _references_near_bolts(cfg: StationConfig, bolts: BoltCheck,
                           top: Mapping[str, YamlNode]) -> list[ConfigError]:
    """A reference marker near where the wrench's marker is on a bolt (upright, ``tool``
    below it): within ``exclusion_mm`` the wrench there is taken for the reference (refused
    at that bolt); within the check's search window around it (its field's diagonal more),
    the calibration check finds two markers while the wrench is on that bolt and waits (a
    line engineer's trial: a reload with the wrench resting on B32 beside R4 kept B32
    refused 34 s, "R4 ambiguous (2 markers around it)" every 10 s).  At the reference's
    line; a warning: a tilted wrench, or a marker at another depth, differs (distances in
    the vehicle frame, the window's corner counted)."""
    refs, table = cfg.references, bolts.table
    if refs is None or table is None or "references" not in top:
        return []
    try:
        named = dict(top["references"].mapping(REFERENCES_KEYS)["markers"].named())
    except (ConfigError, KeyError):
        return []
    # the check's window is a square of this half-side around the reference: the wrench's
    # rings inside its corner are a second marker there
    half = cfg.marker.field_mm * np.sqrt(2.0) + refs.exclusion_mm
    window = half * np.sqrt(2.0) + cfg.marker.outer_mm
    out: list[ConfigError] = []
    for r in refs.markers:
        d, bolt, model = min(((float(np.linalg.norm(marker_upright(b.position, cfg.tool)
                                                    - np.asarray(r.position_mm))),
                               b.bolt_id, m.name) for m in table.models for b in m.bolts),
                             default=(np.inf, "", ""))
        if d >= window:
            continue
        said = (f"taken for {r.name} there, never for the wrench (within {refs.exclusion_mm:g} "
                "mm of a reference a marker is the reference)" if d <= refs.exclusion_mm else
                f"the calibration check finds two markers at {r.name} while the wrench is on "
                f"{bolt} (its search reaches {window:.0f} mm), and waits")
        message = (f"reference {r.name}: {d:.0f} mm from where the wrench's marker is on "
                   f"{bolt} ({model}), upright: {said}; place it farther from the bolts")
        node = named.get(r.name)
        out.append(node.error(message) if node is not None else ConfigError(message))
    return out


def psets_only_errors(url: str, bolts: BoltCheck) -> list[ConfigError]:
    """Bolts with their own torque and no pset, on a controller that selects psets only (its
    driver says: Open Protocol, and its simulated twin): each would be refused at every
    visit, the station in fault and the bolt missing on every vehicle, so the table is
    refused with them, each at its line (a line engineer's trial: a warning that the check
    and the reload passed)."""
    if bolts.table is None or takes_targets(url):
        return []
    return [_at_bolt(bolts, m.name, b, (
                f"{b.bolt_id} ({m.name}): no pset, and the controller {url} selects psets "
                "only: it would be refused at every visit (give it a pset, or drive the "
                "controller over Modbus)"))
            for m in bolts.table.models for b in m.bolts if b.parameters.pset is None]


def _at_bolt(bolts: BoltCheck, model: str, bolt: BoltSpec, message: str) -> ConfigError:
    """``message`` at the line of ``bolt`` (of ``model``) in its bolt file."""
    node = bolts.nodes.get((model, bolt.bolt_id))
    return node.error(message) if node is not None else ConfigError(message, path=bolts.path)

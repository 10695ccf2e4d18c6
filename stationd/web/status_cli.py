"""``stationd status``'s words: a running daemon's ``/api/status`` as a few lines, and the
form of a daemon's URL (the command itself is :func:`stationd.command_cli.cmd_status`: it
reads the station file to find the daemon, which this layer, below the configuration, cannot).

Why over HTTP: the daemon already serves ``/api/status`` for its screens; the command is a
client of it (no second channel into the daemon, nothing it can change).
"""

from __future__ import annotations

import urllib.parse
from typing import Any

from drivers.counting import counted
from stationd.errors import InputError
from stationd.words import records_waiting

DEFAULT_URL = "http://127.0.0.1:8080/"
EXIT_FAULT = 1          # answered, but the station is in fault: not OK for a monitor
# no status at all (no daemon answers, or it refused: a wrong token): another alarm than a
# station in fault, so a monitoring script can tell them apart
EXIT_UNREACHABLE = 3
#: serving and not in fault, but its last reload was refused (a file that does not read, a
#: device another daemon drives, the screens' new port taken): the station runs on what it
#: read before, and a file that does not read would not start it at the next reboot; a
#: monitor's warning until a reload goes through
EXIT_RELOAD_REFUSED = 4


def status_url(url: str) -> str:
    """``http://host:port[/]`` -> its ``/api/status``; InputError for anything else."""
    try:
        u = urllib.parse.urlsplit(url)
        port = u.port        # checks the port's range
    except ValueError:
        raise InputError(f"--url {url!r}: expected http://host:port/") from None
    if u.scheme not in ("http", "https") or not u.hostname or port == 0:
        raise InputError(f"--url {url!r}: expected http://host:port/")
    if any(c.isspace() or not c.isprintable() for c in url):
        # http.client refuses them later with InvalidURL, which is no ValueError
        raise InputError(f"--url {url!r}: a URL has no spaces or control characters "
                         "(expected http://host:port/)")
    return urllib.parse.urlunsplit((u.scheme, u.netloc, u.path.rstrip("/") + "/api/status",
                                    "", ""))


def counter_words(c: dict[str, Any], held: int = 0,
                  bolts: list[dict[str, Any]] | None = None) -> str:
    """The vehicle's bolts by their state now, in the operator screen's words: "3/50 bolts
    OK, 1 skipped, 1 bolt ending NOK, 2 held" (skipped and held only when there are any).
    Why: "3/50 done, 1 NOK" left the skipped bolts out and read as 1 NOK result, where it
    counts the bolts whose last rundown is NOK (a NOK tightened again to OK is not counted);
    and a line with 3 bolts held for a supervisor said none of them (a supervisor's trial)."""
    nok = int(c.get("nok", 0))
    words = f"{c.get('done', 0)}/{c.get('total', 0)} bolts OK"
    if c.get("skipped"):
        words += f", {c['skipped']} skipped"
    # which ones, each skipped one said (a supervisor's trial: a bolt skipped after its lock
    # was "1 bolt ending NOK", no bolt named, where db report says "B39 skipped by pete")
    named = [str(b["bolt"]) + (", skipped" if b.get("state") == "skipped" else "")
             for b in bolts or [] if b.get("ends_nok")]
    which = f" ({'; '.join(named)})" if named and len(named) == nok else ""
    return words + f", {counted(nok, 'bolt')} ending NOK{which}" + \
        (f", {held} held" if held else "")


def lock_lines(st: dict[str, Any], via: str = "") -> list[str]:
    """Each locked (or held) bolt in the operator screen's words, and who releases it how.
    Why: the journal said "B11 locked ... the operator waits ... for a person's release",
    while ``stationd status`` showed only "1 bolt ending NOK" and "Bring the wrench to a
    bolt": the bolt the station waited on was not in it."""
    locks = list(st.get("locks") or [])
    if not locks:
        return []
    vin = (st.get("vehicle") or {}).get("vin") or "VIN"
    by = st.get("release_by")
    who = "" if by is None else \
        f" (a user with the release right: {', '.join(by)})" if by else \
        " (no user of this station has the release right: access.users and access.roles)"
    # the bolt named where one is locked (a newcomer read BOLT for the only one there was)
    named = list(st.get("locked_bolts") or [])
    bolt = str(named[0]) if len(named) == 1 and len(locks) == 1 else "BOLT"
    held = list(st.get("held_bolts") or [])
    # a held bolt may have been tightened: the outcome the controller shows is entered (a
    # supervisor trial: only "release" was suggested, and a release tightens it again)
    entered = [f"outcome:  stationd enter-outcome {vin} {held[0] if len(held) == 1 else 'BOLT'}"
               f"{via} --ok|--nok --torque NM --angle DEG --comment TEXT --user NAME (a held "
               "bolt: what the controller's screen shows), or the operator screen's Enter "
               "outcome form"] if held else []
    # a held bolt is said as held, with why (a supervisor's trial: holds were listed as
    # locks); a daemon of an earlier version gives no holds: all its locks are "locked"
    holds = [text for text in st.get("holds") or [] if text in locks]
    return [f"locked:   {text}" for text in locks if text not in holds] + \
        [f"held:     {text}" for text in holds] + entered + [
        f"release:  stationd release {vin} {bolt}{via} --comment TEXT --user NAME, or the "
        f"operator screen's Release form{who}"]


#: a device fault's kind (``drivers.keeper.FaultKind``) as ``status`` says it before the
#: reason (a technician's trial: "lift: reported the lift PLC reports a fault ...")
FAULT_WORDS = {"timeout": "timed out", "garbage": "garbled", "refused": "refused",
               "down": "down", "changed": "changed", "rejected": "rejected",
               "reported": "in fault"}


def _fault(d: dict[str, Any]) -> str:
    """A device in fault: its kind in words, then why (``down: disk I/O error``)."""
    kind, reason = str(d.get("kind") or ""), str(d.get("reason") or "")
    word = FAULT_WORDS.get(kind, kind)
    return f"{word}: {reason}" if word and reason else word or reason


def line_lines(line: dict[str, Any] | None) -> list[str]:
    """The line database's forwarding in the operator screen's words (never a fault of the
    station: a status that left it out said nothing while 13 records waited)."""
    if not line:
        return []
    n = int(line.get("backlog") or 0)
    if line.get("alarm"):
        return [f"line:     line database: {line['alarm']}"]
    if line.get("up") is False:
        return [f"line:     line database down ({line.get('last_error') or 'no answer'}): "
                f"{records_waiting(n)} (the station goes on; they are forwarded when it "
                "answers)"]
    return [f"line:     line database: {n} behind"]


def now_line(st: dict[str, Any]) -> str | None:
    """The ``now:`` line: the operator screen's headline in full, or None where it says the
    state line's words again (the state, its reason, or a fault's "FAULT: " and its reason).

    Why in full (``headline_title``, the screen's hover title; ``headline`` from a daemon of
    an earlier version): ``headline`` cuts a fault's reason to a panel's large type, with
    "…", and the status printed it so, under a state line that had the reason whole, in a
    terminal that wraps and a monitoring script's log that keeps every character.  Never cut
    here, in a terminal or not: the device lines are not either."""
    head = st.get("headline_title") or st.get("headline")
    reason = st.get("reason")
    if not head or head in (st["state"], reason) or (reason and head == f"FAULT: {reason}"):
        return None
    return f"now:      {head}"


def format_status(st: dict[str, Any], via: str = "") -> str:
    """The status as a few readable lines; ``via``: how the command that asked reached the
    station (`` --config FILE``, `` --url URL``; "" for the default station file), given
    again in the commands it suggests (run as printed, they reach the same station)."""
    lines = [f"state:    {st['state']}" + (f" ({st['reason']})" if st.get("reason") else "")]
    now = now_line(st)
    if now is not None:
        lines.append(now)
    if st["state"] == "teaching":   # one left on by a session cut off: how it ends
        lines.append(f"teach:    teach mode is on: nothing is tightened until it ends (stationd "
                     f"teach --stop --user NAME{via}, or the commissioning screen's Stop teach "
                     "mode)")
    v = st.get("vehicle")
    c = st.get("counters", {})
    said = "none" if not v else \
        f"{v['vin']} ({v['model']}{', rework' if v.get('rework') else ''}): " \
        f"{counter_words(c, len(st.get('held_bolts') or []), st.get('bolts'))}"
    if v and v.get("at_station") is False:
        # closed: the next one is not loaded (rejected, or not raised yet); the last one was
        # read as the vehicle at the station (a line engineer's trial)
        how = "closed" if not v.get("reopened_by") else \
            f"reopened by {v['reopened_by']}: not at the station yet"
        said = f"none loaded (the last: {said}, {how})"
    lines.append("vehicle:  " + said)
    op = st.get("operator") or {}
    if op.get("user") or op.get("required"):
        lines.append("operator: " + (op.get("user") or "nobody signed in: sign in to tighten"))
    lines += lock_lines(st, via)
    loosen = st.get("to_loosen") or []
    if loosen:
        lines.append("loosen:   " + ", ".join(
            b["bolt"] + (f" (loosen pset {b['loosen_pset']})" if b.get("loosen_pset") is not None
                         else "") for b in loosen) + ": to be loosened first, then tightened")
    if st.get("reload_refused"):
        lines.append(f"config:   reload refused ({st['reload_refused']}): the station runs on "
                     "the configuration it loaded before")
    for name, d in sorted(st.get("devices", {}).items()):
        check = d.get("check") or {}   # a pair's calibration check: up is not trusted
        lines.append(f"device:   {name}: " + (
            "ok" if d["ok"] else str(d.get("reason") or "not opened yet")
            if d.get("kind") == "opening" else _fault(d))
            + (f"; {check['words']}" if d["ok"] and check and not check.get("trusted")
               else "")
            + ("; not registered into the vehicle frame: its frames localize nothing "
               f"(stationd calibrate vehicle --pair {name})"
               if name in st.get("unregistered", ()) else ""))
    lines += line_lines(st.get("line"))
    vers = st.get("versions", {})
    lines.append("versions: " + ", ".join(f"{k} {x}" for k, x in sorted(vers.items())))
    return "\n".join(lines)

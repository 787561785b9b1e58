"""The run directory: created new or resumed, locked while a run writes, described by ``run.json``.

A non-empty directory is refused unless resuming (nothing finished is overwritten); the
lock (``fcntl.flock`` on ``DIR/.lock``) refuses a second run into a directory another run
is writing; ``run.json`` is written before any job, so an interrupted run is always
resumable, and ``--resume`` refuses a selection other than the one it describes (it may
only add methods, and then updates ``run.json``).
"""

from __future__ import annotations

import contextlib
import fcntl
import json
import os
import re
import secrets
import warnings
from pathlib import Path

from rippleb.simulator.conditions import DEFAULT_CONDITION
from rippleb import integrity
from rippleb.errors import InputError
from rippleb import files
from rippleb.files import atomic_path
from rippleb.engine.results import RunWarning
from rippleb.engine.rows import MAX_SEEDS


@contextlib.contextmanager
def run_dir(out, resume: bool, config: dict, on_start=None):
    """Create (or, to resume, check) the run directory and hold its lock while the run writes;
    ``on_start()``, if given, is called once the directory is this run's (``run.json``
    written or checked), before any job starts."""
    if out is None:
        if on_start is not None:
            on_start()
        yield None
        return
    out = Path(out)
    try:
        out.mkdir(parents=True, exist_ok=True)
        probe = out / f".write-test-{secrets.token_hex(8)}"   # a new file: never one planted there
        os.close(os.open(probe, os.O_WRONLY | os.O_CREAT | os.O_EXCL | os.O_NOFOLLOW, 0o600))
        probe.unlink()
    except OSError as exc:
        raise InputError(f"{out}: cannot write the output directory: {exc.strerror or exc}") from None
    refuse_links(out)
    with _locked(out):
        if resume:
            _check_resume(out, config)
        else:
            kept = sorted(p.name for p in out.iterdir() if p.name != ".lock")
            if kept:
                raise InputError(f"{out}: not empty (holds {', '.join(kept[:3])}"
                                 f"{', ...' if len(kept) > 3 else ''}); finish that run with "
                                 f"--resume {out}, or choose another --out")
            with atomic_path(out / "run.json") as tmp:
                tmp.write_text(json.dumps(integrity.seal_config(config), indent=1) + "\n")
        if on_start is not None:
            on_start()
        yield out


#: What rippleb writes in a run directory; none of them may be a symbolic link.
OWN_ENTRIES = (".lock", "run.json", "results.csv", integrity.LEDGER, "provenance.json", "logs")


def refuse_links(out: Path) -> None:
    """Refuse a run directory where a file rippleb writes (:data:`OWN_ENTRIES`, or a log
    in ``logs/``) is a symbolic link (:func:`rippleb.files.refuse_links`)."""
    files.refuse_links(out, OWN_ENTRIES, also_in="logs")


@contextlib.contextmanager
def _locked(out: Path):
    try:
        handle = open(os.open(out / ".lock", os.O_WRONLY | os.O_APPEND | os.O_CREAT | os.O_NOFOLLOW | os.O_CLOEXEC,
                              0o644), "a")
    except OSError as exc:
        raise InputError(f"{out / '.lock'}: cannot open the run's lock: {exc.strerror or exc}") from None
    try:
        try:
            fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            raise InputError(f"{out}: another rippleb run is writing this directory; wait for it to "
                             f"end or choose another --out") from None
        yield
    finally:
        handle.close()


def _check_resume(out: Path, config: dict) -> None:
    """Refuse a selection other than ``run.json``'s; adding methods is the one extension
    allowed, since it only adds rows: ``run.json`` is updated to describe them, and said."""
    saved = read_config(out)
    saved.setdefault("conditions", [DEFAULT_CONDITION])
    differ = [name for name in ("methods", "scenarios", "conditions", "seeds", "log", "sweep", "sealed")
              if saved.get(name) != config.get(name)]
    if differ == ["methods"] and set(saved["methods"]) <= set(config["methods"]):
        added = [m for m in config["methods"] if m not in saved["methods"]]
        warnings.warn(f"{out / 'run.json'}: adding method(s) {', '.join(added)} to this run "
                      f"(run.json updated)", RunWarning, stacklevel=4)
        nonce = (saved.get("integrity") or {}).get("nonce")   # the rows' MACs stay valid
        with atomic_path(out / "run.json") as tmp:
            tmp.write_text(json.dumps(integrity.seal_config({**saved, "methods": config["methods"]}, nonce),
                                      indent=1) + "\n")
        return
    if differ:
        name = differ[0]
        raise InputError(f"{out / 'run.json'}: --resume finishes the run it describes ({name} "
                         f"{saved.get(name)}, asked {config.get(name)}); drop the selection options "
                         f"(more methods may be added) or choose another --out")


def read_config(out) -> dict:
    """The selection saved by a run in ``out/run.json`` (for ``--resume``), checked field
    by field: a file edited by hand or cut short is one line naming the field."""
    from rippleb.reading import RUN_FILE_BYTES, parse_json, read_text

    path = Path(out) / "run.json"
    try:
        config = parse_json(read_text(path, RUN_FILE_BYTES, "run file", in_run_dir=True), path)
    except FileNotFoundError:
        raise InputError(f"{Path(out)}: nothing to resume (no run.json: no run was started there)") from None
    if not isinstance(config, dict) or not isinstance(config.get("methods"), list):
        raise InputError(f"{path}: not a rippleb run file")
    if "log" in config:
        raise InputError(f"{path}: a run on a recorded log cannot be resumed; run it again")
    _check_fields(config, path)
    integrity.check_config(config, path)
    return config


def _check_fields(config: dict, path: Path) -> None:
    for name in ("methods", "scenarios", "conditions"):
        value = config.get(name)
        if value is None and name == "conditions":
            continue   # runs made before conditions existed: same-session
        if not (isinstance(value, list) and value and all(isinstance(v, str) and v.strip() for v in value)):
            raise InputError(f"{path}: field {name!r}: expected a non-empty list of names, got "
                             f"{_shown(value)}")
    seeds = config.get("seeds")
    if not (isinstance(seeds, list) and seeds and all(type(s) is int and s >= 0 for s in seeds)):
        raise InputError(f"{path}: field 'seeds': expected a non-empty list of non-negative whole "
                         f"numbers, got {_shown(seeds)}")
    if len(seeds) > MAX_SEEDS:
        raise InputError(f"{path}: field 'seeds': {len(seeds)} seeds, more than the {MAX_SEEDS} a run may have")
    if "sweep" in config and not isinstance(config["sweep"], dict):
        raise InputError(f"{path}: field 'sweep': expected an object of parameter: values, got "
                         f"{_shown(config['sweep'])}")
    if "sealed" in config:
        check_commitment(config["sealed"], path)


#: A sealed run's commitment as run.json records it (rippleb.engine.sealing.commitment).
_COMMITMENT = re.compile(r"sha256:[0-9a-f]{64}")


def check_commitment(value, path) -> None:
    """Refuse a ``sealed`` field of ``run.json`` that holds no valid commitment."""
    if not isinstance(value, dict) or not isinstance(value.get("commitment"), str) \
            or not _COMMITMENT.fullmatch(value["commitment"]):
        raise InputError(f"{path}: field 'sealed': expected {{\"commitment\": \"sha256:<64 hex digits>\"}}")


def _shown(value) -> str:
    """A field's value in an error line: short, and 'nothing' where it is missing."""
    return "nothing (the field is missing)" if value is None else json.dumps(value)[:60]


def log_dir(out_dir: Path | None) -> Path | None:
    if out_dir is None:
        return None
    logs = out_dir / "logs"
    logs.mkdir(exist_ok=True)
    return logs

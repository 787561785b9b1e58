"""Which rows of a run directory rippleb itself wrote: a keyed hash (HMAC-SHA256) of each.

A method's process is confined (:mod:`rippleb.engine.process.isolation`): it cannot write the run
directory. What it cannot be kept from where the kernel refuses namespaces, and what
anyone else may do to a results file between runs (an edit by hand, a script, a copied
row), is caught here: every row rippleb records gets a MAC under a key that only the
user's rippleb runs read, so ``--resume`` and ``rippleb report`` drop, and name, rows
that rippleb did not write, and ``--resume`` refuses a ``run.json`` changed since.

* The key: 32 random bytes in ``$RIPPLEB_KEY_FILE``, or ``$XDG_STATE_HOME/rippleb/key``
  (``~/.local/state/rippleb/key``), created on first use, readable by its owner only. It
  is loaded only after the fork server started, so no method's process inherits it, and
  a confined worker sees its directory covered. Its id (a hash) is recorded, not the key.
* ``run.json`` carries ``integrity``: the key's id, a random nonce of the run and the MAC
  of the rest of the file; a ``run.json`` without it is not trusted (``--resume`` refuses,
  ``report`` warns), or deleting the field would switch the check off. A row's MAC covers the nonce and every non-empty cell as the
  CSV holds it, so a row copied from another run, or edited in one cell, fails.
* ``DIR/rows.mac``: one MAC per line, appended before its row's CSV line is (a run
  killed in between leaves a MAC without a row, never a row without its MAC).

What it does not do: a run directory made by another user or on another machine is
reported as not verifiable here (its key is not this one), its rows kept; a plugin of
the same user on a host without mount namespaces can read the key file (its permissions
are the user's); a published table is checked by re-running it (docs/reproducibility.md).
"""

from __future__ import annotations

import hashlib
import hmac
import json
import math
import os
import secrets
import warnings
from pathlib import Path

import numpy as np

from rippleb.errors import InputError, RunWarning

KEY_ENV = "RIPPLEB_KEY_FILE"
LEDGER = "rows.mac"
SCHEME = "hmac-sha256 v1"
_LEDGER_HEADER = "# rippleb row MACs, " + SCHEME + ", key {key}\n"


class IntegrityWarning(RunWarning):
    """Rows or a run file that rippleb cannot vouch for."""


def cell_text(value) -> str:
    """A value as the results file holds it: '' for missing or NaN, ``repr`` of a float
    (the shortest text that reads back to the same double)."""
    if value is None:
        return ""
    if isinstance(value, (float, np.floating)):
        return "" if math.isnan(value) else repr(float(value))
    if isinstance(value, np.integer):
        return str(int(value))
    return str(value)


def key_path() -> Path:
    if os.environ.get(KEY_ENV):
        return Path(os.environ[KEY_ENV])
    state = os.environ.get("XDG_STATE_HOME") or os.path.join(os.path.expanduser("~"), ".local", "state")
    return Path(state) / "rippleb" / "key"


def _key_at(path: Path, create: bool) -> bytes | None:
    # Read each time, never cached: a later run's fork server, forked from this process,
    # must not inherit the key in a module's memory (rippleb.run called twice in a session).
    from rippleb.reading import SECRET_BYTES, read_bytes

    try:
        secret = read_bytes(path, SECRET_BYTES, "key file")
    except FileNotFoundError:
        if not create:
            return None
        secret = _create_key(path)
    except (OSError, InputError):   # not a regular file, too large: no key
        return None
    return secret if len(secret) == 32 else None


def _create_key(path: Path) -> bytes:
    """Write a new key, readable by its owner only, atomically: a concurrent run that
    created one first wins, and both use that one."""
    key = secrets.token_bytes(32)
    path.parent.mkdir(parents=True, exist_ok=True, mode=0o700)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.{secrets.token_hex(4)}")
    fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
    try:
        os.write(fd, key)
    finally:
        os.close(fd)
    try:
        os.link(tmp, path)
    except FileExistsError:
        key = path.read_bytes()
    finally:
        tmp.unlink()
    return key


def key(create: bool = True) -> bytes | None:
    """This user's key (created if ``create`` and absent), or None where it cannot be read."""
    try:
        return _key_at(key_path(), create)
    except OSError:
        return None


def key_id(secret: bytes) -> str:
    return hashlib.sha256(b"rippleb key id\0" + secret).hexdigest()[:16]


def _mac(secret: bytes, *parts: bytes) -> str:
    return hmac.new(secret, b"\0".join(parts), hashlib.sha256).hexdigest()


def _config_body(config: dict) -> bytes:
    return json.dumps({k: v for k, v in config.items() if k != "integrity"}, sort_keys=True).encode()


def seal_config(config: dict, nonce: str | None = None) -> dict:
    """``config`` with its ``integrity`` field (a new nonce unless one is given); unchanged
    where no key can be made (a read-only home: the run still runs, unverifiable)."""
    secret = key(create=True)
    if secret is None:
        # said when the run starts, not only when a --resume is refused for it
        warnings.warn(IntegrityWarning(
            f"no key could be read or written at {key_path()}: this run's rows get no keyed hash, so "
            f"'rippleb run --resume' will refuse it; set {KEY_ENV} to a file you can write"), stacklevel=2)
        return {k: v for k, v in config.items() if k != "integrity"}
    nonce = nonce or secrets.token_hex(16)
    return {**config, "integrity": {"scheme": SCHEME, "key": key_id(secret), "nonce": nonce,
                                    "mac": _mac(secret, b"run", nonce.encode(), _config_body(config))}}


def check_config(config: dict, path: Path) -> None:
    """Raise :class:`InputError` if ``run.json`` was changed since rippleb wrote it or has no
    integrity field; one warning where it cannot be checked here (another key)."""
    seal = config.get("integrity")
    if seal is None:
        raise InputError(f"{path}: {UNSEALED}; rippleb will not resume a run it cannot vouch for: start it "
                         f"again with another --out")
    secret = key(create=False)
    if not _ours(seal, secret, path):
        return
    if not _config_intact(secret, config):
        raise InputError(f"{path}: changed since rippleb wrote it (its keyed hash does not match); "
                         f"rippleb will not resume a run it cannot vouch for: start it again with another --out")


#: Why a run.json without its integrity field is not trusted: deleting the field must not
#: be a way past the check (issue 34); only runs older than row MACs lack it honestly.
UNSEALED = ("has no integrity field (deleted, or written before rippleb kept keyed hashes, or where no "
            "key could be written)")


def _ours(seal, secret: bytes | None, path: Path) -> bool:
    """True if ``seal`` was made with this user's key; else one warning why not."""
    if not isinstance(seal, dict) or seal.get("scheme") != SCHEME:
        warnings.warn(f"{path}: its integrity field is not one this rippleb reads; rows not verified",
                      IntegrityWarning, stacklevel=3)
        return False
    if secret is None or seal.get("key") != key_id(secret):
        warnings.warn(f"{path}: made with another rippleb key (another user or machine: {seal.get('key')}); "
                      f"its rows cannot be verified here", IntegrityWarning, stacklevel=3)
        return False
    return True


def _canonical(value) -> str:
    """A cell's text as written, with numbers in one spelling: the row recorded holds an
    int where the row read back holds the float the reader made of it (``140000`` and
    ``140000.0``); both must give one MAC."""
    text = cell_text(value)
    try:
        return repr(float(text))
    except ValueError:
        return text


def row_mac(secret: bytes, nonce: str, row: dict) -> str:
    cells = sorted((str(name), _canonical(value)) for name, value in row.items())
    body = json.dumps([cell for cell in cells if cell[1] != ""], separators=(",", ":"))
    return _mac(secret, b"row", nonce.encode(), body.encode())


class Ledger:
    """The MACs of one run directory's rows (``DIR/rows.mac``), written beside its rows.

    Made from the run directory's ``run.json``; with no ``integrity`` field there (a run
    without a key) it records nothing.
    """

    def __init__(self, run_dir: Path):
        self.path = Path(run_dir) / LEDGER
        seal = _read_seal(Path(run_dir))
        secret = key(create=False)
        usable = isinstance(seal, dict) and secret is not None and seal.get("key") == key_id(secret)
        self._secret = secret if usable else None
        self._nonce = str(seal.get("nonce")) if usable else ""

    @property
    def active(self) -> bool:
        return self._secret is not None

    def mac(self, row: dict) -> str:
        return row_mac(self._secret, self._nonce, row)

    def append(self, row: dict) -> None:
        if self.active:
            new = not self.path.is_file()
            from rippleb.files import open_appending

            with open_appending(self.path, encoding="ascii") as fh:
                fh.write((_LEDGER_HEADER.format(key=key_id(self._secret)) if new else "") + self.mac(row) + "\n")

    def rewrite(self, rows: list[dict]) -> None:
        from rippleb.files import atomic_path

        if self.active:
            with atomic_path(self.path) as tmp:
                tmp.write_text(_LEDGER_HEADER.format(key=key_id(self._secret))
                               + "".join(self.mac(row) + "\n" for row in rows), encoding="ascii")


def _config_intact(secret: bytes, config: dict) -> bool:
    """Whether ``config`` (a run.json with its integrity field) is as rippleb wrote it."""
    seal = config["integrity"]
    expected = _mac(secret, b"run", str(seal.get("nonce")).encode(), _config_body(config))
    return hmac.compare_digest(expected, str(seal.get("mac")))


def _read_config(run_dir: Path) -> dict:
    """``run_dir/run.json``, or {} where it cannot be read as an object (a link, a FIFO, too
    large or too deep: :mod:`rippleb.reading`; the report's own reading of it says why)."""
    from rippleb.reading import RUN_FILE_BYTES, parse_json, read_text

    path = run_dir / "run.json"
    try:
        config = parse_json(read_text(path, RUN_FILE_BYTES, "run file", in_run_dir=True), path)
    except (OSError, InputError):
        return {}
    return config if isinstance(config, dict) else {}


def _read_seal(run_dir: Path):
    return _read_config(run_dir).get("integrity")


def verified_rows(run_dir: Path, rows: list[dict], results_path: Path) -> list[dict]:
    """``rows`` without those rippleb did not write into ``run_dir``, with one warning
    naming how many and the first; all of them (and at most one warning) where the
    directory cannot be checked here."""
    config = _read_config(Path(run_dir))
    seal = config.get("integrity")
    if seal is None:
        _warn_unsealed(Path(run_dir), config)
        return rows
    secret = key(create=False)
    if not _ours(seal, secret, Path(run_dir) / "run.json"):
        return rows
    if not _config_intact(secret, config):
        warnings.warn(f"{Path(run_dir) / 'run.json'}: changed since rippleb wrote it (its keyed hash does not "
                      f"match); what it says of the run (seeds, selection) is not rippleb's", IntegrityWarning,
                      stacklevel=3)
    from rippleb.reading import LEDGER_BYTES, read_text

    try:
        known = set(read_text(Path(run_dir, LEDGER), LEDGER_BYTES, "ledger of row MACs", in_run_dir=True,
                              encoding="ascii").split())
    except FileNotFoundError:
        known = set()
    nonce = str(seal.get("nonce"))
    kept, foreign = [], []
    for row in rows:
        (kept if row_mac(secret, nonce, row) in known else foreign).append(row)
    if foreign:
        first = foreign[0]
        warnings.warn(f"{results_path}: ignored {len(foreign)} row(s) that rippleb did not write or that "
                      f"were changed since (first: {first.get('method')}/{first.get('scenario')}/"
                      f"{first.get('condition')}/seed {first.get('seed')}); --resume runs them again",
                      IntegrityWarning, stacklevel=3)
    return kept


def _warn_unsealed(run_dir: Path, config: dict) -> None:
    """One warning for a run directory whose rows cannot be verified because ``run.json``
    lacks its integrity field, or is gone while the row MACs remain. A bare results file
    (no run.json, no rows.mac: a published table, a file made by a script) is read as it is."""
    if config:
        warnings.warn(f"{run_dir / 'run.json'}: {UNSEALED}; its rows are not verified", IntegrityWarning,
                      stacklevel=4)
    elif (run_dir / LEDGER).exists() and not (run_dir / "run.json").exists():
        warnings.warn(f"{run_dir}: holds {LEDGER} but no run.json (deleted?); its rows are not "
                      f"verified", IntegrityWarning, stacklevel=4)

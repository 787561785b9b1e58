"""Sealed runs: devices and noise drawn from a secret salt that no method can know.

Why: the simulator and the seeds are public, so a method could find out which scenario,
condition and seed it is scored on (the log's ``meta`` says so, and a brute force over a
few seeds finds it otherwise), call :func:`rippleb.simulate` itself and return the truth
(an RMS error of 0.000). That cannot be forbidden; a sealed run takes the exact truth
out of reach. The runner draws a random salt (:mod:`secrets`) and simulates each seed
``s`` on the device seed ``HMAC-SHA256(salt, s)`` instead of ``s``: the device, the
nominal arm model, the index pulse and the noise are all drawn from it, so a method that
re-simulates ``s`` gets another device, and is scored as that wrong device. (The public
scenarios still tell it much of the torque: docs/robustness.md measures how much.)

Where the salt lives (docs/robustness.md, "Sealed runs"):

* it is drawn, or read back for ``--resume``, only after the fork server that forks every
  fit and row has been forked, so that server and its rows never hold it;
* only simulation jobs use it, and those are forked from the runner directly, never sent
  through the fork server (whose freed memory every later row would inherit); they run
  rippleb's code only, and the visible logs they write name the public seed;
* while it is in memory the runner is not dumpable (``PR_SET_DUMPABLE``, for the whole
  of every run: :func:`rippleb.engine.process.isolation.undumpable`), so where the kernel refuses PID
  namespaces a row of the same user cannot read it (or the truths) through
  ``/proc/<runner>/mem`` either;
* ``run.json`` records only its commitment (``sha256:`` + SHA-256 of the 32 salt bytes);
  the salt itself is written to the file the user named (``--sealed FILE``) when the
  run ends, after every job process has ended. No file holds it while methods run.

``--resume`` of a sealed run needs that file (``--salt-file FILE``, ``-`` for stdin), and
checks it against the commitment. The command-line options are added here, not in
:mod:`rippleb.cli`.
"""

from __future__ import annotations

import contextlib
import hashlib
import hmac
import os
import secrets
import sys
from pathlib import Path

from rippleb.errors import InputError
from rippleb.printable import markdown_code

SALT_BYTES = 32
#: The result column that marks the rows of a sealed run (absent from unsealed runs).
SEALED_COLUMN = "sealed"
_DOMAIN = b"rippleb sealed device seed v1:"


class Seal:
    """The salt of one sealed run, in this process only.

    Parameters
    ----------
    salt
        ``SALT_BYTES`` random bytes.
    save_to
        Where to write the salt when the run ends (a new sealed run), or None (resumed).
    read_from
        The file a resumed run read the salt from (None: standard input, or a new run).
    """

    def __init__(self, salt: bytes, save_to: Path | None = None, read_from: Path | None = None):
        self._salt = bytearray(salt)   # a bytearray can be wiped when the run ends
        self.save_to = save_to
        self.read_from = read_from
        self.commitment = commitment(salt)

    def files(self) -> tuple[Path, ...]:
        """The salt's files, which a method's worker sees covered (:mod:`rippleb.engine.process.isolation`)."""
        return tuple(path for path in (self.save_to, self.read_from) if path is not None)

    def device_seed(self, seed: int) -> int:
        """The seed a sealed run simulates for the public ``seed``: 256 bits of
        ``HMAC-SHA256(salt, seed)`` (``rippleb.simulate`` takes any non-negative int)."""
        digest = hmac.new(bytes(self._salt), _DOMAIN + str(int(seed)).encode(), hashlib.sha256).digest()
        return int.from_bytes(digest, "big")

    def hex(self) -> str:
        return bytes(self._salt).hex()

    def wipe(self) -> None:
        """Overwrite the salt in place (best effort: copies made by hmac are freed, not wiped)."""
        self._salt[:] = bytes(len(self._salt))


def draw_salt() -> bytes:
    """A new salt from the operating system's secure random source."""
    return secrets.token_bytes(SALT_BYTES)


def commitment(salt: bytes) -> str:
    """``sha256:`` + the SHA-256 of the salt bytes: what ``run.json`` records."""
    return "sha256:" + hashlib.sha256(bytes(salt)).hexdigest()


# ----------------------------------------------------------------------------- before the run


def check_new_salt_path(path, out) -> Path:
    """The ``--sealed FILE`` of a new run: a new file outside the run directory, in a
    directory that exists. Checked before the run starts (the path is no secret)."""
    path = Path(path)
    if str(path) in ("", "-"):
        raise InputError("--sealed: give the file the salt is written to when the run ends")
    if path.exists():
        raise InputError(f"{path}: --sealed writes a new salt file and never overwrites one; "
                         f"choose another file")
    if out is not None and Path(out).resolve() in path.resolve().parents:
        raise InputError(f"{path}: the salt file must be outside the run directory {out} (methods "
                         f"could read it there)")
    parent = path.resolve().parent
    if not parent.is_dir() or not os.access(parent, os.W_OK):
        raise InputError(f"{path}: --sealed cannot write the salt there ({parent} is not a writable directory)")
    return path


#: ``run.json``'s mark of a run on the devices of a salt it was given (``--salt-file``
#: without ``--resume``): a replay of a sealed comparison, not one itself.
GIVEN = "given"


def open_seal(out, resume: bool, config: dict, *, sealed, salt_file) -> Seal | None:
    """The seal of this run, drawn or read now: call it after the fork server started.

    A new run with ``sealed`` (the salt file to write at the end) draws a salt; a new run
    with ``salt_file`` re-runs the devices of that salt (a published one, to verify its
    rows: ``run.json`` marks it ``"salt": "given"``); a resumed run reads the salt of
    ``out/run.json``'s commitment from ``salt_file``. Sets ``config["sealed"]`` to the
    commitment, so ``run.json`` records it and ``--resume`` compares it.
    """
    if not resume:
        if sealed is not None and salt_file is not None:
            raise InputError("--sealed draws a new salt and --salt-file re-runs the devices of a given one; "
                             "give one of them")
        if sealed is None and salt_file is None:
            return None
        if out is None:
            raise InputError("a sealed run needs an output directory (its run.json records the "
                             "salt's commitment)")
        if salt_file is not None:
            seal = Seal(read_salt(salt_file), read_from=None if str(salt_file) == "-" else Path(salt_file))
            config["sealed"] = {"commitment": seal.commitment, "salt": GIVEN}
            return seal
        seal = Seal(draw_salt(), save_to=Path(sealed))
        config["sealed"] = {"commitment": seal.commitment}
        return seal
    if sealed is not None:
        raise InputError("--sealed starts a new sealed run; to resume one, give its salt with "
                         "--salt-file FILE")
    from rippleb.engine.rundir import read_config

    saved = read_config(Path(out)).get("sealed")
    seal = _resumed_seal(Path(out), saved, salt_file)
    if seal is not None:
        config["sealed"] = dict(saved)
    return seal


def _resumed_seal(out: Path, saved, salt_file) -> Seal | None:
    where = out / "run.json"
    if saved is None:
        if salt_file is not None:
            raise InputError(f"{where}: not a sealed run; drop --salt-file")
        return None
    expected = saved["commitment"]
    if salt_file is None:
        raise InputError(f"{where}: a sealed run ({expected[:19]}...); --resume needs its salt: "
                         f"add --salt-file FILE (the file --sealed wrote)")
    salt = read_salt(salt_file)
    if commitment(salt) != expected:
        raise InputError(f"{_name(salt_file)}: not the salt of this run (its SHA-256 differs from the "
                         f"commitment {expected[:19]}... in {where})")
    return Seal(salt, read_from=None if str(salt_file) == "-" else Path(salt_file))


def read_salt(path) -> bytes:
    """The salt in ``path`` (``-``: standard input): 64 hex digits."""
    from rippleb.reading import SECRET_BYTES, read_text

    try:
        text = sys.stdin.read(SECRET_BYTES + 1) if str(path) == "-" else \
            read_text(path, SECRET_BYTES, "salt file", encoding="ascii")
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"{_name(path)}: cannot read the salt: {getattr(exc, 'strerror', None) or exc}") from None
    words = text.split()
    try:
        salt = bytes.fromhex(words[0]) if len(words) == 1 else b""
    except ValueError:
        salt = b""
    if len(salt) != SALT_BYTES:
        raise InputError(f"{_name(path)}: not a rippleb salt file (expected {2 * SALT_BYTES} hex digits)")
    return salt


def _name(path) -> str:
    return "standard input" if str(path) == "-" else str(path)


# ----------------------------------------------------------------------------- during and after


def release(seal: Seal | None, run_started: bool) -> None:
    """After every job of the run has ended: write a new run's salt to its file, wipe it
    here."""
    if seal is None:
        return
    try:
        save_salt(seal, run_started)
    finally:
        seal.wipe()


def save_salt(seal: Seal | None, run_started: bool) -> None:
    """Write a new run's salt to its file once every job has ended; a run that never
    wrote ``run.json`` has no rows to verify, so nothing is written. The file is created
    new (never overwritten), readable by its owner only."""
    if seal is None or seal.save_to is None or not run_started:
        return
    created = False
    try:
        fd = os.open(seal.save_to, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
        created = True
        with os.fdopen(fd, "w", encoding="ascii") as fh:
            fh.write(seal.hex() + "\n")
    except OSError as exc:
        if created:  # a file cut short (a full disk) would be taken for a wrong salt later
            with contextlib.suppress(OSError):
                os.unlink(seal.save_to)
        # Nothing else holds the salt: say it rather than lose every sealed row's proof.
        print(f"rippleb: error: {seal.save_to}: cannot write the salt ({exc.strerror or exc}); "
              f"it is {seal.hex()}: save it now", file=sys.stderr)
        return
    print(f"rippleb: sealed run: the salt is in {seal.save_to}; keep it apart from the methods' "
          f"authors until the results are published (its {seal.commitment[:19]}... commitment is in "
          f"run.json)", file=sys.stderr)


def redact(argv: list[str]) -> list[str]:
    """``argv`` with the salt file paths replaced by ``SALT_FILE``: provenance.json, in the
    run directory, must not point a method of a later ``--resume`` to the salt."""
    out, hide = [], False
    for word in argv:
        if hide:
            out.append("SALT_FILE")
            hide = False
            continue
        flag = word.split("=", 1)[0]
        if flag in ("--sealed", "--salt-file"):
            hide = "=" not in word
            out.append(word if hide else f"{flag}=SALT_FILE")
            continue
        out.append(word)
    return out


# ----------------------------------------------------------------------------- the report


def sealed_rows(frame) -> int:
    """How many of ``frame``'s rows ran on devices drawn from a secret salt."""
    if SEALED_COLUMN not in frame:
        return 0
    return int((frame[SEALED_COLUMN].astype(str).str.lower() == "true").sum())


def sealed_text(frame, run: dict) -> str:
    """The report's sentence on whether its rows were sealed (``run`` is what
    ``run.json`` and ``provenance.json`` recorded)."""
    n = len(frame)
    sealed = sealed_rows(frame)
    if sealed == 0:
        return ("Not sealed: these devices are those of the public seeds, which a method could "
                "re-simulate to read off the truth; a comparison that matters runs sealed "
                "(`rippleb run --sealed FILE`, docs/robustness.md).")
    recorded = run.get("sealed") if isinstance(run.get("sealed"), dict) else {}
    commitment_text = recorded.get("commitment") or "not recorded"
    if sealed < n:
        return (f"Partly sealed: {sealed} of {n} rows ran on devices drawn from a secret salt, the "
                f"others on the public seeds' devices (rows of different runs mixed?); only the "
                f"sealed rows are safe from a method that re-simulates its scenario.")
    if recorded.get("salt") == GIVEN:
        return (f"Replayed: all {n} rows ran on the devices of a salt given to the run (commitment "
                f"`{commitment_text}` in run.json), to verify a sealed comparison's rows; the salt was "
                f"known before the run, so these rows are no sealed comparison themselves.")
    return (f"Sealed: all {n} rows ran on devices drawn from a secret salt (commitment "
            f"{markdown_code(commitment_text)} in run.json), so no method could re-simulate them; the signal "
            f"figures, re-simulated by the report, show the public seeds' devices instead.")


def published_salt(run: dict, salt_file) -> bytes:
    """The salt of the sealed run whose ``run.json`` said ``run`` (its provenance), read
    from ``salt_file`` and checked against the run's commitment, to publish beside its
    report (``rippleb report --salt-file``); one line naming the file otherwise."""
    recorded = run.get("sealed") if isinstance(run.get("sealed"), dict) else {}
    if not recorded.get("commitment"):
        raise InputError(f"--salt-file {salt_file}: the run is not sealed (its run.json records no "
                         f"commitment): there is no salt to publish")
    salt = read_salt(salt_file)
    if commitment(salt) != recorded["commitment"]:
        raise InputError(f"{_name(salt_file)}: not the salt of this run (its SHA-256 differs from the "
                         f"commitment {recorded['commitment'][:19]}... in run.json)")
    return salt

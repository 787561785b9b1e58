"""Hashed artefacts and plain-array messages between the runner and its jobs.

Every file a job reads that another process wrote (a simulated log, a fitted method) is
an :class:`Artefact`: its path plus the SHA-256 of its bytes, recorded by the runner
when the file was made. A job verifies the hash before it uses the file, and before any
method code is imported, so a plugin that rewrites a cache file fails the rows that
would read it instead of forging them.

Logs and messages are ``.npz`` archives of plain arrays read with
``allow_pickle=False``: no bytes a job sends are ever unpickled by the runner.
"""

from __future__ import annotations

import hashlib
import io
import json
import os
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from rippleb.data import JointSpec, SensorLog
from rippleb.errors import RipplebError
from rippleb.files import atomic_path


class TamperedError(RipplebError):
    """A cached artefact's bytes no longer match the hash recorded when it was written."""


@dataclass(frozen=True)
class Artefact:
    """A file and the SHA-256 (hex) of the bytes it must hold."""

    path: str
    sha256: str

    def read(self) -> bytes:
        """The file's bytes, verified.

        Raises
        ------
        TamperedError
            The file is missing or changed since it was written.
        """
        try:
            data = Path(self.path).read_bytes()
        except OSError as exc:
            raise TamperedError(f"cache file {self.path} is gone ({exc.strerror or exc})") from None
        if hashlib.sha256(data).hexdigest() != self.sha256:
            raise TamperedError(f"cache file {Path(self.path).name} changed after the runner wrote it "
                                f"(SHA-256 mismatch): refusing to use it")
        return data


    @classmethod
    def of_file(cls, path) -> "Artefact":
        """A file written already (a fitted state the pool received into it), made read-only
        and hashed as it is now, read in chunks."""
        os.chmod(path, 0o444)
        with open(path, "rb") as fh:
            return cls(str(path), hashlib.file_digest(fh, "sha256").hexdigest())


def digest(data: bytes) -> str:
    """SHA-256 of ``data`` as hex."""
    return hashlib.sha256(data).hexdigest()


def store(path: Path, data: bytes) -> Artefact:
    """Write ``data`` atomically and read-only; return its artefact."""
    with atomic_path(path) as tmp:
        tmp.write_bytes(data)
        os.chmod(tmp, 0o444)
    return Artefact(str(path), digest(data))


def pack(arrays: dict, info: dict | None = None) -> bytes:
    """Plain arrays plus a JSON ``info`` dict as ``.npz`` bytes."""
    buf = io.BytesIO()
    np.savez(buf, __info__=np.array(json.dumps(info or {}, default=str)),
             **{k: np.asarray(v) for k, v in arrays.items() if v is not None})
    return buf.getvalue()


def unpack(data: bytes) -> tuple[dict, dict]:
    """The arrays and info of :func:`pack` bytes (no pickle: object arrays raise)."""
    with np.load(io.BytesIO(data), allow_pickle=False) as npz:
        arrays = {name: npz[name] for name in npz.files if name != "__info__"}
        info = json.loads(str(npz["__info__"])) if "__info__" in npz.files else {}
    if not isinstance(info, dict):
        raise ValueError("message info is not a JSON object")
    return arrays, info


def log_bytes(log: SensorLog) -> bytes:
    """A log (its present columns, spec and meta) as :func:`pack` bytes."""
    return pack(log.columns(), {"spec": asdict(log.spec), "meta": log.meta})


def log_from_bytes(data: bytes) -> SensorLog:
    """The log stored by :func:`log_bytes`."""
    arrays, info = unpack(data)
    return SensorLog(spec=JointSpec(**info["spec"]), meta=info.get("meta", {}), **arrays)


def load_log(source) -> SensorLog:
    """A :class:`SensorLog` given as itself or as an :class:`Artefact` (verified)."""
    if isinstance(source, SensorLog):
        return source
    return log_from_bytes(source.read())

"""Hashed artefacts and plain-array messages between the runner and its jobs.

Every file a job reads that another process wrote (a simulated log, a fitted method) is
an :class:`Artefact`: its path plus the SHA-256 of its bytes, recorded by the runner
when the file was made. A job verifies the hash before it uses the file, and before any
method code is imported, so a plugin that rewrites a cache file fails the rows that
would read it instead of forging them.

Logs and messages are ``.npz`` archives of plain arrays read with
``allow_pickle=False``; a row's result, sent once per row, is a plain message instead
(:func:`pack_raw`: a JSON header and the arrays' bytes, no archive to build, no checksum to
compute). No bytes a job sends are ever unpickled by the runner.
"""

from __future__ import annotations

import hashlib
import io
import json
import math
import os
import struct
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


#: The first bytes of a :func:`pack_raw` message, then its header's length (4 bytes, little-endian).
RAW_MAGIC = b"rippleb-raw-1\n"
_HEADER_LENGTH = struct.Struct("<I")
#: What a raw message's arrays may hold: numbers only (never objects, never structured records).
RAW_KINDS = "biuf"
_ALIGN = 64


def pack_raw(arrays: dict, info: dict | None = None) -> bytes:
    """Plain arrays plus a JSON ``info`` dict as one message: :data:`RAW_MAGIC`, the
    header's length, the header (``info`` and each array's name, dtype, shape and offset)
    and the arrays' bytes, each at an offset aligned to 64 bytes. Read by :func:`unpack`."""
    arrays = {k: np.asarray(v, order="C") for k, v in arrays.items() if v is not None}
    entries, offset = [], 0
    for name, value in arrays.items():
        entries.append([name, value.dtype.str, list(value.shape), offset])
        offset += -(-value.nbytes // _ALIGN) * _ALIGN
    header = json.dumps({"info": info or {}, "arrays": entries}, default=str).encode()
    start = -(-(len(RAW_MAGIC) + _HEADER_LENGTH.size + len(header)) // _ALIGN) * _ALIGN
    parts = [RAW_MAGIC, _HEADER_LENGTH.pack(len(header)), header, bytes(start - len(RAW_MAGIC) - _HEADER_LENGTH.size - len(header))]
    for value in arrays.values():
        parts += [memoryview(value.reshape(-1).view(np.uint8)), bytes(-value.nbytes % _ALIGN)]
    return b"".join(parts)


def _unpack_raw(data: bytes) -> tuple[dict, dict]:
    """The arrays (fresh copies) and info of :func:`pack_raw` bytes; ``ValueError`` for
    anything else: a header that is not JSON of that shape, a dtype that is not a plain
    number (:data:`RAW_KINDS`), an array that does not lie inside the message."""
    at = len(RAW_MAGIC) + _HEADER_LENGTH.size
    if len(data) < at:
        raise ValueError("message cut short")
    (length,) = _HEADER_LENGTH.unpack_from(data, len(RAW_MAGIC))
    if at + length > len(data):
        raise ValueError("message header beyond its end")
    header = json.loads(data[at:at + length])
    if not isinstance(header, dict) or not isinstance(header.get("arrays"), list):
        raise ValueError("message header is not a JSON object with arrays")
    start = -(-(at + length) // _ALIGN) * _ALIGN
    arrays = {}
    for entry in header["arrays"]:
        name, dtype, shape, offset = entry
        dtype = np.dtype(dtype)
        if (not isinstance(name, str) or dtype.kind not in RAW_KINDS or dtype.hasobject or dtype.fields
                or not all(isinstance(n, int) and n >= 0 for n in shape) or not isinstance(offset, int)
                or offset < 0):
            raise ValueError(f"message array {str(name)[:40]!r} is not plain numbers")
        count = math.prod(shape)
        if start + offset + count * dtype.itemsize > len(data):
            raise ValueError(f"message array {name[:40]!r} lies beyond the message's end")
        # A copy: an array of its own, allocated as any other (its alignment is numpy's).
        arrays[name] = np.frombuffer(data, dtype, count, start + offset).reshape(shape).copy()
    return arrays, header.get("info", {})


def unpack(data: bytes) -> tuple[dict, dict]:
    """The arrays and info of :func:`pack` or :func:`pack_raw` bytes (no pickle: object arrays raise)."""
    if data[:len(RAW_MAGIC)] == RAW_MAGIC:
        arrays, info = _unpack_raw(data)
        if not isinstance(info, dict):
            raise ValueError("message info is not a JSON object")
        return arrays, info
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

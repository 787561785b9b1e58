"""Logs in files: :func:`read_log` reads a recorded joint's CSV or Parquet file (with its
joint description) into a checked :class:`~rippleb.data.SensorLog`; :func:`write_log` and
:func:`write_columns` write one.

Examples
--------
>>> import numpy as np, tempfile, pathlib
>>> from rippleb import JointSpec, make_log, read_log, write_log
>>> spec = JointSpec()
>>> log = make_log(spec, {"t": np.arange(40) / spec.fs, "strain": np.zeros(40),
...                       "encoder": np.zeros(40), "current": np.zeros(40)})
>>> path = write_log(log, pathlib.Path(tempfile.mkdtemp()) / "rec.csv")
>>> len(read_log(path))
40
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np

from rippleb.data import JointSpec, SensorLog, holds_booleans, make_log
from rippleb.errors import InputError
from rippleb.files import atomic_path
from rippleb.log_columns import LOG_COLUMNS, MAX_CHANNELS, channel_names
from rippleb.reading import LOG_BYTES, check_file, duplicated_columns, read_table
from rippleb.timebase import check_steps, uniform_rate

#: Most samples a recorded log may hold: 20 million, 1000 s at 20 kHz, twice the longest
#: simulated scenario (:data:`rippleb.simulator.scenario.MAX_SAMPLES`); more is read no further.
MAX_LOG_SAMPLES = 20_000_000


def read_log(path: str | Path, spec: JointSpec | None = None, *, joint=None,
             resample: bool = False) -> SensorLog:
    """Read a log from CSV or Parquet and check its schema.

    Parameters
    ----------
    path
        A ``.csv`` or ``.parquet`` file with at least the columns ``t, strain,
        encoder, current`` (or the columns its joint description maps onto them);
        ``index``, ``torque_ref`` and ``torque_true`` are optional.
    spec
        The joint the log was recorded on, used as it is (a joint description that gives
        another value is refused). By default :class:`JointSpec`
        with the values the joint description gives and ``fs`` the rate of ``t``'s clock
        (:func:`rippleb.timebase.uniform_rate`).
    joint
        A :class:`~rippleb.joint_file.JointDescription` or the path of a ``joint.toml``;
        the log's sidecar (``rec.toml`` beside ``rec.csv``) overrides it key by key.
    resample
        Put a log whose time stamps jitter, or that dropped samples, on a uniform grid at its
        clock's rate (:func:`rippleb.timebase.resample`); without it such a log is refused.

    ``meta["joint"]`` lists, per value the log is read with, whether it was given or assumed,
    and what the log's own checks found (:mod:`rippleb.joint_checks`: a contradicted value is
    an :class:`InputError`); ``meta["reference_kind"]``, what its ``torque_ref`` is.
    """
    from rippleb import joint_checks, joint_file

    path = Path(path)
    suffix = path.suffix.lower()
    if suffix not in (".csv", ".parquet"):
        raise InputError(f"{path}: unsupported log format {suffix or '(none)'!r}; use .csv or .parquet")
    try:   # a regular file of at most LOG_BYTES: not a FIFO (a hang), a device or a giant
        check_file(path, LOG_BYTES, "log")
    except FileNotFoundError:
        raise InputError(f"{path}: no such file") from None
    given = joint_file.load_joint(joint) if isinstance(joint, (str, Path)) else joint
    description = joint_file.description_for(path, given)
    twice = duplicated_columns(path, LOG_COLUMNS + channel_names(MAX_CHANNELS))
    if twice:
        raise InputError(f"{path}: column {', '.join(twice)} appears more than once; keep one")
    frame = read_table(path, MAX_LOG_SAMPLES, "log")
    wanted = joint_file.with_channels(frame, description, LOG_COLUMNS)
    columns, units = joint_file.map_columns(frame, description, str(path), wanted)
    if not joint_file.index_wanted(description, columns, str(path)):
        columns.pop("index", None)
        units.pop("index", None)
    if resample:
        columns = _resampled(columns, str(path))
    if spec is not None:
        joint_file.check_agrees(spec, description, str(path))
    log = make_log(spec or _spec_from(description, columns, str(path)), columns, source=str(path),
                   meta={"source": str(path), "reference_kind": description.reference_kind,
                         "columns": {k: f"{v['column']!r} in {v['unit']}" for k, v in units.items()}})
    notes = joint_checks.notes(log, description, str(path), spec_given=spec is not None)
    log.meta["joint"] = joint_file.describe(log.spec, description, units, log.index is not None,
                                            spec_given=spec is not None, notes=notes)
    return log


def _spec_from(description, columns: dict, source: str) -> JointSpec:
    """:class:`JointSpec` with the values ``description`` gives and ``fs`` the rate of ``t``."""
    from rippleb import joint_file

    spec = joint_file.with_spec(JointSpec(), description)
    fs = _rate(columns.get("t"))
    if np.isfinite(fs) and fs > 0:
        spec = dataclasses.replace(spec, fs=round(fs, 6))
    # an implausible rate from t is the run's to refuse, naming column t (engine.checks)
    if "control_rate" in description.values and spec.control_rate > spec.fs:
        raise InputError(f"{description.sources['control_rate']}: joint.control_rate: {spec.control_rate:g} Hz "
                         f"exceeds {source}'s sample rate, {spec.fs:g} Hz")
    return spec


def _rate(t) -> float:
    """The rate of a ``t`` column, NaN if it is not numeric (make_log names the column)."""
    if t is None:
        return float("nan")
    try:
        return uniform_rate(np.asarray(t, dtype=float))
    except (TypeError, ValueError):
        return float("nan")


def _resampled(columns: dict, source: str) -> dict:
    """``columns`` on a uniform grid (:func:`rippleb.timebase.resample`) if they can be read as
    numbers and ``t`` strictly increases without a gap; else as they are, for
    :func:`make_log` to name what is wrong."""
    from rippleb.timebase import resample

    if any(holds_booleans(np.asarray(v)) for k, v in columns.items() if k != "index"):
        return columns
    try:
        numeric = {k: np.asarray(v, dtype=float) for k, v in columns.items()}
    except (TypeError, ValueError):
        return columns
    t = numeric.get("t")
    if t is None or len(t) < 2 or not np.isfinite(t).all() or (np.diff(t) <= 0).any():
        return columns
    check_steps(t, source, resampling=True)
    return resample(numeric)


def write_log(log: SensorLog, path: str | Path) -> Path:
    """Write ``log`` to CSV or Parquet (by suffix), atomically.

    Both go through Arrow: a CSV holds each float in its shortest form that reads back
    to the same double, so a written log runs bit for bit like the simulated one, and
    Arrow's writer is about ten times faster than pandas' formatter (0.06 against 0.6 s
    for paper-quintic's 80 000 rows).
    """
    return write_columns(log.file_columns(), path)


def write_columns(columns: dict[str, np.ndarray], path: str | Path) -> Path:
    """Write named columns to CSV or Parquet as :func:`write_log` does (any column names)."""
    import pyarrow as pa

    path = Path(path)
    suffix = path.suffix.lower()
    if suffix not in (".csv", ".parquet"):
        raise InputError(f"{path}: unsupported log format {suffix or '(none)'!r}; use .csv or .parquet")
    table = pa.table(columns)
    with atomic_path(path) as tmp:
        if suffix == ".csv":
            import pyarrow.csv as pa_csv

            pa_csv.write_csv(table, tmp)
        else:
            import pyarrow.parquet as pq  # imports pandas: only where needed

            pq.write_table(table, tmp)
    return path

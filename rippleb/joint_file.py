"""The joint description of a recorded log: ``joint.toml`` and a log's sidecar.

A ``[joint]`` table gives what rippleb cannot read from the log (the encoder's counts per
revolution, the gear ratio, ...) and a ``[joint.columns]`` table maps the DAQ's column names
and units onto rippleb's (docs/your-joint.md has the full format)::

    [joint]
    counts_per_rev = 16384
    index_pulse = true

    [joint.columns]
    t = {column = "t_ms", unit = "ms"}
    strain = {column = "strain_mV", unit = "mV"}
    encoder = "enc_counts"            # a name alone: the column is in rippleb's unit

A ``[joint.reference]`` table says what the log's ``torque_ref`` is (:data:`REFERENCE_KINDS`):
a torque sensor in series with the joint, which reads the real torque, or a model torque
(eq. (7) of the paper), which lacks every torque the model leaves out, the gear's own
among them; the two are scored differently (docs/metrics.md, "Scores against a
reference"). A log without a reference says so with ``torque_ref = false``.

It comes from ``--joint FILE`` (:func:`load_joint`) and from the log's sidecar
``<log stem>.toml`` beside it (:func:`sidecar_of`), whose keys win: a sidecar describes
its one file. :func:`describe` says, per value, whether it was given or assumed.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from rippleb.reading import check_joint_value
from rippleb.errors import InputError
from rippleb.log_columns import is_channel
from rippleb.timebase import TIME_UNITS, looks_like_epoch, to_seconds

#: Joint values a ``[joint]`` table may give (the fields of ``JointSpec`` but ``fs``, which
#: column ``t`` gives) and ``index_pulse``, with the type each must have.
JOINT_KEYS = {"counts_per_rev": int, "gear_ratio": float, "rated_torque": float,
              "torque_constant": float, "rotor_inertia": float, "control_rate": float,
              "index_pulse": bool}
#: rippleb's unit of each column, and the units a ``[joint.columns]`` entry may name instead,
#: with the factor that turns them into rippleb's.
COLUMN_UNITS = {
    "t": {unit: 1.0 for unit in TIME_UNITS},
    "strain": {"V": 1.0, "mV": 1e-3, "uV": 1e-6},
    "current": {"A": 1.0, "mA": 1e-3},
    "encoder": {"counts": 1.0},
    "index": {"pulse": 1.0},
    "torque_ref": {"Nm": 1.0, "mNm": 1e-3, "kNm": 1e3},
    "torque_true": {"Nm": 1.0, "mNm": 1e-3, "kNm": 1e3},
}
#: The unit of each column when none is given.
RIPPLEB_UNITS = {"t": "s", "strain": "V", "current": "A", "encoder": "counts", "index": "pulse",
                 "torque_ref": "Nm", "torque_true": "Nm"}
_ENTRY_KEYS = ("column", "unit", "scale")
#: Columns a log may lack; ``NAME = false`` in ``[joint.columns]`` says this log has none.
OPTIONAL_COLUMNS = ("index", "torque_ref", "torque_true")
#: What a log's ``torque_ref`` may be (``[joint.reference] kind``).
REFERENCE_KINDS = {
    "transducer": "a torque sensor in series with the joint: the real torque, with the sensor's own noise "
                  "and bandwidth",
    "model": "a model torque (eq. (7) or any model): without the gear's own torque and whatever else the "
             "model leaves out",
}
#: The kind assumed when none is given: scored as a model torque, whose score does not reward
#: erasing real torque a model lacks; a transducer's log loses little by it (docs/metrics.md).
DEFAULT_REFERENCE_KIND = "model"


@dataclass(frozen=True)
class Column:
    """Where one of rippleb's columns is in a file, and how to turn it into rippleb's unit.

    ``scale`` multiplies the file's values (a unit's factor, or a ``scale`` given as such);
    ``unit`` is the unit given, for the record ('' when a scale was given instead).
    """

    name: str
    unit: str = ""
    scale: float = 1.0
    absent: bool = False   # ``NAME = false``: the log has no such column


@dataclass(frozen=True)
class JointDescription:
    """What ``joint.toml`` files gave: joint values, columns, and the file each came from."""

    values: dict = field(default_factory=dict)
    columns: dict = field(default_factory=dict)
    sources: dict = field(default_factory=dict)
    reference: dict = field(default_factory=dict)

    def merged(self, over: "JointDescription") -> "JointDescription":
        """This description with every value and column ``over`` gives replaced by its own."""
        return JointDescription({**self.values, **over.values}, {**self.columns, **over.columns},
                                {**self.sources, **over.sources}, {**self.reference, **over.reference})

    @property
    def reference_kind(self) -> str:
        """The declared kind of ``torque_ref``, else :data:`DEFAULT_REFERENCE_KIND`."""
        return self.reference.get("kind", DEFAULT_REFERENCE_KIND)


def load_joint(path: str | Path, *, sidecar: bool = False) -> JointDescription:
    """Read and check a joint file; every bad key is one :class:`InputError` naming it.

    A ``--joint`` file holds the ``[joint]`` table alone; a sidecar may hold other tables
    of its own (notes, the bench), which rippleb leaves alone.
    """
    from rippleb.reading import TOML_BYTES, parse_toml, read_text

    path = Path(path)
    try:   # a regular file of at most TOML_BYTES (a FIFO once hung the run), nested a few deep
        raw = parse_toml(read_text(path, TOML_BYTES, "joint file"), path)
    except FileNotFoundError:
        raise InputError(f"{path}: no such joint file") from None
    extra = sorted(set(raw) - {"joint"})
    if extra and not sidecar:
        raise InputError(f"{path}: {extra[0]}: unknown key; a joint file holds a [joint] table")
    table = raw.get("joint", {})
    if not isinstance(table, dict):
        raise InputError(f"{path}: joint: must be a table")
    return _description(path, table)


def _description(path: Path, table: dict) -> JointDescription:
    values, columns, reference = {}, {}, {}
    for key, value in table.items():
        if key == "columns":
            if not isinstance(value, dict):
                raise InputError(f"{path}: joint.columns: must be a table")
            columns = {name: _column(path, name, entry) for name, entry in value.items()}
        elif key == "reference":
            reference = _reference(path, value)
        elif key in JOINT_KEYS:
            values[key] = _joint_value(path, key, value)
        else:
            raise InputError(f"{path}: joint.{key}: unknown key; known: "
                             f"{', '.join(list(JOINT_KEYS) + ['columns', 'reference'])}")
    sources = {**{k: str(path) for k in values}, **{f"columns.{k}": str(path) for k in columns},
               **{f"reference.{k}": str(path) for k in reference}}
    return JointDescription(values, columns, sources, reference)


def _reference(path: Path, table) -> dict:
    """The ``[joint.reference]`` table: ``kind``, one of :data:`REFERENCE_KINDS`."""
    if not isinstance(table, dict):
        raise InputError(f"{path}: joint.reference: must be a table, e.g. kind = \"transducer\"")
    unknown = [k for k in table if k != "kind"]
    if unknown:
        raise InputError(f"{path}: joint.reference.{unknown[0]}: unknown key; known: kind")
    kind = table.get("kind")
    if kind not in REFERENCE_KINDS:
        raise InputError(f"{path}: joint.reference.kind: {kind!r} is not a kind of reference; use "
                         + "; or ".join(f"{k!r} ({v})" for k, v in REFERENCE_KINDS.items()))
    return {"kind": kind}


def _joint_value(path: Path, key: str, value):
    kind = JOINT_KEYS[key]
    where = f"{path}: joint.{key}"
    if kind is bool:
        if not isinstance(value, bool):
            raise InputError(f"{where}: must be true or false, got {value!r}")
        return value
    if isinstance(value, bool) or not isinstance(value, (int, float)) or (kind is int and not isinstance(value, int)):
        raise InputError(f"{where}: must be a {'whole ' if kind is int else ''}number, got {value!r}")
    if not np.isfinite(value):
        raise InputError(f"{where}: must be positive, got {value!r}")
    return kind(check_joint_value(key, value, where))   # the ranges a scenario's [joint] has too


def unit_kind(name: str) -> str:
    """The column whose units ``name`` takes: ``strain`` for a channel ``strain_k``."""
    return "strain" if is_channel(name) else name


def _column(path: Path, name: str, entry) -> Column:
    where = f"{path}: joint.columns.{name}"
    if unit_kind(name) not in COLUMN_UNITS:
        raise InputError(f"{where}: unknown column; rippleb's columns: {', '.join(COLUMN_UNITS)} "
                         f"and the strain channels strain_1, strain_2, ...")
    if entry is False and name in OPTIONAL_COLUMNS:
        return Column("", absent=True)
    if isinstance(entry, str):
        entry = {"column": entry}
    if not isinstance(entry, dict):
        raise InputError(f"{where}: must be a column name or a table {{column = ..., unit = ...}}"
                         + (" (or false: the log has none)" if name in OPTIONAL_COLUMNS else ""))
    unknown = [k for k in entry if k not in _ENTRY_KEYS]
    if unknown:
        raise InputError(f"{where}.{unknown[0]}: unknown key; known: {', '.join(_ENTRY_KEYS)}")
    column = entry.get("column")
    if not isinstance(column, str) or not column:
        raise InputError(f"{where}.column: must name the file's column, got {column!r}")
    if "unit" in entry and "scale" in entry:
        raise InputError(f"{where}: give unit or scale, not both")
    if "scale" in entry:
        return Column(column, "", _scale(where, name, entry["scale"]))
    kind = unit_kind(name)
    unit = entry.get("unit", RIPPLEB_UNITS[kind])
    if unit not in COLUMN_UNITS[kind]:
        raise InputError(f"{where}.unit: {unit!r} is not a unit of {name}; use one of "
                         f"{', '.join(COLUMN_UNITS[kind])}")
    return Column(column, unit, COLUMN_UNITS[kind][unit])


def _scale(where: str, name: str, scale) -> float:
    if name in ("t", "encoder", "index"):
        raise InputError(f"{where}.scale: {name} takes a unit, not a scale ({', '.join(COLUMN_UNITS[name])})")
    if isinstance(scale, bool) or not isinstance(scale, (int, float)) or not np.isfinite(scale) or scale == 0:
        raise InputError(f"{where}.scale: must be a finite non-zero number, got {scale!r}")
    return float(scale)


def sidecar_of(log_path: str | Path) -> Path:
    """The sidecar of a log: ``rec.toml`` beside ``rec.csv``."""
    return Path(log_path).with_suffix(".toml")


def description_for(log_path: str | Path, given: JointDescription | None) -> JointDescription:
    """``given`` (from ``--joint``), overridden by the log's sidecar if it has one."""
    base = given or JointDescription()
    sidecar = sidecar_of(log_path)
    return base.merged(load_joint(sidecar, sidecar=True)) if sidecar.is_file() else base


def with_channels(frame, joint: JointDescription, wanted: tuple[str, ...]) -> tuple[str, ...]:
    """``wanted`` and the strain channels (``strain_k``) the joint maps or the file holds
    under rippleb's name (a file column another entry maps is not a channel of its own)."""
    targets = {column.name for column in joint.columns.values()}
    found = {name for name in joint.columns if is_channel(name)}
    found |= {str(c) for c in frame.columns if is_channel(c) and str(c) not in targets}
    return tuple(wanted) + tuple(sorted(found - set(wanted), key=lambda n: int(n.rpartition("_")[2])))


def map_columns(frame, joint: JointDescription, source: str, wanted: tuple[str, ...]) -> tuple[dict, dict]:
    """rippleb's columns from a pandas ``frame``, renamed and in rippleb's units.

    Returns ``(columns, units)``: ``units`` says per column the file's column and unit and
    whether they were given. A mapped column the file lacks is an :class:`InputError`
    naming the joint file and the entry; an unmapped one is looked up under rippleb's name.
    """
    _refuse_shared_columns(joint)
    columns, units = {}, {}
    for name in wanted:
        mapped = joint.columns.get(name)
        if mapped is not None and mapped.absent:
            continue
        if mapped is not None and mapped.name not in frame.columns:
            hint = (f"; if {source} has none, say so in its sidecar {sidecar_of(source).name}: "
                    f"[joint.columns] {name} = false" if name in OPTIONAL_COLUMNS else "")
            raise InputError(f"{joint.sources[f'columns.{name}']}: joint.columns.{name}: {source} has no "
                             f"column {mapped.name!r} (its columns: {', '.join(map(str, frame.columns))}){hint}")
        column = mapped or Column(name, RIPPLEB_UNITS[unit_kind(name)])
        if column.name not in frame.columns:
            continue
        columns[name] = frame[column.name].to_numpy()
        units[name] = {"column": column.name, "unit": column.unit or f"x {column.scale:g}",
                       "given": joint.sources.get(f"columns.{name}", "")}
        if column.scale != 1.0:
            columns[name] = _scaled(columns[name], column.scale)
    if "t" in columns:
        columns["t"] = _seconds(columns["t"], joint.columns.get("t"), units["t"])
    return columns, units


def _refuse_shared_columns(joint: JointDescription) -> None:
    """One line when two of rippleb's columns are mapped onto one column of the file (the
    strain read as the current too gave ``ok`` rows of a joint that does not exist)."""
    seen: dict[str, str] = {}
    for name, column in joint.columns.items():
        if column.absent:   # ``NAME = false`` maps no column of the log
            continue
        if column.name in seen:
            raise InputError(f"{joint.sources[f'columns.{name}']}: joint.columns: {seen[column.name]} and {name} "
                             f"both map the log's column {column.name!r}; each of rippleb's columns is one of "
                             f"the log's")
        seen[column.name] = name


def _scaled(values, scale: float):
    try:
        return np.asarray(values, dtype=float) * scale
    except (TypeError, ValueError):
        return values  # not numeric: make_log names the column


def _seconds(t, given: Column | None, unit: dict):
    try:
        t = np.asarray(t, dtype=float)
    except (TypeError, ValueError):
        return t  # not numeric: make_log names the column
    name = given.unit if given is not None else ("epoch" if looks_like_epoch(t) else "s")
    if given is None and name == "epoch":
        unit["unit"] = f"epoch (assumed: its first stamp, {t[0]:.10g} s, is a Unix date)"
    return to_seconds(t, name) if name != "s" else t


def index_wanted(joint: JointDescription, columns: dict, source: str) -> bool:
    """Whether the log's index pulse is passed on: ``index_pulse`` if given (true needs the
    column), else whether the log has one."""
    wanted = joint.values.get("index_pulse")
    if wanted and "index" not in columns:
        raise InputError(f"{joint.sources['index_pulse']}: joint.index_pulse: true, but {source} has no "
                         f"index column (map it in [joint.columns] as index = \"NAME\")")
    return "index" in columns if wanted is None else wanted


def spec_values(joint: JointDescription) -> dict:
    """The ``JointSpec`` fields ``joint`` gives."""
    return {k: v for k, v in joint.values.items() if k != "index_pulse"}


def describe(spec, joint: JointDescription, units: dict, index_used: bool, *,
             spec_given: bool = False, notes: dict | None = None) -> list[str]:
    """One line per value a log run uses: given (and where) or assumed (the default).

    ``spec_given``: ``spec`` was handed to ``read_log``, so its values are the caller's.
    ``notes``: per key, what the checks of the log found (:mod:`rippleb.joint_checks`),
    appended to its line."""
    notes = notes or {}
    default = "given as read_log's spec" if spec_given else "ASSUMED (rippleb's default)"
    rate_origin = default if spec_given else "from column t: the rate of its clock"
    lines = [f"  fs = {spec.fs:.6g} Hz ({rate_origin}{_note(notes, 'fs')})"]
    for key in JOINT_KEYS:
        value = index_used if key == "index_pulse" else getattr(spec, key)
        origin = f"given in {joint.sources[key]}" if key in joint.sources else default
        if key == "index_pulse" and key not in joint.sources:
            origin = "ASSUMED (from whether the log has an index column)"
        origin += _note(notes, key)
        lines.append(f"  {key} = {value:g} ({origin})" if not isinstance(value, bool)
                     else f"  {key} = {str(value).lower()} ({origin})")
    for name, info in units.items():
        origin = f"given in {info['given']}" if info["given"] else "ASSUMED (rippleb's name and unit)"
        lines.append(f"  column {name} = {info['column']!r} in {info['unit']} ({origin})")
    if "torque_ref" in units:
        kind = joint.reference_kind
        origin = (f"given in {joint.sources['reference.kind']}" if "reference.kind" in joint.sources
                  else 'ASSUMED: declare it in [joint.reference] kind = "transducer" or "model"')
        lines.append(f"  reference kind = {kind} ({origin}): torque_ref is {REFERENCE_KINDS[kind]}")
    return lines


def _note(notes: dict, key: str) -> str:
    return f"; {notes[key]}" if key in notes else ""


def check_agrees(spec, joint: JointDescription, source: str) -> None:
    """Refuse a description that gives ``source`` another joint value than ``spec``, the
    joint it is read with (a calibration log is read with the scored log's)."""
    for key, value in spec_values(joint).items():
        if getattr(spec, key) != value:
            raise InputError(f"{joint.sources[key]}: joint.{key}: {value:g}, but {source} is read with "
                             f"{key} = {getattr(spec, key):g} (one joint: a calibration log is read with the "
                             f"scored log's values)")


def with_spec(spec, joint: JointDescription):
    """``spec`` with the values ``joint`` gives."""
    return dataclasses.replace(spec, **spec_values(joint))

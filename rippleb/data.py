"""The data that flows through rippleb: joint specification, sensor logs and blocks.

A :class:`SensorLog` is what a DAQ records on one joint: equal-length numpy columns
sampled at ``spec.fs``. Simulated logs also carry ``torque_true`` (what the flexspline
really carries) and ``torque_ref`` (the paper's model torque). Methods see
:class:`SensorBlock` objects, one control tick at a time, and never the truth.

Examples
--------
>>> import numpy as np
>>> from rippleb import JointSpec, SensorLog
>>> spec = JointSpec()
>>> log = SensorLog(spec=spec, t=np.arange(40) / spec.fs, strain=np.zeros(40),
...                 encoder=np.zeros(40, dtype=np.int64), current=np.zeros(40))
>>> [len(b) for b in log.blocks()]
[20, 20]
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Iterator

import numpy as np

from rippleb.log_columns import LOG_COLUMNS, SENSOR_COLUMNS, channel_columns, channel_names
from rippleb.errors import InputError
from rippleb.timebase import check_steps

#: Largest encoder count a log may hold: 2^53, the largest integer below which a float64
#: (how a log's columns are read and checked) holds every integer exactly.
MAX_EXACT_COUNT = 2**53
#: The smallest normal float64 (2.2e-308). Below it a value is subnormal: it has lost
#: precision, and no instrument reads such a value (the strain ADC steps by 3e-4 V), so a
#: column holding one was scaled or corrupted, and would be scored as if it were zero.
SMALLEST_NORMAL = float(np.finfo(float).tiny)
#: A torque above this many times the joint's rated torque would break the drive: Harmonic
#: Drive catalogues rate the momentary peak of size-25 units at 4-7 times the rated torque.
#: Simulated loads stay below it; a recorded log's estimate beyond it is not scored
#: (:mod:`rippleb.scoring.scorable`).
MAX_TORQUE_FACTOR = 10.0


@dataclass(frozen=True)
class JointSpec:
    """What an engineer knows about a joint from datasheets and the DAQ.

    Never the simulator's hidden truth (ripple, friction, gauge errors).

    Parameters
    ----------
    fs
        DAQ sample rate of strain and current [Hz]. Default 20 kHz (docs/design.md).
    control_rate
        Control tick rate [Hz]; the runner hands ``fs / control_rate`` samples per
        ``step``. Default 1 kHz (docs/design.md).
    gear_ratio
        Harmonic-drive reduction N. Default 100 (SHD-25-100, the paper's Sec. IV-A).
    counts_per_rev
        Encoder positions per motor revolution. Default 2500 (the paper's Sec. IV-A).
    rated_torque
        Rated output torque [Nm]. Default 51 Nm: Harmonic Drive SHD-25-100 catalogue
        rating at 2000 rpm input (size-25 ratings span 51-87 Nm over ratios 50-160).
    torque_constant
        Motor torque constant K_t [Nm/A]. Default 0.07: estimate for a 200 W class
        brushless servo motor of the size that drives a size-25 harmonic drive
        (catalogue values of such motors lie in 0.05-0.1 Nm/A).
    rotor_inertia
        Inertia on the motor shaft, rotor plus wave generator [kg m^2]. Default
        6e-5: estimate, rotor about 1.8e-5 plus size-25 wave generator 4.1e-5
        (Harmonic Drive CSG/SHG-25 catalogue input inertia).
    """

    fs: float = 20_000.0
    control_rate: float = 1_000.0
    gear_ratio: float = 100.0
    counts_per_rev: int = 2500
    rated_torque: float = 51.0
    torque_constant: float = 0.07
    rotor_inertia: float = 6.0e-5

    @property
    def block_size(self) -> int:
        """Samples per control tick, ``fs / control_rate``."""
        return max(1, int(round(self.fs / self.control_rate)))

    def validate(self, where: str = "joint spec") -> "JointSpec":
        """Refuse impossible values with one sentence naming the field."""
        positive = ("fs", "control_rate", "gear_ratio", "counts_per_rev", "rated_torque",
                    "torque_constant", "rotor_inertia")
        for name in positive:
            value = getattr(self, name)
            if not np.isfinite(value) or value <= 0:
                raise InputError(f"{where}: {name} must be a positive number, got {value!r}")
        if self.control_rate > self.fs:
            raise InputError(f"{where}: control_rate ({self.control_rate}) exceeds fs ({self.fs})")
        return self


@dataclass(frozen=True)
class SensorBlock:
    """The samples of one control tick: equal-length arrays, oldest first.

    ``t`` [s], ``strain`` [V], ``encoder`` [integer counts], ``current`` [A];
    ``index`` [0/1 per sample, the encoder's index pulse] or None when the log has none;
    ``channels`` [V, samples x channels], each amplifier channel of a gauge layout with
    several (``strain`` is their mean), or None.
    """

    t: np.ndarray
    strain: np.ndarray
    encoder: np.ndarray
    current: np.ndarray
    index: np.ndarray | None = None
    channels: np.ndarray | None = None

    def __len__(self) -> int:
        return len(self.t)

    @classmethod
    def of_views(cls, t, strain, encoder, current, index=None, channels=None) -> "SensorBlock":
        """The block of these arrays, made without the frozen dataclass's ``__init__``
        (six ``object.__setattr__`` calls, a third of the cost of cutting a log into its
        ticks, which every row pays once per tick): the same fields, as frozen."""
        block = object.__new__(cls)
        block.__dict__.update(t=t, strain=strain, encoder=encoder, current=current, index=index,
                              channels=channels)
        return block


def _cut(column: np.ndarray, size: int) -> list[np.ndarray]:
    """``column`` (samples first) as consecutive views of ``size`` samples, the last one
    shorter when ``size`` does not divide its length: one reshape and the views of its
    rows, where slicing each block costs several times as much. Splitting the first axis
    never needs a copy, so every block is a view of the log."""
    whole = len(column) // size * size
    views = list(column[:whole].reshape(-1, size, *column.shape[1:]))
    if whole < len(column):
        views.append(column[whole:])
    return views


@dataclass(frozen=True, eq=False)
class SensorLog:
    """A recording of one joint, equal-length columns sampled at ``spec.fs``.

    ``index`` (the encoder's index pulse, 0/1) is optional, as on a recorded log, and so
    is ``channels`` (samples x channels [V]: each amplifier channel of a gauge layout with
    several, whose mean is ``strain``; ``strain_1 .. strain_K`` in a file).
    ``torque_true`` is present only on simulated logs and never reaches a method;
    ``torque_ref`` reaches a method only in the calibration log.
    ``meta`` holds provenance (scenario, seed, run) and is free-form.
    """

    spec: JointSpec
    t: np.ndarray
    strain: np.ndarray
    encoder: np.ndarray
    current: np.ndarray
    index: np.ndarray | None = None
    torque_true: np.ndarray | None = None
    torque_ref: np.ndarray | None = None
    meta: dict = field(default_factory=dict)
    channels: np.ndarray | None = None

    def __len__(self) -> int:
        return len(self.t)

    def blocks(self, size: int | None = None) -> Iterator[SensorBlock]:
        """Yield the log as consecutive blocks of ``size`` samples (default one tick).

        The last block may be shorter. Blocks are views, not copies.
        """
        size = size or self.spec.block_size
        columns = [_cut(column, size) for column in (self.t, self.strain, self.encoder, self.current)]
        ticks = len(columns[0])
        for column in (self.index, self.channels):
            columns.append([None] * ticks if column is None else _cut(column, size))
        yield from map(SensorBlock.of_views, *columns)

    def block(self, start: int, stop: int) -> SensorBlock:
        """The samples ``start:stop`` as one block."""
        index = None if self.index is None else self.index[start:stop]
        channels = None if self.channels is None else self.channels[start:stop]
        return SensorBlock(self.t[start:stop], self.strain[start:stop],
                           self.encoder[start:stop], self.current[start:stop], index, channels)

    def for_method(self, *, keep_ref: bool) -> "SensorLog":
        """A copy a method may see: no ``torque_true``; ``torque_ref`` only if ``keep_ref``."""
        return dataclasses.replace(self, torque_true=None,
                                   torque_ref=self.torque_ref if keep_ref else None)

    def columns(self) -> dict[str, np.ndarray]:
        """The columns that are present, in file order; ``channels`` (2-D) last."""
        cols = {name: getattr(self, name) for name in LOG_COLUMNS + ("channels",)}
        return {name: value for name, value in cols.items() if value is not None}

    def file_columns(self) -> dict[str, np.ndarray]:
        """:meth:`columns` as a file holds them: each channel its own ``strain_k`` column."""
        cols = self.columns()
        channels = cols.pop("channels", None)
        if channels is not None:
            cols.update(zip(channel_names(channels.shape[1]), channels.T))
        return cols


def make_log(spec: JointSpec, columns: dict, *, source: str = "log", meta: dict | None = None) -> SensorLog:
    """Build a :class:`SensorLog` from columns after checking the schema.

    Raises :class:`~rippleb.errors.InputError` naming ``source`` and the column for a
    missing column, an empty log, a true/false column (but ``index``), NaN, infinite or
    subnormal values, non-integer encoder counts or counts beyond :data:`MAX_EXACT_COUNT`, or time
    stamps that do not strictly increase.
    """
    columns = dict(columns)
    stacked = columns.pop("channels", None)
    if stacked is not None:   # a log's own 2-D channels, checked like a file's columns
        stacked = np.asarray(stacked)
        if stacked.ndim != 2:
            raise InputError(f"{source}: channels must be samples x channels, got {stacked.ndim} dimension(s)")
        columns.update(zip(channel_names(stacked.shape[1]), stacked.T))
    named = channel_columns(columns, source)
    missing = [name for name in SENSOR_COLUMNS if name not in columns]
    if missing:
        raise InputError(f"{source}: missing column(s) {', '.join(missing)} "
                         f"(a log needs {', '.join(SENSOR_COLUMNS)}; a DAQ's own names and units are "
                         f"mapped in a joint file's [joint.columns], docs/your-joint.md)")
    arrays = {}
    for name in LOG_COLUMNS + named:
        if name not in columns or columns[name] is None:
            continue
        raw = np.asarray(columns[name])
        if name != "index" and holds_booleans(raw):  # True/False would pass as 1.0/0.0
            raise InputError(f"{source}: column {name} holds true/false values, not numbers")
        try:
            arrays[name] = np.asarray(raw, dtype=float)
        except (TypeError, ValueError):
            raise InputError(f"{source}: column {name} is not numeric") from None
    n = len(arrays["t"])
    if n == 0:
        raise InputError(f"{source}: the log is empty")
    for name, values in arrays.items():
        if values.ndim != 1 or len(values) != n:
            raise InputError(f"{source}: column {name} has {values.size} values, t has {n}")
        bad = ~np.isfinite(values)
        if bad.any():
            raise InputError(f"{source}: column {name} holds NaN or infinite values "
                             f"(first at row {int(np.argmax(bad))})")
        tiny = (values != 0) & (np.abs(values) < SMALLEST_NORMAL)
        if tiny.any():
            row = int(np.argmax(tiny))
            raise InputError(f"{source}: column {name} holds subnormal values ({values[row]:.3g} at row {row}), "
                             f"below the smallest normal float64 ({SMALLEST_NORMAL:.3g}): no sensor reads that; "
                             f"is the column scaled?")
    steps = np.diff(arrays["t"])
    if (steps <= 0).any():
        row = int(np.argmax(steps <= 0)) + 1
        raise InputError(f"{source}: column t must strictly increase (row {row} repeats or goes back)")
    check_steps(arrays["t"], source)
    encoder = arrays["encoder"]
    if not np.array_equal(encoder, np.round(encoder)):
        raise InputError(f"{source}: column encoder must hold integer counts")
    if np.abs(encoder).max() > MAX_EXACT_COUNT:
        raise InputError(f"{source}: column encoder reaches {np.abs(encoder).max():.4g} counts, beyond "
                         f"+-2^53 ({MAX_EXACT_COUNT:.4g}), the largest integers a float64 holds exactly: "
                         f"neighbouring counts there cannot be told apart")
    arrays["encoder"] = encoder.astype(np.int64)
    if "index" in arrays:
        if not np.isin(arrays["index"], (0.0, 1.0)).all():
            raise InputError(f"{source}: column index must hold 0 or 1 (the encoder's index pulse)")
        arrays["index"] = arrays["index"].astype(np.int8)
    if named:
        arrays["channels"] = np.column_stack([arrays.pop(name) for name in named])
    return SensorLog(spec=spec, meta=dict(meta or {}), **arrays)


def holds_booleans(values: np.ndarray) -> bool:
    """True for a boolean column (numpy's, or pandas' nullable one, which arrives as objects)."""
    if values.dtype.kind == "b":
        return True
    return values.dtype.kind == "O" and any(isinstance(v, (bool, np.bool_)) for v in values)

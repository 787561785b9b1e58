"""The conformance kit: does a method behave as the runner expects? One check at a time.

:func:`checks` lists the checks; each is ``(what it asserts, function of a Subject)`` and
raises :class:`AssertionError` saying where and by how much it failed. Two front ends run
them: :func:`rippleb.testing.check_method` in a plugin author's tests (the first failure
raises) and ``rippleb check NAME`` (:mod:`rippleb.cli.check`, one line per check).

The checks, on a short simulated log (by default 1 s of ``stop-restart`` around a stop
and restart, calibrated on the ``calibration`` scenario of the same device):

1. output: one finite float per sample, in blocks of one control tick;
2. determinism: two fresh instances give the same estimate, and so does one instance
   run again after ``reset`` (the state is cleared);
3. causality: changing the samples from index ``k`` on (strain, current and encoder)
   leaves the estimate before ``k`` unchanged (``k`` on a tick boundary);
4. block-size independence, one check per size: blocks of that many samples give the
   estimate of blocks of ``spec.block_size`` samples; the default sizes run from one
   sample to one second (the whole log in one block), as a recorded log may come.
"""

from __future__ import annotations

import dataclasses
import functools
from copy import deepcopy
from dataclasses import dataclass

import numpy as np

from rippleb.data import SensorLog, make_log
from rippleb import harness
from rippleb.harness import InvalidOutput

#: Block lengths compared with one control tick: single samples, an odd length that cuts
#: ticks, one tick, and one second (20 000 samples at 20 kHz), which holds the whole
#: default log: a method must take a block of any length, as a recorded log may come.
BLOCK_SIZES = (1, 7, 20, 1000, 20_000)
#: Of stop-restart seed 0: the end of a move, a 50 ms stop, a restart and the move after, 1 s.
WINDOW_S = (0.6, 1.6)
#: Absolute tolerance of the comparisons [Nm]: far below any error the benchmark reports
#: (tenths of a Nm), above the last-bit differences of a reordered sum.
ATOL_NM = 1e-6


@dataclass
class Subject:
    """A method under check: its class and parameters, the logs, and what the first check
    computed (the fitted instance and its estimate), which the others compare with."""

    cls: type
    params: dict
    log: SensorLog
    calibration: SensorLog
    atol: float = ATOL_NM
    fitted: object = None
    base: np.ndarray | None = None

    @property
    def label(self) -> str:
        """``Class(p=v, ...)``, as failures name it."""
        return f"{self.cls.__name__}({', '.join(f'{k}={v!r}' for k, v in self.params.items())})"


def subject(cls, params: dict | None = None, *, log: SensorLog | None = None,
            calibration: SensorLog | None = None, atol: float = ATOL_NM) -> Subject:
    """A :class:`Subject` on the given logs, or on the default ones (:func:`default_logs`)."""
    if log is None or calibration is None:
        default_cal, default_log = default_logs()
        log = default_log if log is None else log
        calibration = default_cal if calibration is None else calibration
    return Subject(cls, dict(params or {}), log, calibration, atol)


def checks(block_sizes=BLOCK_SIZES) -> list[tuple[str, object]]:
    """``[(what the check asserts, check(subject))]``, in the order they must run: the
    first fits the method and computes the estimate the others compare with."""
    return [("output: one finite estimate [Nm] per sample, in blocks of one control tick", check_output),
            ("determinism: fresh instances, and a second run after reset, give the same estimate",
             check_determinism),
            ("causality: changing later samples leaves the earlier estimate unchanged", check_causality),
            *((f"blocks of {size} sample{'s' if size > 1 else ''} give the estimate of one-tick blocks",
               functools.partial(check_block_size, size=size)) for size in block_sizes)]


@functools.lru_cache(maxsize=1)
def default_logs() -> tuple[SensorLog, SensorLog]:
    """``(calibration, log)``: the calibration scenario and a 1 s slice of stop-restart, seed 0."""
    from rippleb.simulator import simulate

    calibration = simulate("calibration", 0).log
    full = simulate("stop-restart", 0).log
    start, stop = (int(round(s * full.spec.fs)) for s in WINDOW_S)
    return calibration, slice_log(full, start, stop)


def slice_log(log: SensorLog, start: int, stop: int) -> SensorLog:
    """Samples ``start:stop`` of ``log`` as a new log (copies)."""
    columns = {name: np.array(values[start:stop]) for name, values in log.columns().items()}
    return make_log(log.spec, columns, source="slice", meta=dict(log.meta))


def check_output(s: Subject) -> None:
    """Fit the method and stream the log in one-tick blocks (kept for the other checks)."""
    s.fitted = _fit(s.cls, s.params, s.calibration)
    s.base = _estimate(s.fitted, s.log, None, s.label)


def check_determinism(s: Subject) -> None:
    again = _estimate(_fit(s.cls, s.params, s.calibration), s.log, None, s.label)
    _assert_close(again, s.base, s.atol, f"{s.label}: two fresh instances give different estimates")
    method = deepcopy(s.fitted)
    _estimate(method, s.log, None, s.label, copy=False)
    rerun = _estimate(method, s.log, None, s.label, copy=False)
    _assert_close(rerun, s.base, s.atol, f"{s.label}: a second run after reset differs from the first "
                                         "(reset must clear all streaming state)")


def check_causality(s: Subject) -> None:
    log = s.log
    size = log.spec.block_size
    k = (len(log) // 2) // size * size
    rng = np.random.default_rng(0)
    columns = {n: np.array(v) for n, v in log.columns().items()}
    tail = len(log) - k
    columns["strain"][k:] += rng.normal(0, np.std(log.strain) + 1e-3, tail)
    if "channels" in columns:   # a gauge layout's channels change with the strain
        columns["channels"][k:] += rng.normal(0, np.std(log.strain) + 1e-3, columns["channels"][k:].shape)
    columns["current"][k:] += rng.normal(0, np.std(log.current) + 1e-3, tail)
    columns["encoder"][k:] += np.cumsum(rng.integers(-3, 4, tail))
    changed = dataclasses.replace(log, **columns)
    other = _estimate(s.fitted, changed, None, s.label)
    _assert_close(other[:k], s.base[:k], s.atol, f"{s.label}: not causal: changing samples from {k} on "
                                                 f"changed the estimate before sample {k}")


def check_block_size(s: Subject, size: int) -> None:
    other = _estimate(s.fitted, s.log, size, s.label)
    _assert_close(other, s.base, s.atol, f"{s.label}: blocks of {size} samples differ from blocks of "
                                         f"{s.log.spec.block_size}")


def _fit(cls, params, calibration):
    return harness.fit(cls(**params), calibration)


def _estimate(fitted, log, block_size, name, copy=True) -> np.ndarray:
    # A deep copy of the fitted method per run: one fit serves every check.
    method = deepcopy(fitted) if copy else fitted
    try:
        estimate, _ = harness.run(method, log, block_size)
    except InvalidOutput as exc:
        raise AssertionError(f"{name}: {exc}" + (f" (blocks of {block_size})" if block_size else "")) from None
    return estimate


def _assert_close(actual: np.ndarray, expected: np.ndarray, atol: float, message: str) -> None:
    diff = np.abs(actual - expected)
    if not np.all(diff <= atol):
        i = int(np.argmax(diff))
        raise AssertionError(f"{message}: max difference {diff[i]:.3g} Nm at sample {i} "
                             f"(tolerance {atol:g} Nm)")

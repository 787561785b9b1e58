"""Conformance checks for method authors: ``check_method(MyMethod)`` in a test.

Examples
--------
>>> from rippleb.testing import check_method
>>> from rippleb.methods.raw import Raw
>>> check_method(Raw)
"""

from __future__ import annotations

import dataclasses
import functools
from copy import deepcopy

import numpy as np

from rippleb.data import SensorLog, make_log
from rippleb.streaming import InvalidOutput, prepare_blocks, stream

#: Block lengths compared with one control tick: single samples, an odd length that cuts
#: ticks, one tick, and one second (20 000 samples at 20 kHz), which holds the whole
#: default log: a method must take a block of any length, as a recorded log may come.
BLOCK_SIZES = (1, 7, 20, 1000, 20_000)
#: Of stop-restart seed 0: the end of a move, a 50 ms stop, a restart and the move after, 1 s.
WINDOW_S = (0.6, 1.6)


def check_method(cls, *, log: SensorLog | None = None, calibration: SensorLog | None = None,
                 atol: float = 1e-6, block_sizes=BLOCK_SIZES, **params) -> None:
    """Assert that ``cls(**params)`` behaves as the runner expects.

    Checks, on a short simulated log (by default 1 s of ``stop-restart`` around a stop
    and restart, calibrated on the ``calibration`` scenario of the same device):

    1. output: one finite float per sample, for every block;
    2. determinism: two fresh instances give the same estimate, and so does one instance
       run again after ``reset`` (the state is cleared);
    3. causality: changing the samples from index ``k`` on (strain, current and encoder)
       leaves the estimate before ``k`` unchanged (``k`` on a tick boundary);
    4. block-size independence: blocks of each of ``block_sizes`` samples give the
       estimate of blocks of ``spec.block_size`` samples, within ``atol`` [Nm]; the
       default sizes run from one sample to one second (the whole log in one block). A
       method that decides once per tick on purpose may pass its own ``block_sizes``.

    Parameters
    ----------
    cls
        The :class:`~rippleb.Method` subclass.
    log, calibration
        Logs to check on instead of the default ones (``calibration`` needs ``torque_ref``).
    atol
        Absolute tolerance of the comparisons [Nm].
    **params
        Constructor parameters of ``cls``.

    Raises
    ------
    AssertionError
        Saying which check failed, where, and by how much.
    """
    if log is None or calibration is None:
        default_cal, default_log = default_logs()
        log = default_log if log is None else log
        calibration = default_cal if calibration is None else calibration
    name = f"{cls.__name__}({', '.join(f'{k}={v!r}' for k, v in params.items())})"
    fitted = _fit(cls, params, calibration)
    base = _estimate(fitted, log, None, name)
    _check_determinism(cls, params, calibration, fitted, log, base, atol, name)
    _check_causality(fitted, log, base, atol, name)
    for size in block_sizes:
        other = _estimate(fitted, log, size, name)
        _assert_close(other, base, atol, f"{name}: blocks of {size} samples differ from blocks of "
                                         f"{log.spec.block_size}")


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


def _fit(cls, params, calibration):
    method = cls(**params)
    method.fit(calibration.for_method(keep_ref=True))
    return method


def _estimate(fitted, log, block_size, name, copy=True) -> np.ndarray:
    # A deep copy of the fitted method per run: one fit serves every check.
    method = deepcopy(fitted) if copy else fitted
    visible = log.for_method(keep_ref=False)
    method.reset(visible.spec)
    try:
        estimate, _ = stream(method.step, prepare_blocks(visible, block_size), len(visible))
    except InvalidOutput as exc:
        raise AssertionError(f"{name}: {exc}" + (f" (blocks of {block_size})" if block_size else "")) from None
    return estimate


def _check_determinism(cls, params, calibration, fitted, log, base, atol, name) -> None:
    again = _estimate(_fit(cls, params, calibration), log, None, name)
    _assert_close(again, base, atol, f"{name}: two fresh instances give different estimates")
    method = deepcopy(fitted)
    _estimate(method, log, None, name, copy=False)
    rerun = _estimate(method, log, None, name, copy=False)
    _assert_close(rerun, base, atol, f"{name}: a second run after reset differs from the first "
                                     "(reset must clear all streaming state)")


def _check_causality(fitted, log, base, atol, name) -> None:
    size = log.spec.block_size
    k = (len(log) // 2) // size * size
    rng = np.random.default_rng(0)
    columns = {n: np.array(v) for n, v in log.columns().items()}
    tail = len(log) - k
    columns["strain"][k:] += rng.normal(0, np.std(log.strain) + 1e-3, tail)
    columns["current"][k:] += rng.normal(0, np.std(log.current) + 1e-3, tail)
    columns["encoder"][k:] += np.cumsum(rng.integers(-3, 4, tail))
    changed = dataclasses.replace(log, **columns)
    other = _estimate(fitted, changed, None, name)
    _assert_close(other[:k], base[:k], atol, f"{name}: not causal: changing samples from {k} on "
                                             f"changed the estimate before sample {k}")


def _assert_close(actual: np.ndarray, expected: np.ndarray, atol: float, message: str) -> None:
    diff = np.abs(actual - expected)
    if not np.all(diff <= atol):
        i = int(np.argmax(diff))
        raise AssertionError(f"{message}: max difference {diff[i]:.3g} Nm at sample {i} "
                             f"(tolerance {atol:g} Nm)")

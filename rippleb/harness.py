"""The one in-process harness: ``fit``, then ``reset`` and the causal streaming loop.

Every path that runs a method runs this sequence and no other: the row and fit jobs of a
run (:mod:`rippleb.engine.jobs`, inside the sandboxed worker), the conformance checks
(:mod:`rippleb.engine.conformance`), the report's figures and the harness benchmark.

* :func:`fitted`: construct the method with its parameters and ``fit`` it on the
  calibration log as a method may see it (with ``torque_ref``, never ``torque_true``);
* :func:`run`: ``reset`` it on a log as a method may see it (neither reference) and
  :func:`stream` the log's blocks through ``step`` in time order, each call timed.
"""

from __future__ import annotations

import json
import time

import numpy as np

from rippleb.data import SensorLog


class InvalidOutput(Exception):
    """A method returned something that is not one finite float per sample."""


def prepare_blocks(log: SensorLog, size: int | None = None) -> list:
    """The log as a list of blocks (views), sliced before the timed loop."""
    return list(log.blocks(size))


def stream(step, blocks: list, n_samples: int) -> tuple[np.ndarray, np.ndarray]:
    """Feed ``blocks`` to ``step`` in order; return the estimate and each call's time [ns].

    Per tick the harness checks only shape and dtype (a cheap attribute test: ``float64``,
    so that no integer, however large, passes as a torque); the finiteness of the whole
    estimate is checked once at the end, which keeps the harness overhead per tick near one
    microsecond.

    Raises
    ------
    InvalidOutput
        Wrong length, a non-numeric dtype, or NaN/inf anywhere in the estimate.
    """
    out = np.empty(n_samples)
    ticks = np.empty(len(blocks), dtype=np.int64)
    clock = time.perf_counter_ns
    asarray = np.asarray
    float64 = np.dtype(np.float64)
    pos = 0
    for k, block in enumerate(blocks):
        t0 = clock()
        y = step(block)
        t1 = clock()
        ticks[k] = t1 - t0
        m = len(block.t)
        y = asarray(y)
        if y.shape != (m,) or y.dtype != float64:
            raise InvalidOutput(f"step returned {_describe(y)} for a block of {m} samples "
                                f"(tick {k}); expected {m} float64 values")
        out[pos:pos + m] = y
        pos += m
    bad = ~np.isfinite(out)
    if bad.any():
        first = int(np.argmax(bad))
        raise InvalidOutput(f"estimate holds {int(bad.sum())} NaN/inf values "
                            f"(first at sample {first}, tick {first // max(1, len(blocks[0].t))})")
    return out, ticks


def fit(method, calibration: SensorLog):
    """``method.fit`` on ``calibration`` as a method may see it (``torque_ref``, no
    ``torque_true``); returns the method."""
    method.fit(calibration.for_method(keep_ref=True))
    return method


def fitted(cls, params: dict | None, calibration: SensorLog):
    """``(method, params, fit_s)``: ``cls(**params)`` fitted on ``calibration``
    (:func:`fit`), its ``get_params()`` as JSON (:func:`params_json`) and the seconds the
    construction and the fit took."""
    t0 = time.perf_counter()
    method = cls(**(params or {}))
    params_text = params_json(method)
    fit(method, calibration)
    return method, params_text, time.perf_counter() - t0


def run(method, log: SensorLog, block_size: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """``reset`` a fitted ``method`` on ``log`` as a method may see it (neither reference),
    then :func:`stream` the log in blocks of ``block_size`` samples (None: one control tick)."""
    visible = log.for_method(keep_ref=False)
    method.reset(visible.spec)
    return stream(method.step, prepare_blocks(visible, block_size), len(visible))


def run_method(method, calibration: SensorLog, evaluation: SensorLog,
               block_size: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """:func:`fit` on ``calibration``, then :func:`run` on ``evaluation``."""
    return run(fit(method, calibration), evaluation, block_size)


def params_json(method) -> str:
    """A method's ``get_params()`` as sorted JSON ('' if it cannot say)."""
    try:
        return json.dumps(method.get_params(), sort_keys=True, default=repr)
    except Exception:  # a broken get_params must not cost the row
        return ""


def _describe(y: np.ndarray) -> str:
    return f"shape {y.shape} dtype {y.dtype}"

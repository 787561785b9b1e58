"""The causal streaming loop: blocks in time order, each ``step`` call timed.

Kept apart from the process machinery of :mod:`rippleb.engine.runner` so that the conformance
checks (:mod:`rippleb.testing`) and the harness benchmark run exactly this loop.
"""

from __future__ import annotations

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

    Per tick the harness checks only shape and dtype (a cheap attribute test); the
    finiteness of the whole estimate is checked once at the end, which keeps the harness
    overhead per tick near one microsecond.

    Raises
    ------
    InvalidOutput
        Wrong length, a non-numeric dtype, or NaN/inf anywhere in the estimate.
    """
    out = np.empty(n_samples)
    ticks = np.empty(len(blocks), dtype=np.int64)
    clock = time.perf_counter_ns
    asarray = np.asarray
    pos = 0
    for k, block in enumerate(blocks):
        t0 = clock()
        y = step(block)
        t1 = clock()
        ticks[k] = t1 - t0
        m = len(block.t)
        y = asarray(y)
        if y.shape != (m,) or y.dtype.kind not in "fiu":
            raise InvalidOutput(f"step returned {_describe(y)} for a block of {m} samples "
                                f"(tick {k}); expected {m} floats")
        out[pos:pos + m] = y
        pos += m
    bad = ~np.isfinite(out)
    if bad.any():
        first = int(np.argmax(bad))
        raise InvalidOutput(f"estimate holds {int(bad.sum())} NaN/inf values "
                            f"(first at sample {first}, tick {first // max(1, len(blocks[0].t))})")
    return out, ticks


def run_method(method, calibration: SensorLog, evaluation: SensorLog,
               block_size: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """``fit`` on ``calibration`` (with ``torque_ref``), ``reset``, then :func:`stream` the
    evaluation log (without ``torque_true`` or ``torque_ref``)."""
    method.fit(calibration.for_method(keep_ref=True))
    visible = evaluation.for_method(keep_ref=False)
    method.reset(visible.spec)
    blocks = prepare_blocks(visible, block_size)
    return stream(method.step, blocks, len(visible))


def _describe(y: np.ndarray) -> str:
    return f"shape {y.shape} dtype {y.dtype}"

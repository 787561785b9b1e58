"""Conformance checks for method authors: ``check_method(MyMethod)`` in a test.

The checks themselves are :mod:`rippleb.engine.conformance`; ``rippleb check NAME`` runs
the same ones from the command line, one line each, without pytest.

Examples
--------
>>> from rippleb.testing import check_method
>>> from rippleb.methods.raw import Raw
>>> check_method(Raw)
"""

from __future__ import annotations

from rippleb.data import SensorLog
from rippleb.engine.conformance import ATOL_NM, BLOCK_SIZES, WINDOW_S, checks, default_logs, slice_log, subject

__all__ = ["check_method", "default_logs", "slice_log", "BLOCK_SIZES", "WINDOW_S"]


def check_method(cls, *, log: SensorLog | None = None, calibration: SensorLog | None = None,
                 atol: float = ATOL_NM, block_sizes=BLOCK_SIZES, **params) -> None:
    """Assert that ``cls(**params)`` behaves as the runner expects.

    Runs every check of :func:`rippleb.engine.conformance.checks` in order, on a short
    simulated log (by default 1 s of ``stop-restart`` around a stop and restart, calibrated
    on the ``calibration`` scenario of the same device): one finite estimate per sample;
    determinism (fresh instances, and a second run after ``reset``); causality; and
    block-size independence for each of ``block_sizes`` (from one sample to one second). A
    method that decides once per tick on purpose may pass its own ``block_sizes``.

    Parameters
    ----------
    cls
        The :class:`~rippleb.Method` subclass.
    log, calibration
        Logs to check on instead of the default ones (``calibration`` needs ``torque_ref``).
    atol
        Absolute tolerance of the comparisons [Nm].
    block_sizes
        Block lengths [samples] whose estimate must equal that of one-tick blocks.
    **params
        Constructor parameters of ``cls``.

    Raises
    ------
    AssertionError
        Saying which check failed, where, and by how much.
    """
    checked = subject(cls, params, log=log, calibration=calibration, atol=atol)
    for _, check in checks(block_sizes):
        check(checked)

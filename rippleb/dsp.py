"""Small signal-processing helpers shared by several methods and the metrics."""

from __future__ import annotations

import numpy as np


def fit_gain_offset(strain: np.ndarray, torque: np.ndarray) -> tuple[float, float]:
    """Least-squares ``torque ~= gain * strain + offset``.

    On a calibration log that spans many wave-generator revolutions the ripple, being
    zero-mean over a revolution, averages out of the fit.

    Returns
    -------
    gain, offset
        In Nm/V and Nm.
    """
    design = np.column_stack([strain, np.ones_like(strain)])
    (gain, offset), *_ = np.linalg.lstsq(design, torque, rcond=None)
    return float(gain), float(offset)


def encoder_angle(counts: np.ndarray, counts_per_rev: int) -> np.ndarray:
    """Motor (wave-generator) angle [rad] from encoder counts."""
    return np.asarray(counts, dtype=float) * (2.0 * np.pi / counts_per_rev)

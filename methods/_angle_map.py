"""What the angle-indexed methods share: their calibration fit and their homed streaming.

:func:`fit_gain_and_ripple` fits the strain's gain and offset together with a Fourier
ripple of the encoder angle, so the ripple does not bias the gain (``spatial-filter``,
``fourier-lms``, ``periodic-dob``).

``fourier-lms`` and ``periodic-dob`` keep a ripple estimate indexed by the absolute motor
angle, learned in the calibration log's count frame. :class:`HomedMapMethod` hands their
compiled loop the counts of each block in that frame (:class:`~rippleb.methods._homing.IndexHoming`)
and, when the first index pulse of a run moves the frame (the joint was power-cycled), starts
the map again from its calibration at that very sample: what was learned in the wrong frame
is not worth keeping. A private module (leading underscore), so method discovery skips it.
"""

from __future__ import annotations

import numpy as np

from rippleb.data import JointSpec, SensorBlock, SensorLog
from rippleb.method import Method
from rippleb.methods._homing import IndexHoming


def harmonic_regressors(counts: np.ndarray, orders, counts_per_rev: int) -> np.ndarray:
    """``[cos k theta, sin k theta]`` per order, interleaved, for integer angles in counts."""
    orders = np.asarray(orders, dtype=np.int64)
    phase = 2.0 * np.pi * ((np.asarray(counts, dtype=np.int64)[:, None] * orders) % counts_per_rev)
    out = np.empty((len(phase), 2 * len(orders)))
    out[:, 0::2] = np.cos(phase / counts_per_rev)
    out[:, 1::2] = np.sin(phase / counts_per_rev)
    return out


def fit_gain_and_ripple(calibration: SensorLog, orders, name: str):
    """Gain [Nm/V], offset [Nm] and Fourier ripple [Nm] from a calibration log.

    Least squares of the strain on ``[torque_ref, 1, x(theta)]`` (``x`` of
    :func:`harmonic_regressors`), then ``gain = 1 / c_tau``, ``offset = -c_1 / c_tau`` and
    the ripple coefficients ``gain c_x``. Regressing the torque on the strain instead
    (``rippleb.dsp.fit_gain_offset``) takes the ripple for noise in the regressor and
    biases the gain low by ``var(ripple) / var(strain)`` (2 % on the tests' synthetic log).

    Raises
    ------
    ValueError
        Naming the method ``name`` when the log has no ``torque_ref``.
    """
    if calibration.torque_ref is None:
        raise ValueError(f"{name} needs torque_ref in the calibration log")
    x = harmonic_regressors(calibration.encoder, orders, int(calibration.spec.counts_per_rev))
    design = np.column_stack([calibration.torque_ref, np.ones(len(x)), x])
    coef, *_ = np.linalg.lstsq(design, calibration.strain, rcond=None)
    gain = 1.0 / coef[0]
    return float(gain), float(-coef[1] * gain), gain * coef[2:]


class HomedMapMethod(Method):
    """A method whose ``step`` runs ``self._run(strain, counts, out)`` on homed counts.

    Subclasses set ``self.index_mark_`` in ``fit`` and implement ``_run`` (the compiled
    loop over one stretch of samples) and ``_restart_map`` (back to the calibration map).
    """

    def reset(self, spec: JointSpec) -> None:
        """Clear the homing state; subclasses clear their own after calling this."""
        if not hasattr(self, "gain_"):
            raise RuntimeError(f"{self.name} needs fit(calibration) before reset")
        super().reset(spec)
        self.homing_ = IndexHoming(mark=self.index_mark_, counts_per_rev=int(spec.counts_per_rev))
        self.samples_ = 0      # absolute index of the next sample

    def step(self, block: SensorBlock) -> np.ndarray:
        """One torque estimate [Nm] per sample of ``block``."""
        counts, pulse = self.homing_.counts(block.encoder, block.index, self.samples_)
        counts = np.asarray(counts, dtype=np.int64)
        out = np.empty(len(block.strain))
        cut = None if pulse is None else pulse - self.samples_
        self.samples_ += len(block.strain)
        if cut is None:
            self._run(block.strain, counts, out)
            return out
        self._run(block.strain[:cut], counts[:cut], out[:cut])
        self._restart_map()
        self._run(block.strain[cut:], counts[cut:], out[cut:])
        return out

    def _run(self, strain: np.ndarray, counts: np.ndarray, out: np.ndarray) -> None:
        raise NotImplementedError

    def _restart_map(self) -> None:
        raise NotImplementedError

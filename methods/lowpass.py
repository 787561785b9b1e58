"""``lowpass``: the ``raw`` estimate through a fixed Butterworth low-pass filter.

It shows the trade-off a plain filter makes: the ripple frequency follows the motor
speed (order 4 at 4x the wave-generator rotation rate), so a cutoff low enough to remove
it at low speed delays every torque change.

Cutoff
------
190 Hz, second order: the point the one tuning protocol adopted (``rippleb tune``, budget
16, range 2-200 Hz, calibration logs of seeds 100-104 scored against ``torque_ref``;
``methods/tuning.json``): 1.853 Nm against 1.893 Nm at the former 30 Hz, better on all
five devices. Against ``torque_ref`` a slow filter's delay costs more than the ripple it
removes (the unmodelled load and the gear's real torque are in that error too), so the
protocol opens the filter nearly to the range's edge; the former 30 Hz had been chosen
against the simulator's ``torque_true`` on the calibration scenario, which no real
calibration has (docs/tuning.md). At 190 Hz the filter passes the ripple of every speed
above about 0.4 rad/s at the joint (order 4); the delay trade-off this baseline shows is
in ``benchmarks/lowpass_cutoff.py``'s sweep.
"""

from __future__ import annotations

from scipy.signal import butter, lfilter, lfilter_zi

from rippleb.dsp import fit_gain_offset
from rippleb.method import Method


class Lowpass(Method):
    """Butterworth low-pass of order ``order`` at ``cutoff_hz`` on the calibrated strain.

    Parameters
    ----------
    cutoff_hz
        -3 dB frequency [Hz].
    order
        Filter order; 2 keeps the transfer-function form numerically sound at
        ``cutoff_hz / fs`` of 1e-3 (higher orders would need second-order sections,
        whose ``sosfilt`` call costs about 6x more per tick).
    """

    name = "lowpass"
    description = "the raw estimate through a Butterworth low-pass (order=2, cutoff_hz=190.0)"
    #: ranges of the tuning protocol (rippleb/tuning.py)
    tunable = {"cutoff_hz": (2.0, 200.0, "log")}

    def __init__(self, cutoff_hz: float = 190.0, order: int = 2):
        self.cutoff_hz = cutoff_hz
        self.order = order

    def fit(self, calibration):
        self.gain_, self.offset_ = fit_gain_offset(calibration.strain, calibration.torque_ref)

    def reset(self, spec):
        super().reset(spec)
        self.b_, self.a_ = butter(self.order, self.cutoff_hz, fs=spec.fs)
        self.zi_ = None

    def step(self, block):
        # Filter the torque (not the strain) so the unit-DC-gain filter keeps the offset.
        x = block.strain * self.gain_ + self.offset_
        if self.zi_ is None:
            # Start in steady state on the first sample, not from zero torque.
            self.zi_ = lfilter_zi(self.b_, self.a_) * x[0]
        y, self.zi_ = lfilter(self.b_, self.a_, x, zi=self.zi_)
        return y

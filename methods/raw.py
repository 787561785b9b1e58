"""``raw``: the strain bridge times a gain plus an offset, with nothing removed.

It shows the problem: the estimate carries the whole torque ripple of the harmonic drive.
"""

from __future__ import annotations

from rippleb.dsp import fit_gain_offset
from rippleb.method import Method


class Raw(Method):
    """``tau_hat = gain * strain + offset``, both fitted by least squares on the calibration log.

    On a calibration log spanning many wave-generator revolutions the ripple averages
    out of the fit (:func:`rippleb.dsp.fit_gain_offset`).
    """

    name = "raw"
    description = "strain times a gain plus an offset, both fitted by least squares on the calibration log"

    def fit(self, calibration):
        self.gain_, self.offset_ = fit_gain_offset(calibration.strain, calibration.torque_ref)

    def step(self, block):
        return block.strain * self.gain_ + self.offset_

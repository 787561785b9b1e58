"""A running median of the calibrated strain over the last `window` samples."""
import numpy as np
from rippleb import Method
from rippleb.dsp import fit_gain_offset


class Median(Method):
    name = "median"

    def __init__(self, window=200):
        self.window = window                    # plain keyword arguments, no logic

    def fit(self, calibration):
        self.gain_, self.offset_ = fit_gain_offset(calibration.strain, calibration.torque_ref)

    def reset(self, spec):
        self.history_ = np.empty(0)             # clear the streaming state

    def step(self, block):
        x = np.concatenate([self.history_, block.strain * self.gain_ + self.offset_])
        n = len(block)
        out = np.array([np.median(x[max(0, i - self.window + 1): i + 1])
                        for i in range(len(x) - n, len(x))])
        self.history_ = x[max(0, len(x) - self.window + 1):]
        return out

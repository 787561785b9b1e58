"""Streaming an angle-indexed ripple map through the re-homing of the encoder count.

``fourier-lms`` and ``periodic-dob`` keep a ripple estimate indexed by the absolute motor
angle, learned in the calibration log's count frame. :class:`HomedMapMethod` hands their
compiled loop the counts of each block in that frame (:class:`~rippleb.methods._homing.IndexHoming`)
and, when the first index pulse of a run moves the frame (the joint was power-cycled), starts
the map again from its calibration at that very sample: what was learned in the wrong frame
is not worth keeping. A private module (leading underscore), so method discovery skips it.
"""

from __future__ import annotations

import numpy as np

from rippleb.data import JointSpec, SensorBlock
from rippleb.method import Method
from rippleb.methods._homing import IndexHoming


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

"""``periodic-dob``: a periodic-disturbance observer whose period is one turn of the encoder.

Muramatsu & Katsura (IEEE TII 14(10), 2018, "An adaptive periodic-disturbance observer for
periodic-disturbance suppression") estimate a periodic disturbance, fundamental and
harmonics at once, with a **periodic filter** built on a time delay of one period ``L``
inside a disturbance observer, and make it **adaptive** with an adaptive notch filter that
tracks the fundamental frequency and so sets ``L``. Here the disturbance is the ripple on
the strain and its period is one revolution of the wave generator: in the angle-indexed
form the delay is exactly one turn of the encoder (``counts_per_rev`` counts), so the
encoder does what the adaptive notch does in time, without its tracking lag.

The disturbance observer: the strain ``y`` [Nm] is the torque plus the disturbance, and
the torque's nominal value ``tau_n`` is the observer's own estimate through a first-order
low-pass of ``nominal_hz`` (the DOB's Q-filter), so the disturbance estimate is
``d = y - tau_n``. The periodic filter in angle, with a forgetting factor ``lam`` per
revolution, keeps of ``d`` what repeats every turn::

    S(theta) <- lam S(theta) + (1 - lam) d(theta)        (each time theta is passed)
    r(theta) = S(theta) - mean_theta S                     (its order-0 tooth removed)
    tau = y - r(theta),   tau_n <- tau_n + alpha (tau - tau_n)

``S`` is the comb ``(1 - lam) z^-N / (1 - lam z^-N)`` in angle samples (``N`` bins per
turn): pass bands at every whole order, fundamental and harmonics, of width set by
``lam``; its zero-order tooth would pass a torque offset, so the mean over a turn is taken
out. Torque that ``tau_n`` follows stays out of ``d``; without the nominal torque every
load change between two passes over an angle is learned as ripple. The table starts from the calibration
log's ripple (``fit``) and learns only while the angle moves: at rest nothing is learned
and the ripple at the resting angle is still removed. See ``docs/methods/periodic-dob.md``.
"""

from __future__ import annotations

import numpy as np
from numba import types

from rippleb.data import JointSpec, SensorLog
from rippleb.dsp import F8, IN_F8, IN_I8, compiled
from rippleb.methods._angle_map import HomedMapMethod, fit_gain_and_ripple
from rippleb.methods._homing import index_mark

I8 = types.int64[:]
#: ripple orders fitted beside the gain (``docs/physics.md``); the table itself has no orders
GAIN_FIT_ORDERS = (1, 2, 4, 6, 8)
#: positions in ``scalars``: sum of the table, disturbance sum of the open bin, nominal torque
TABLE_SUM, BIN_SUM, NOMINAL = range(3)
#: positions in ``counters``: open bin (-1 before the first sample), samples in it
OPEN_BIN, BIN_SAMPLES = range(2)


def bin_of(counts: np.ndarray, bins: int, counts_per_rev: int) -> np.ndarray:
    """Angle bin ``0..bins-1`` of each count (the count taken modulo one turn)."""
    return (np.asarray(counts) % counts_per_rev) * bins // counts_per_rev


@compiled(types.void(IN_F8, IN_I8, F8, types.float64, types.float64, types.int64, types.float64,
                     types.float64, F8, F8, I8))
def observe(strain, counts, out, gain, offset, counts_per_rev, lam, alpha, table, scalars,
            counters):
    """Remove the table's ripple from every sample; fold each bin left into the table.

    ``out = y - (S[b] - mean S)`` for the sample's bin ``b``. The disturbance ``y - tau_n``
    of the samples spent in a bin is averaged (``tau_n`` as of the sample before); when
    the count leaves the bin, ``S[b] <- lam S[b] + (1 - lam) mean``, which applies from
    then on (causal). ``scalars`` and ``counters`` carry the table's sum, the open bin and
    ``tau_n`` between calls; ``tau_n`` starts on the first sample's estimate.
    """
    bins = len(table)
    for s in range(len(strain)):
        y = gain * strain[s] + offset
        b = (counts[s] % counts_per_rev) * bins // counts_per_rev
        current = counters[OPEN_BIN]
        if current >= 0 and b != current:
            old = table[current]
            table[current] = lam * old + (1.0 - lam) * scalars[BIN_SUM] / counters[BIN_SAMPLES]
            scalars[TABLE_SUM] += table[current] - old
            scalars[BIN_SUM], counters[BIN_SAMPLES] = 0.0, 0
        estimate = y - (table[b] - scalars[TABLE_SUM] / bins)
        if current < 0:
            scalars[NOMINAL] = estimate
        counters[OPEN_BIN] = b
        scalars[BIN_SUM] += y - scalars[NOMINAL]
        counters[BIN_SAMPLES] += 1
        scalars[NOMINAL] += alpha * (estimate - scalars[NOMINAL])
        out[s] = estimate


class PeriodicDOB(HomedMapMethod):
    """Angle-indexed periodic-disturbance observer (Muramatsu & Katsura).

    Parameters
    ----------
    bins
        Angle bins per wave-generator turn (the delay line's length ``N``); 2010 bins
        (the one tuning protocol's, ``methods/tuning.json``) hold order 8 with 251 bins
        per period.
    memory_revs
        Forgetting of the periodic filter in passes over a bin: ``lam = exp(-1 /
        memory_revs)``; the comb's teeth are about ``1 / (pi memory_revs)`` orders wide
        (tuned on calibration).
    nominal_hz
        Cut-off of the Q-filter that makes the nominal torque from the estimate [Hz]
        (tuned on calibration).
    warm_start
        Start from the calibration ripple (True) or from an empty table.
    """

    name = "periodic-dob"
    description = ("a periodic-disturbance observer whose delay is one encoder turn: a comb over "
                   "bins=2010 angle bins on strain minus a nominal torque (Muramatsu & Katsura)")
    #: constructor parameters worth tuning and their ranges (for a tuner shared by all methods)
    tunable = {"bins": (50, 2500, "int"), "memory_revs": (1.0, 300.0, "log"),
               "nominal_hz": (0.5, 100.0, "log")}

    def __init__(self, bins: int = 2010, memory_revs: float = 206.0, nominal_hz: float = 94.6,
                 warm_start: bool = True):
        self.bins = bins
        self.memory_revs = memory_revs
        self.nominal_hz = nominal_hz
        self.warm_start = warm_start

    def fit(self, calibration: SensorLog) -> None:
        """Gain, offset and the starting table from the calibration log.

        Gain and offset: least squares of the strain on ``[torque_ref, 1]`` and a Fourier
        ripple of the angle at the orders of ``docs/physics.md`` (:func:`fit_gain_and_ripple`),
        so the ripple does not bias the gain. Table: the mean of ``y - torque_ref`` in each
        angle bin (zero in a bin the log never reached), minus its mean over the turn.
        """
        self.gain_, self.offset_, _ = fit_gain_and_ripple(calibration, GAIN_FIT_ORDERS, self.name)
        cpr = int(calibration.spec.counts_per_rev)
        bins = self._checked_bins(cpr)
        residual = self.gain_ * calibration.strain + self.offset_ - calibration.torque_ref
        where = bin_of(calibration.encoder.astype(np.int64), bins, cpr)
        sums = np.bincount(where, weights=residual, minlength=bins)
        hits = np.bincount(where, minlength=bins)
        table = np.divide(sums, hits, out=np.zeros(bins), where=hits > 0)
        self.map_ = table - table[hits > 0].mean() * (hits > 0)
        self.index_mark_ = index_mark(calibration.encoder, calibration.index, cpr)

    def _checked_bins(self, counts_per_rev: int) -> int:
        if not 1 <= int(self.bins) <= counts_per_rev:
            raise ValueError(f"{self.name}: bins={self.bins} must lie in 1..{counts_per_rev} "
                             "(the encoder's counts per turn)")
        return int(self.bins)

    def reset(self, spec: JointSpec) -> None:
        """The table back to the calibration ripple; no bin open."""
        if not (self.memory_revs > 0 and self.nominal_hz > 0):
            raise ValueError(f"{self.name}: needs memory_revs > 0 and nominal_hz > 0, got "
                             f"memory_revs={self.memory_revs}, nominal_hz={self.nominal_hz}")
        super().reset(spec)
        if len(self.map_) != self._checked_bins(int(spec.counts_per_rev)):
            raise ValueError(f"{self.name}: fitted with {len(self.map_)} bins")
        self.lam_ = float(np.exp(-1.0 / self.memory_revs))
        self.alpha_ = float(-np.expm1(-2.0 * np.pi * self.nominal_hz / spec.fs))
        self.scalars_ = np.zeros(3)
        self.counters_ = np.array([-1, 0], dtype=np.int64)
        self._restart_map()

    def _restart_map(self) -> None:
        self.table_ = self.map_.copy() if self.warm_start else np.zeros_like(self.map_)
        self.scalars_[TABLE_SUM] = self.table_.sum()
        # the open bin was gathered in the old frame (before a re-homing): drop it
        self.scalars_[BIN_SUM] = 0.0
        self.counters_[:] = (-1, 0)

    def _run(self, strain, counts, out) -> None:
        observe(strain, counts, out, self.gain_, self.offset_, int(self.spec_.counts_per_rev),
                self.lam_, self.alpha_, self.table_, self.scalars_, self.counters_)

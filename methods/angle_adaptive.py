"""``angle-adaptive``: a ripple map indexed by the encoder angle, learned online and subtracted.

The strain, converted to Nm with the calibrated gain and offset (``y``), is modelled as the
torque plus a ripple that is a function of the wave-generator angle ``theta`` (the motor
angle, from the encoder) and of the load::

    y = tau + phi(theta) . (c0 + c1 y + c2 |y|)

with ``phi = [cos k theta, sin k theta]`` over the ripple orders ``k`` of
``docs/physics.md`` (1, 2, 4, 6, 8). ``c1``, ``c2`` carry the load dependence of the ripple
(amplitude ``a + b |tau|`` and a phase that turns with ``tau``); the load enters through
``y`` itself, so the estimate ``tau = y - phi . (c0 + c1 y + c2 |y|)`` is explicit, per
sample, with no filter and no delay: at rest it is the strain minus the map at the resting
angle, whatever the torque does.

The coefficients ``w = [c0, c1, c2]`` are adapted online by recursive least squares with
**stabilised forgetting** (Kulhavy & Zarrop 1993; the generalised-forgetting RLS of Lai &
Bernstein 2023 covers it): the information matrix forgets towards a floor about the
calibration map instead of towards zero, so it stays invertible in directions the motion
does not excite and the estimate cannot wind up. Forgetting is per *revolution* of the wave
generator, not per second, and a tick enters the fit only if the encoder moved by at least
``min_counts`` in it: at rest nothing is learned and nothing is forgotten. The unknown torque
is removed from the fit by second differences of consecutive control ticks (tick means)::

    y_j - 2 y_{j-1} + y_{j-2} = d2 tau_j + d2 phi_j . (c0 + c1 y_{j-2} + c2 |y_{j-2}|)

the torque's second difference over two ticks is the equation error; an innovation gate
keeps unknown torque steps out. The map is warm-started from the calibration log and
referred to the encoder's index pulse when the logs have one (re-homing after a power
cycle). The compiled per-sample and per-period loops are in ``_angle_adaptive_law.py``
beside this module. See ``docs/methods/angle-adaptive.md`` for the design, the sources and
the measurements.
"""

from __future__ import annotations

import numpy as np

from rippleb.data import JointSpec, SensorBlock, SensorLog
from rippleb.method import Method
# the compiled law lives beside the class; its gate and solver stay importable from here
from rippleb.methods._angle_adaptive_law import LAW_GATE, LAW_R, consistent, solve, stream  # noqa: F401


def phasor_table(counts_per_rev: int) -> np.ndarray:
    """``exp(2j pi n / counts_per_rev)`` for every encoder position ``n`` (exact per count)."""
    return np.exp(2j * np.pi * np.arange(counts_per_rev) / counts_per_rev)


def angle_regressors(angle_counts: np.ndarray, orders: np.ndarray, table: np.ndarray) -> np.ndarray:
    """``[cos k theta, sin k theta]`` per order, interleaved, for integer angles in counts.

    Returns
    -------
    ndarray, shape ``angle_counts.shape + (2 * len(orders),)``
    """
    z = table[(angle_counts[..., None] * orders) % len(table)]
    out = np.empty(z.shape[:-1] + (2 * len(orders),))
    out[..., 0::2] = z.real
    out[..., 1::2] = z.imag
    return out


def map_rows(phi: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Regressor rows ``[phi, y phi, |y| phi]`` of the load-dependent ripple map."""
    return np.concatenate([phi, y[..., None] * phi, np.abs(y)[..., None] * phi], axis=-1)


def ripple(phi: np.ndarray, y: np.ndarray, w: np.ndarray) -> np.ndarray:
    """The map ``phi . (c0 + c1 y + c2 |y|)`` for coefficient rows ``w`` (one per sample or shared)."""
    m = phi.shape[-1]
    c0, c1, c2 = w[..., :m], w[..., m:2 * m], w[..., 2 * m:]
    return np.sum(phi * (c0 + y[:, None] * c1 + np.abs(y)[:, None] * c2), axis=-1)


def rotation(orders: np.ndarray, shift_counts: int, counts_per_rev: int, blocks: int = 3) -> np.ndarray:
    """Orthogonal ``T`` with ``w_new = T w_old`` when the angle origin moves by ``shift_counts``.

    With ``theta_old = theta_new + shift``, ``a cos k theta_old + b sin k theta_old`` is
    ``(a cos k s + b sin k s) cos k theta_new + (b cos k s - a sin k s) sin k theta_new``.
    Regressor rows transform with the same ``T`` (``(T psi) . (T w) = psi . w``).
    """
    angle = 2.0 * np.pi * orders * shift_counts / counts_per_rev
    c, s = np.cos(angle), np.sin(angle)
    m = len(orders)
    pair = np.zeros((2 * m, 2 * m))
    pair[0::2, 0::2] = np.diag(c)
    pair[0::2, 1::2] = np.diag(s)
    pair[1::2, 0::2] = np.diag(-s)
    pair[1::2, 1::2] = np.diag(c)
    return np.kron(np.eye(blocks), pair)


def first_index_count(encoder: np.ndarray, index: np.ndarray | None) -> int | None:
    """The encoder count at the first index pulse, or None when there is none."""
    if index is None:
        return None
    hits = np.flatnonzero(index)
    return int(encoder[hits[0]]) if len(hits) else None


class AngleAdaptive(Method):
    """Angle-indexed ripple map, learned online by RLS with stabilised forgetting.

    Parameters
    ----------
    orders
        Ripple orders of the wave-generator angle (``docs/physics.md``: 1, 2, 4, 6, 8).
    memory_revs
        Forgetting time constant in wave-generator revolutions (139: the one tuning
        protocol's, ``methods/tuning.json``).
    prior_sd_nm
        Initial standard deviation of each map coefficient about the calibration map, in Nm
        of ripple (the load terms: at rated torque); the warm start's confidence (0.0446: the
        tuning protocol's).
    floor_sd_nm
        Standard deviation of the stabilising floor the forgetting tends to, in the same
        units: how strongly an unexcited coefficient is held near the calibration map.
    min_counts
        Encoder counts a tick must turn by to enter the fit; below it the angle is taken
        as not moving and nothing is learned (chosen on calibration).
    update_ticks
        The map is re-solved every ``update_ticks`` control ticks (on absolute tick
        numbers, so the output does not depend on the block cutting).
    outlier_gate
        Innovation gate in standard deviations: a tick whose second difference the map
        cannot explain within its own uncertainty is not learned from (an unknown torque
        step); see :meth:`_consistent`.
    max_jolt_counts
        A tick whose end count has a second difference (over three ticks) above this is
        not learned from: the motor jumped through the gear compliance under a sudden
        torque. Counting quantisation alone gives at most 1 at constant speed, and the
        scenarios' smooth accelerations well under 1 count per tick squared.
    adapt
        False: the calibration map only (the ``angle-adaptive-frozen`` ablation).
    """

    name = "angle-adaptive"
    description = ("an angle-indexed ripple map warm-started from calibration, adapted online by RLS"
                   " (memory_revs=139.0), re-homed on the index pulse")
    #: ranges of the tuning protocol (rippleb/tuning.py)
    tunable = {"memory_revs": (3.0, 300.0, "log"), "prior_sd_nm": (0.03, 3.0, "log"),
               "min_counts": (1, 5, "int")}

    def __init__(self, orders: tuple = (1, 2, 4, 6, 8), memory_revs: float = 139.0,
                 prior_sd_nm: float = 0.0446, floor_sd_nm: float = 1.0, min_counts: int = 2,
                 update_ticks: int = 10, outlier_gate: float = 4.0, max_jolt_counts: int = 2,
                 adapt: bool = True):
        self.orders = orders
        self.memory_revs = memory_revs
        self.prior_sd_nm = prior_sd_nm
        self.floor_sd_nm = floor_sd_nm
        self.min_counts = min_counts
        self.update_ticks = update_ticks
        self.outlier_gate = outlier_gate
        self.max_jolt_counts = max_jolt_counts
        self.adapt = adapt

    # ------------------------------------------------------------------ fit
    def fit(self, calibration: SensorLog) -> None:
        """Gain, offset and the initial map from the calibration log (data only).

        1. Gain and offset: least squares of the tick-mean strain on
           ``[tau_ref, 1, phi, tau_ref phi, |tau_ref| phi]`` (as ``kalman-ripple``).
        2. Map: least squares of ``y - tau_ref`` on ``[phi, y phi, |y| phi]``, the rows the
           online law uses, in the angle frame of the index pulse when the log has one.
        3. ``r_``: the variance of the differenced equation error on moving ticks, the
           noise level that scales the online information.
        """
        if calibration.torque_ref is None:
            raise ValueError("angle-adaptive needs torque_ref in the calibration log")
        self.home_ = first_index_count(calibration.encoder, calibration.index)
        enc, phi, strain, tau = self._calibration_ticks(calibration)
        T = len(tau)
        design = np.hstack([tau[:, None], np.ones((T, 1)), phi, tau[:, None] * phi,
                            np.abs(tau)[:, None] * phi])
        coef, *_ = np.linalg.lstsq(design, strain, rcond=None)
        self.gain_ = float(1.0 / coef[0])
        self.offset_ = float(-coef[1] / coef[0])
        y = self.gain_ * strain + self.offset_
        rows = map_rows(phi, y)
        self.map_, *_ = np.linalg.lstsq(rows, y - tau, rcond=None)
        steps = np.abs(np.diff(enc[:, -1]))
        moved = np.minimum(steps[1:], steps[:-1]) >= max(int(self.min_counts), 1)
        error = (np.diff(y, n=2) - map_rows(np.diff(phi, n=2, axis=0), y[:-2]) @ self.map_)[moved]
        self.r_ = float(max(np.mean(error ** 2), 1e-12)) if len(error) else 1e-4
        self.residual_rms_ = float(np.std(y - tau - rows @ self.map_))

    def _calibration_ticks(self, calibration: SensorLog):
        """Per control tick of ``calibration``: the encoder counts in the index frame
        (``home_``), the tick-mean angle regressors, strain and ``torque_ref``."""
        spec = calibration.spec
        D = spec.block_size
        T = len(calibration) // D
        enc = calibration.encoder[:T * D].reshape(T, D) - (self.home_ or 0)
        phi = angle_regressors(enc, np.asarray(self.orders, dtype=np.int64),
                               phasor_table(int(spec.counts_per_rev))).mean(axis=1)
        strain = calibration.strain[:T * D].reshape(T, D).mean(axis=1)
        tau = calibration.torque_ref[:T * D].reshape(T, D).mean(axis=1)
        return enc, phi, strain, tau

    # ------------------------------------------------------------ streaming
    def reset(self, spec: JointSpec) -> None:
        """Start from the calibration map, no data information, frame of the calibration."""
        if not hasattr(self, "gain_"):
            raise RuntimeError(f"{self.name} needs fit(calibration) before reset")
        self.spec_ = spec
        self.cpr_ = int(spec.counts_per_rev)
        self.orders_ = np.asarray(self.orders, dtype=np.int64)
        self.table_ = phasor_table(self.cpr_)
        n = len(self.map_)
        m = 2 * len(self.orders_)
        U = int(self.update_ticks)
        self.scale_ = np.concatenate([np.ones(m), np.full(2 * m, float(spec.rated_torque) ** 2)])
        self.law_ = np.array([self.r_, float(self.outlier_gate),
                              self.cpr_ * float(self.memory_revs), 1.0 / self.floor_sd_nm ** 2,
                              float(self.min_counts), float(self.max_jolt_counts), np.inf])
        self.frame_ = self.home_ or 0   # angle origin in counts; the calibration's until homed
        self.homed_ = self.home_ is None  # nothing to home on without a calibration index
        self.w_ = self.map_.copy()
        self.info_ = np.zeros((n, n))   # data information (D), frame of frame_
        self.vec_ = np.zeros(n)         # data information vector (d)
        # [prior weight pi (rho, forgets towards delta), strain sum of the open tick]
        self.scalars_ = np.array([1.0 / self.prior_sd_nm ** 2, 0.0])
        # lower Cholesky factor of the map's information D + pi S (see solve)
        self.chol_ = np.diag(np.sqrt(self.scalars_[0] * self.scale_))
        # [samples in the open tick, complete ticks in the open period, history present]
        self.counters_ = np.zeros(3, dtype=np.int64)
        self.tick_phi_ = np.zeros(m)    # regressor sums of the open tick
        # rows 0-1: the last two ticks learned from (history); 2..: the open period's ticks
        self.ticks_phi_ = np.zeros((U + 2, m))
        self.ticks_y_ = np.zeros(U + 2)
        self.ticks_end_ = np.zeros(U + 2, dtype=np.int64)
        # no gear model (gear-keeping has one): its coefficients, orders, speed state, ticks
        self.gear_ = np.zeros(0)
        self.gear_index_ = np.zeros(0, dtype=np.int64)
        self.speed_ = np.zeros(6)
        self.ticks_gear_ = np.zeros(U + 2)

    @property
    def weight_(self) -> float:
        """The prior weight ``pi`` of the stabilised forgetting."""
        return float(self.scalars_[0])

    def step(self, block: SensorBlock) -> np.ndarray:
        """One torque estimate [Nm] per sample: the strain minus the current map."""
        out = np.empty(len(block.strain))
        cut = self._homing_sample(block)
        if cut is None:
            self._stream(block.strain, block.encoder, out)
            return out
        self._stream(block.strain[:cut], block.encoder[:cut], out[:cut])
        self._rehome(int(block.encoder[cut]))
        self._stream(block.strain[cut:], block.encoder[cut:], out[cut:])
        return out

    def _stream(self, strain, encoder, out) -> None:
        stream(strain, encoder, out, self.gain_, self.offset_, self.frame_, self.orders_,
               self.table_, int(self.spec_.block_size), int(self.update_ticks), bool(self.adapt),
               self.law_, self.scale_, self.map_, self.w_, self.chol_, self.info_, self.vec_,
               self.scalars_, self.counters_, self.tick_phi_, self.ticks_phi_, self.ticks_y_,
               self.ticks_end_, self.gear_, self.gear_index_, self.speed_, self.ticks_gear_)

    # -------------------------------------------------------------- homing
    def _homing_sample(self, block):
        """Position of the first index pulse in ``block`` while not yet homed, else None."""
        if self.homed_ or block.index is None:
            return None
        hits = np.flatnonzero(block.index)
        return int(hits[0]) if len(hits) else None

    def _rehome(self, count: int) -> None:
        """Refer the angle to the index pulse seen at ``count``; keep what was learned.

        The data information was gathered in the old frame: it is rotated into the new
        one (exact), and so are the regressors of the ticks not yet learned from and of
        the history. The calibration map was referred to the index pulse, so it is now in
        the right place; the estimate is re-solved at once.
        """
        shift = (count - self.frame_) % self.cpr_
        self.homed_ = True
        if shift == 0:
            return
        T = rotation(self.orders_, shift, self.cpr_)
        m = 2 * len(self.orders_)
        self.frame_ = count
        self.info_[:] = T @ self.info_ @ T.T
        self.vec_[:] = T @ self.vec_
        self.ticks_phi_[:] = self.ticks_phi_ @ T[:m, :m].T
        self.tick_phi_[:] = T[:m, :m] @ self.tick_phi_
        if self.adapt:
            solve(self.info_, self.vec_, self.scalars_[0], self.scale_, self.map_, self.chol_,
                  self.w_)
        else:
            self.w_[:] = self.map_


class AngleAdaptiveFrozen(AngleAdaptive):
    """Ablation: the calibration map, re-homed on the index pulse, never adapted."""

    name = "angle-adaptive-frozen"
    description = "angle-adaptive's calibration map, re-homed on the index pulse, never adapted (adapt=false)"
    #: nothing adapts, so nothing of the online law to tune
    tunable = {}

    def __init__(self, orders: tuple = (1, 2, 4, 6, 8), memory_revs: float = 30.0,
                 prior_sd_nm: float = 0.3, floor_sd_nm: float = 1.0, min_counts: int = 2,
                 update_ticks: int = 10, outlier_gate: float = 4.0, max_jolt_counts: int = 2,
                 adapt: bool = False):
        super().__init__(orders=orders, memory_revs=memory_revs, prior_sd_nm=prior_sd_nm,
                         floor_sd_nm=floor_sd_nm, min_counts=min_counts, update_ticks=update_ticks,
                         outlier_gate=outlier_gate, max_jolt_counts=max_jolt_counts, adapt=adapt)

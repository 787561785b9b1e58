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
cycle). See ``docs/methods/angle-adaptive.md`` for the design, the sources and the
measurements.
"""

from __future__ import annotations

import numpy as np

from rippleb.data import JointSpec, SensorBlock, SensorLog
from rippleb.method import Method


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
        Forgetting time constant in wave-generator revolutions (chosen on calibration).
    prior_sd_nm
        Initial standard deviation of each map coefficient about the calibration map, in Nm
        of ripple (the load terms: at rated torque); the warm start's confidence (chosen on
        calibration).
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

    def __init__(self, orders: tuple = (1, 2, 4, 6, 8), memory_revs: float = 30.0,
                 prior_sd_nm: float = 0.3, floor_sd_nm: float = 1.0, min_counts: int = 2,
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
        spec = calibration.spec
        orders = np.asarray(self.orders, dtype=np.int64)
        table = phasor_table(int(spec.counts_per_rev))
        self.home_ = first_index_count(calibration.encoder, calibration.index)
        D = spec.block_size
        T = len(calibration) // D
        enc = calibration.encoder[:T * D].reshape(T, D) - (self.home_ or 0)
        strain = calibration.strain[:T * D].reshape(T, D).mean(axis=1)
        tau = calibration.torque_ref[:T * D].reshape(T, D).mean(axis=1)
        phi = angle_regressors(enc, orders, table).mean(axis=1)
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

    # ------------------------------------------------------------ streaming
    def reset(self, spec: JointSpec) -> None:
        """Start from the calibration map, no data information, frame of the calibration."""
        if not hasattr(self, "gain_"):
            raise RuntimeError(f"{self.name} needs fit(calibration) before reset")
        self.spec_ = spec
        self.tick_ = spec.block_size
        self.cpr_ = int(spec.counts_per_rev)
        self.orders_ = np.asarray(self.orders, dtype=np.int64)
        self.table_ = phasor_table(self.cpr_)
        n = len(self.map_)
        m = 2 * len(self.orders_)
        self.scale_ = np.concatenate([np.ones(m), np.full(2 * m, float(spec.rated_torque) ** 2)])
        self.prior_info_ = 1.0 / self.prior_sd_nm ** 2
        self.floor_info_ = 1.0 / self.floor_sd_nm ** 2
        self.frame_ = self.home_ or 0   # angle origin in counts; the calibration's until homed
        self.homed_ = self.home_ is None  # nothing to home on without a calibration index
        self.w_ = self.map_.copy()
        self.info_ = np.zeros((n, n))   # data information (D), frame of frame_
        self.vec_ = np.zeros(n)         # data information vector (d)
        self.weight_ = self.prior_info_  # prior weight pi: rho, forgets towards delta
        self.cov_ = np.diag(1.0 / (self.weight_ * self.scale_))
        self.history_ = None            # the last two complete ticks: (phi, y, end count)
        self.pending_ = (np.empty(0), np.empty(0, dtype=np.int64))
        self.ticks_done_ = 0

    def step(self, block: SensorBlock) -> np.ndarray:
        """One torque estimate [Nm] per sample: the strain minus the current map."""
        cut = self._homing_sample(block)
        if cut is None:
            return self._advance(block.strain, block.encoder)
        before = self._advance(block.strain[:cut], block.encoder[:cut])
        self._rehome(int(block.encoder[cut]))
        after = self._advance(block.strain[cut:], block.encoder[cut:])
        return np.concatenate([before, after])

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
        one (exact). The calibration map was referred to the index pulse, so it is now in
        the right place; the estimate is re-solved at once.
        """
        shift = (count - self.frame_) % self.cpr_
        self.homed_ = True
        if shift == 0:
            return
        T = rotation(self.orders_, shift, self.cpr_)
        self.frame_ = count
        self.info_ = T @ self.info_ @ T.T
        self.vec_ = T @ self.vec_
        if self.history_ is not None:
            phi, y, end = self.history_
            m = 2 * len(self.orders_)
            self.history_ = (phi @ T[:m, :m].T, y, end)
        if self.adapt:
            self._solve()
        else:
            self.w_ = self.map_.copy()

    # ----------------------------------------------------------- the law
    def _solve(self) -> None:
        """``w = C (d + pi S w_cal)`` with ``C = (D + pi S)^-1``, from the current information.

        ``S`` (:attr:`scale_`) is diagonal: 1 for the no-load coefficients, the rated torque
        squared for the load terms, so ``prior_sd_nm`` and ``floor_sd_nm`` are both in Nm of
        ripple at rated load. ``S`` is constant over each (cos, sin) pair of every block, so
        re-homing rotations leave it unchanged.
        """
        prior = self.weight_ * self.scale_
        A = self.info_.copy()
        A.flat[::len(prior) + 1] += prior
        self.cov_ = np.linalg.inv(A)
        self.w_ = self.cov_ @ (self.vec_ + prior * self.map_)

    def _advance(self, strain: np.ndarray, encoder: np.ndarray) -> np.ndarray:
        """Process samples (a block or a part of one): learn from complete ticks, subtract."""
        if len(strain) == 0:
            return np.empty(0)
        first = len(self.pending_[0])
        all_strain = np.concatenate([self.pending_[0], strain])
        all_encoder = np.concatenate([self.pending_[1], encoder])
        D, U = self.tick_, int(self.update_ticks)
        # The map changes only at the end of an update period, so the ticks of an open
        # period wait (raw) until it completes: most ticks then cost only the subtraction.
        ticks = len(all_strain) // D
        done = ((self.ticks_done_ + ticks) // U) * U - self.ticks_done_
        weights = [self.w_]
        starts = []  # block-relative first sample of each new map
        if done and self.adapt:
            maps, ends = self._learn(all_strain[:done * D], all_encoder[:done * D])
            weights += list(maps)
            starts = [int(e) - first for e in ends]
        elif done:
            self.ticks_done_ += done
        self.pending_ = (all_strain[done * D:], all_encoder[done * D:])
        y = self.gain_ * strain + self.offset_
        phi = angle_regressors(encoder - self.frame_, self.orders_, self.table_)
        self.w_ = weights[-1]
        if len(weights) == 1:
            return y - ripple(phi, y, self.w_)
        # each sample sees the latest map solved at or before it: one product per map
        rows = map_rows(phi, y)
        out = np.empty(len(strain))
        bounds = [0] + [min(max(b, 0), len(strain)) for b in starts] + [len(strain)]
        for w, lo, hi in zip(weights, bounds[:-1], bounds[1:]):
            out[lo:hi] = y[lo:hi] - rows[lo:hi] @ w
        return out

    def _learn(self, strain, encoder):
        """Fold whole update periods of ticks into the information; the map after each.

        Per period ``p``: ``D = l D + sum psi psi' / r``, ``d = l d + sum psi z / r``,
        ``pi = l pi + (1 - l) / floor_sd^2`` with ``l = exp(-revolutions / memory_revs)``,
        then ``w = (D + pi S)^-1 (d + pi S w_cal)``. A tick enters only if the angle moved
        smoothly (:attr:`min_counts`, :attr:`max_jolt_counts`) and its innovation passes the
        gate of :meth:`_consistent`.

        Returns
        -------
        maps
            ``(P, n)``: the map after each update period.
        ends
            ``(P,)``: the sample (relative to ``strain[0]``) from which each map applies.
        """
        D, U = self.tick_, int(self.update_ticks)
        T = len(strain) // D  # a whole number of update periods (see _advance)
        ybar = self.gain_ * strain.reshape(T, D).mean(axis=1) + self.offset_
        ticks = encoder.reshape(T, D)
        phi = angle_regressors(ticks - self.frame_, self.orders_, self.table_).mean(axis=1)
        psi, z, moved, steps, jolt = self._differences(phi, ybar, ticks[:, -1])
        usable = (moved >= self.min_counts) & (jolt <= self.max_jolt_counts)
        P = T // U
        decay = np.exp(-steps.reshape(P, U).sum(axis=1) / (self.cpr_ * float(self.memory_revs)))
        maps = np.empty((P, len(self.map_)))
        for p in range(P):
            rows = slice(p * U, (p + 1) * U)
            keep = usable[rows] & self._consistent(psi[rows], z[rows])
            X = psi[rows][keep]
            self.info_ = decay[p] * self.info_ + (X.T @ X) / self.r_
            self.vec_ = decay[p] * self.vec_ + (X.T @ z[rows][keep]) / self.r_
            self.weight_ = decay[p] * self.weight_ + (1.0 - decay[p]) * self.floor_info_
            self._solve()
            maps[p] = self.w_
        self.ticks_done_ += T
        return maps, np.arange(1, P + 1) * U * D

    def _consistent(self, psi, z):
        """Innovation gate: False for ticks no ripple within the map's uncertainty explains.

        The innovation ``z - psi . w`` of the current map is compared with ``outlier_gate``
        standard deviations of its predicted spread, ``r + psi' C psi`` (``C`` the
        covariance of the map): the usual chi-square gate of a Kalman filter. An unknown
        torque step (load-steps: 15 Nm in 10 ms gives second differences of 0.8 Nm per tick)
        fails it; a map that is still uncertain (warm start, or after a long rest nothing
        was learned in) has a wide gate. Forgetting runs on revolutions whether ticks pass
        or not, so a map the gate has locked out widens its own gate again.
        """
        spread = self.r_ + np.sum((psi @ self.cov_) * psi, axis=1)
        return (z - psi @ self.w_) ** 2 <= self.outlier_gate ** 2 * spread

    def _differences(self, phi, ybar, end):
        """Second differences of the regressors and tick means over consecutive ticks.

        ``z_j = y_j - 2 y_{j-1} + y_{j-2}`` removes the torque and its rate; what is left
        of the torque is its second difference (the jerk over two ticks), the equation
        error. First differences were tried first: the torque steps of the calibration's
        speed ramps, which span a fraction of a revolution at low speed, correlate with
        the slow orders (1, 2) over so short an arc, and biased them (RMS error on the
        calibration log 0.11 Nm with the batch first-difference map against 0.058 Nm with
        second differences and 0.049 Nm with the level map). Only the angle part is
        differenced, ``psi = [d2 phi, y_{j-2} d2 phi, |y_{j-2}| d2 phi]``: a regressor
        built from ``y_j`` would contain the torque change that is the equation error,
        and the fit would be biased; the load is taken at the earliest tick, before it.

        Returns
        -------
        psi, z, moved, steps, jolt
            Rows, second differences, the counts turned in the last and the previous tick
            (the smaller of the two: both intervals must turn for the angle to move), the
            counts turned in the last tick, and the second difference of the end counts.
        """
        if self.history_ is None:  # repeat the first tick: zero differences, gate closed
            self.history_ = (np.repeat(phi[:1], 2, axis=0), np.repeat(ybar[:1], 2),
                             np.repeat(end[:1], 2))
        hp, hy, he = self.history_
        phi_all = np.vstack([hp, phi])
        y_all = np.concatenate([hy, ybar])
        end_all = np.concatenate([he, end])
        self.history_ = (phi_all[-2:].copy(), y_all[-2:].copy(), end_all[-2:].copy())
        d2phi = phi_all[2:] - 2.0 * phi_all[1:-1] + phi_all[:-2]
        z = y_all[2:] - 2.0 * y_all[1:-1] + y_all[:-2]
        steps = np.abs(np.diff(end_all)).astype(float)
        moved = np.minimum(steps[1:], steps[:-1])
        jolt = np.abs(end_all[2:] - 2 * end_all[1:-1] + end_all[:-2])
        return map_rows(d2phi, y_all[:-2]), z, moved, steps[1:], jolt


class AngleAdaptiveFrozen(AngleAdaptive):
    """Ablation: the calibration map, re-homed on the index pulse, never adapted."""

    name = "angle-adaptive-frozen"

    def __init__(self, orders: tuple = (1, 2, 4, 6, 8), memory_revs: float = 30.0,
                 prior_sd_nm: float = 0.3, floor_sd_nm: float = 1.0, min_counts: int = 2,
                 update_ticks: int = 10, outlier_gate: float = 4.0, max_jolt_counts: int = 2,
                 adapt: bool = False):
        super().__init__(orders=orders, memory_revs=memory_revs, prior_sd_nm=prior_sd_nm,
                         floor_sd_nm=floor_sd_nm, min_counts=min_counts, update_ticks=update_ticks,
                         outlier_gate=outlier_gate, max_jolt_counts=max_jolt_counts, adapt=adapt)

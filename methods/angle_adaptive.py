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
from numba import types

from rippleb.data import JointSpec, SensorBlock, SensorLog
from rippleb.dsp import (F8, F8_2D_C, F8_C, IN_F8, IN_I8, backward_substitute, cholesky, compiled,
                         forward_substitute)
from rippleb.method import Method

IN_C16 = types.Array(types.complex128, 1, "A", readonly=True)
I8 = types.int64[:]


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


#: Positions in the ``law`` array of the online law's constants (see ``AngleAdaptive.reset``).
LAW_R, LAW_GATE, LAW_MEMORY_COUNTS, LAW_FLOOR_INFO, LAW_MIN_COUNTS, LAW_MAX_JOLT = range(6)


def first_index_count(encoder: np.ndarray, index: np.ndarray | None) -> int | None:
    """The encoder count at the first index pulse, or None when there is none."""
    if index is None:
        return None
    hits = np.flatnonzero(index)
    return int(encoder[hits[0]]) if len(hits) else None


@compiled(types.void(F8_2D_C, F8, types.float64, IN_F8, IN_F8, F8_2D_C, F8))
def solve(info, vec, weight, scale, prior_map, chol, w):
    """``w = C (d + pi S w_cal)`` with ``C = (D + pi S)^-1``; ``chol`` the factor of ``D + pi S``.

    ``S`` (``scale``) is diagonal: 1 for the no-load coefficients, the rated torque squared
    for the load terms, so ``prior_sd_nm`` and ``floor_sd_nm`` are both in Nm of ripple at
    rated load. ``S`` is constant over each (cos, sin) pair of every block, so re-homing
    rotations leave it unchanged. The covariance ``C`` is kept as the Cholesky factor of
    its inverse (``C = L'^-1 L^-1``): the gate needs only ``psi' C psi = |L^-1 psi|^2``.
    """
    A = info.copy()
    for i in range(len(scale)):
        A[i, i] += weight * scale[i]
    cholesky(A, chol)
    rhs = vec + weight * scale * prior_map
    forward_substitute(chol, rhs)
    backward_substitute(chol, rhs)
    w[:] = rhs


@compiled(types.boolean(F8_C, types.float64, F8, F8_2D_C, IN_F8))
def consistent(psi, z, w, chol, law):
    """Innovation gate: False for a tick no ripple within the map's uncertainty explains.

    The innovation ``z - psi . w`` of the current map is compared with ``outlier_gate``
    standard deviations of its predicted spread, ``r + psi' C psi`` (``C`` the
    covariance of the map, from its factor ``chol``, see :func:`solve`): the usual
    chi-square gate of a Kalman filter. An unknown torque step (load-steps: 15 Nm in
    10 ms gives second differences of 0.8 Nm per tick) fails it; a map that is still
    uncertain (warm start, or after a long rest nothing was learned in) has a wide gate.
    Forgetting runs on revolutions whether ticks pass or not, so a map the gate has
    locked out widens its own gate again.
    """
    innovation = z
    for a in range(len(psi)):
        innovation -= psi[a] * w[a]
    whitened = psi.copy()
    forward_substitute(chol, whitened)
    spread = law[LAW_R] + whitened @ whitened
    return innovation * innovation <= law[LAW_GATE] ** 2 * spread


@compiled(types.void(F8_2D_C, F8, I8, types.int64, IN_F8, IN_F8, IN_F8, F8, F8_2D_C, F8_2D_C,
                     F8, F8))
def learn_period(ticks_phi, ticks_y, ticks_end, history, law, scale, prior_map, w, chol, info,
                 vec, scalars):
    """Fold one update period of ticks into the information, then re-solve the map.

    Rows ``2..`` of ``ticks_*`` hold the period's ticks (tick-mean regressors ``phi`` in
    the current frame, tick-mean ``y`` [Nm], end count), rows 0-1 the two ticks before
    (copied from the first tick when there is no ``history`` yet: zero differences, gate
    closed). Per tick, second differences over three consecutive ticks::

        psi = [d2 phi, y_{j-2} d2 phi, |y_{j-2}| d2 phi],  z = y_j - 2 y_{j-1} + y_{j-2}

    ``z`` removes the torque and its rate; what is left of the torque is its second
    difference (the jerk over two ticks), the equation error. First differences were
    tried first: the torque steps of the calibration's speed ramps, which span a fraction
    of a revolution at low speed, correlate with the slow orders (1, 2) over so short an
    arc, and biased them (RMS error on the calibration log 0.11 Nm with the batch
    first-difference map against 0.058 Nm with second differences and 0.049 Nm with the
    level map). Only the angle part is differenced: a regressor built from ``y_j`` would
    contain the torque change that is the equation error, and the fit would be biased;
    the load is taken at the earliest tick, before it.

    A tick enters only if both its intervals turned by ``min_counts`` (the angle moved),
    the second difference of the end counts is at most ``max_jolt_counts`` (no jump
    through the gear compliance) and :func:`consistent` passes it. Then
    ``D = l D + sum psi psi' / r``, ``d = l d + sum psi z / r``,
    ``pi = l pi + (1 - l) / floor_sd^2`` with ``l = exp(-revolutions / memory_revs)``,
    and :func:`solve`.
    """
    if history == 0:
        ticks_phi[0, :] = ticks_phi[2]
        ticks_phi[1, :] = ticks_phi[2]
        ticks_y[:2] = ticks_y[2]
        ticks_end[:2] = ticks_end[2]
    m = ticks_phi.shape[1]
    n = len(w)
    outer = np.zeros((n, n))
    inner = np.zeros(n)
    psi = np.empty(n)
    turned = 0.0
    for j in range(2, len(ticks_y)):
        load = ticks_y[j - 2]
        for q in range(m):
            d2 = ticks_phi[j, q] - 2.0 * ticks_phi[j - 1, q] + ticks_phi[j - 2, q]
            psi[q], psi[m + q], psi[2 * m + q] = d2, load * d2, abs(load) * d2
        z = ticks_y[j] - 2.0 * ticks_y[j - 1] + ticks_y[j - 2]
        last = abs(ticks_end[j] - ticks_end[j - 1])
        moved = min(last, abs(ticks_end[j - 1] - ticks_end[j - 2]))
        jolt = abs(ticks_end[j] - 2 * ticks_end[j - 1] + ticks_end[j - 2])
        turned += last
        if moved >= law[LAW_MIN_COUNTS] and jolt <= law[LAW_MAX_JOLT] and \
                consistent(psi, z, w, chol, law):
            for a in range(n):
                inner[a] += psi[a] * z
                for b in range(n):
                    outer[a, b] += psi[a] * psi[b]
    decay = np.exp(-turned / law[LAW_MEMORY_COUNTS])
    info[:, :] = decay * info + outer / law[LAW_R]
    vec[:] = decay * vec + inner / law[LAW_R]
    scalars[0] = decay * scalars[0] + (1.0 - decay) * law[LAW_FLOOR_INFO]
    solve(info, vec, scalars[0], scale, prior_map, chol, w)
    last_two = len(ticks_y) - 2
    ticks_phi[:2, :] = ticks_phi[last_two:].copy()
    ticks_y[:2] = ticks_y[last_two:].copy()
    ticks_end[:2] = ticks_end[last_two:].copy()


@compiled(types.void(IN_F8, IN_I8, F8, types.float64, types.float64, types.int64, IN_I8, IN_C16,
                     types.int64, types.int64, types.boolean, IN_F8, IN_F8, IN_F8, F8, F8_2D_C,
                     F8_2D_C, F8, F8, I8, F8, F8_2D_C, F8, I8))
def stream(strain, encoder, out, gain, offset, frame, orders, table, tick, update_ticks, adapt,
           law, scale, prior_map, w, chol, info, vec, scalars, counters, tick_phi, ticks_phi,
           ticks_y, ticks_end):
    """Subtract the current map from every sample; with ``adapt``, learn on the way.

    Per sample: ``out = y - phi(theta) . (c0 + c1 y + c2 |y|)`` with ``y`` the strain in
    Nm and ``theta`` the count relative to ``frame``. With ``adapt`` the sample is also
    added to its control tick (``tick`` samples, counted from the reset, so the output
    does not depend on the block cutting); each complete tick is stored, and after
    ``update_ticks`` ticks :func:`learn_period` re-solves the map, which applies from the
    next sample on. The open tick and period are carried over between calls in
    ``scalars``, ``counters``, ``tick_phi`` and ``ticks_*`` (see ``AngleAdaptive.reset``).
    """
    m = len(orders)
    cpr = len(table)
    strain_sum, in_tick, in_period = scalars[1], counters[0], counters[1]
    for s in range(len(strain)):
        y = gain * strain[s] + offset
        magnitude = abs(y)
        base = (encoder[s] - frame) % cpr
        total = 0.0
        for i in range(m):
            phasor = table[(base * orders[i]) % cpr]
            c, sn = phasor.real, phasor.imag
            a, b = 2 * i, 2 * i + 1
            total += c * (w[a] + y * w[2 * m + a] + magnitude * w[4 * m + a]) \
                + sn * (w[b] + y * w[2 * m + b] + magnitude * w[4 * m + b])
            if adapt:
                tick_phi[a] += c
                tick_phi[b] += sn
        out[s] = y - total
        if not adapt:
            continue
        strain_sum += strain[s]
        in_tick += 1
        if in_tick < tick:
            continue
        row = 2 + in_period
        for q in range(2 * m):
            ticks_phi[row, q] = tick_phi[q] * (1.0 / tick)
            tick_phi[q] = 0.0
        ticks_y[row] = gain * (strain_sum / tick) + offset
        ticks_end[row] = encoder[s]
        strain_sum, in_tick, in_period = 0.0, 0, in_period + 1
        if in_period == update_ticks:
            learn_period(ticks_phi, ticks_y, ticks_end, counters[2], law, scale, prior_map, w,
                         chol, info, vec, scalars)
            counters[2] = 1
            in_period = 0
    scalars[1], counters[0], counters[1] = strain_sum, in_tick, in_period


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
    description = ("an angle-indexed ripple map warm-started from calibration, adapted online by RLS"
                   " (memory_revs=30.0), re-homed on the index pulse")

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
        self.cpr_ = int(spec.counts_per_rev)
        self.orders_ = np.asarray(self.orders, dtype=np.int64)
        self.table_ = phasor_table(self.cpr_)
        n = len(self.map_)
        m = 2 * len(self.orders_)
        U = int(self.update_ticks)
        self.scale_ = np.concatenate([np.ones(m), np.full(2 * m, float(spec.rated_torque) ** 2)])
        self.law_ = np.array([self.r_, float(self.outlier_gate),
                              self.cpr_ * float(self.memory_revs), 1.0 / self.floor_sd_nm ** 2,
                              float(self.min_counts), float(self.max_jolt_counts)])
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
               self.ticks_end_)

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

    def __init__(self, orders: tuple = (1, 2, 4, 6, 8), memory_revs: float = 30.0,
                 prior_sd_nm: float = 0.3, floor_sd_nm: float = 1.0, min_counts: int = 2,
                 update_ticks: int = 10, outlier_gate: float = 4.0, max_jolt_counts: int = 2,
                 adapt: bool = False):
        super().__init__(orders=orders, memory_revs=memory_revs, prior_sd_nm=prior_sd_nm,
                         floor_sd_nm=floor_sd_nm, min_counts=min_counts, update_ticks=update_ticks,
                         outlier_gate=outlier_gate, max_jolt_counts=max_jolt_counts, adapt=adapt)

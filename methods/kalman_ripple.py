"""``kalman-ripple``: a Kalman filter whose state holds the torque and the ripple harmonics.

After Taghirad & Belanger (IEEE TIM 1998), who model the torque ripple of a harmonic
drive as harmonics of the wave-generator angle and estimate it jointly with the torque
by Kalman filtering. Here the strain, converted to Nm with the calibrated gain/offset,
is modelled per control tick as::

    y = tau * (1 + c1 . phi + sgn(tau) c2 . phi) + x_c . phi + v

with ``phi = [cos(k theta), sin(k theta)]`` for the orders ``k`` of the model (block
means over the tick), ``theta`` the wave-generator angle from the encoder, ``x_c`` the
ripple coefficients (a random walk, started from the no-load map) and ``c1``, ``c2`` the
load dependence of the ripple, identified once in :meth:`KalmanRipple.fit`. The state is
``[tau, (tau_rate), a_k1, b_k1, a_k2, b_k2, ...]``; the measurement matrix ``H`` varies
with the angle, so the filter is an ordinary linear, time-varying Kalman filter (filterpy
``KalmanFilter`` with a per-call ``H``), written out by hand for speed
(:func:`kf_step` is tested against ``filterpy`` to 1e-6).

Why one update per control tick on the tick mean is enough: the measurement model is
linear in the state, so the mean of ``H x`` over a tick is ``mean(H) x`` exactly as long
as the state is constant within the tick (1 ms), and ``mean(H)`` is computed from every
encoder sample. A ripple faster than the tick rate is averaged out of both ``y`` and
``H`` alike; it is not aliased. See ``docs/methods/kalman-ripple.md`` for the rates in
the scenarios.

Re-homing: the ripple map is a function of the absolute wave-generator angle, but an
incremental encoder counts from wherever it stood at power-on. When the logs have an
``index`` column (the encoder's once-per-revolution index pulse), :meth:`KalmanRipple.fit`
finds the count of the index mark in the calibration log's frame, and every index pulse of
a scored run re-homes the count into that frame (:class:`~rippleb.methods._homing.IndexHoming`):
at the first pulse after a power cycle the map restarts in the new frame, and later pulses
correct missed or spurious counts. Until the first pulse of a run the count is taken as it
comes, as without an index column: the right frame in the calibration session's power-on,
a wrong one after a power cycle.

Ticks are cut on absolute sample indices (every ``tick`` samples since :meth:`reset`),
not on block boundaries, so the output does not depend on how the stream is cut. Each
sample's output is the posterior torque of the latest complete tick (held), extrapolated
with the torque rate when the state has one. The compiled filter (``kf_step``,
``stream_block``, ``kf_run_batch``) is in ``_kalman_ripple_filter.py`` beside this module;
``step`` is one call of ``stream_block``.
"""

from __future__ import annotations

import numpy as np

from rippleb.data import JointSpec, SensorBlock, SensorLog
from rippleb.method import Method
from rippleb.methods._homing import IndexHoming, index_mark
# the compiled filter lives beside the class; its tick step stays importable from here
from rippleb.methods._kalman_ripple_filter import (  # noqa: F401
    LOGGED, LOGGED_COUNT, RESTART_AT, SAMPLES, kf_run_batch, kf_step, stream_block)

#: the ``index`` of a block without one, or of a run without an index mark: no re-homing
NO_INDEX = np.zeros(0, dtype=np.int8)


def phasor_table(counts_per_rev: int) -> np.ndarray:
    """``exp(2j pi n / counts_per_rev)`` for every encoder position ``n``.

    A table lookup on integer ``(order * count) mod counts_per_rev`` gives the same
    bits whatever the block cutting, and is faster than ``cos``/``sin``.
    """
    return np.exp(2j * np.pi * np.arange(counts_per_rev) / counts_per_rev)


def tick_regressors(encoder: np.ndarray, orders: np.ndarray, table: np.ndarray) -> np.ndarray:
    """Tick means of ``[cos(k theta), sin(k theta)]`` per order, interleaved.

    Parameters
    ----------
    encoder
        Integer counts, shape ``(ticks, samples_per_tick)``.
    orders
        Integer ripple orders of the wave-generator angle.
    table
        :func:`phasor_table` of the encoder.

    Returns
    -------
    ndarray, shape ``(ticks, 2 * len(orders))``
    """
    index = (encoder[..., None] * orders) % len(table)
    # sum times 1/n rather than mean(): same value, a third of the call overhead
    mean = table[index].sum(axis=-2) * (1.0 / encoder.shape[-1])
    out = np.empty(mean.shape[:-1] + (2 * len(orders),))
    out[..., 0::2] = mean.real
    out[..., 1::2] = mean.imag
    return out


class KalmanRipple(Method):
    """Torque and ripple harmonics as the state of a Kalman filter (Taghirad & Belanger).

    Parameters
    ----------
    orders
        Ripple orders of the wave-generator angle held in the state as sine/cosine
        pairs. Default ``(1, 2, 4, 8)``: the orders 2, 4 (dominant) and 8 of the
        paper's Fig. 2 plus the once-per-revolution misalignment term of Taghirad &
        Belanger; order 6 is left out, as a model error the filter has to live with.
    load_map
        Identify in :meth:`fit` how the ripple coefficients grow with the load (terms
        ``tau phi`` and ``|tau| phi``) and put that map into ``H``. If false, the
        coefficients have to follow the load as a random walk alone.
    torque_rate
        Add the torque rate to the state (integrated random walk) so that ramps are
        followed without lag; otherwise the torque is a random walk.
    q_torque
        Process noise of the torque per tick [Nm^2] (of the torque rate [(Nm/s)^2] if
        ``torque_rate``). ``None``: identified in :meth:`fit`.
    q_ripple
        Process noise of each ripple coefficient per revolution of the wave generator
        [Nm^2/rev]: the ripple is a function of the angle, so its coefficients only
        wander while the wave generator turns, and at rest the unobservable split
        between torque and ripple does not grow. ``None``: identified in :meth:`fit`.
    q_grid
        Multipliers, in decades, of the candidate noise levels scanned by :meth:`fit`
        around its starting values.
    tick
        Samples per filter update; ``None`` for one control tick (``spec.block_size``).
    """

    name = "kalman-ripple"
    description = ("Kalman filter with the torque and the ripple harmonics at orders 1, 2, 4, 8 in "
                   "its state (Taghirad & Belanger)")
    #: nothing for the protocol to tune: its noise levels are chosen on the calibration log
    #: by its own likelihood search (q_grid), part of its fit
    tunable = {}

    def __init__(self, orders=(1, 2, 4, 8), load_map=True, torque_rate=False, q_torque=None,
                 q_ripple=None, q_grid=(-4, -3, -2, -1, 0, 1, 2), tick=None):
        self.orders = orders
        self.load_map = load_map
        self.torque_rate = torque_rate
        self.q_torque = q_torque
        self.q_ripple = q_ripple
        self.q_grid = q_grid
        self.tick = tick

    # ------------------------------------------------------------------ fit
    def fit(self, calibration: SensorLog) -> None:
        """Identify gain, offset, ripple map, measurement and process noise.

        1. Least squares, on tick means of the whole log, of the strain against
           ``[tau_ref, 1, phi, tau_ref phi, |tau_ref| phi]``: the gain and offset, the
           no-load ripple coefficients ``c0`` and the load map ``c1``, ``c2``.
        2. Measurement noise ``r``: half the variance of the first difference of the
           least-squares residual (in Nm, per tick). Differencing keeps the white ADC
           noise and fast unmodelled ripple, and drops the slow part of the residual
           (``torque_true - torque_ref``, the unmodelled load), which the torque state
           absorbs.
        3. Process noise ``q_torque``, ``q_ripple``: the pair that maximises the
           innovation log-likelihood of the filter run over the calibration log, on a
           grid of ``q_grid`` decades around ``var(diff(tau_ref))`` (per tick) and
           ``r`` (per revolution).
        """
        self._setup(calibration.spec)
        D = self.tick_
        ticks = len(calibration) // D
        encoder = calibration.encoder[:ticks * D].reshape(ticks, D)
        strain = calibration.strain[:ticks * D].reshape(ticks, D).sum(axis=1) / D
        tau = calibration.torque_ref[:ticks * D].reshape(ticks, D).mean(axis=1)
        phi = tick_regressors(encoder, self.orders_, self.table_)
        self._fit_map(strain, tau, phi)
        y = self.gain_ * strain + self.offset_
        resid = y - tau - phi @ self.c0_ - tau * (phi @ self.c1_) - np.abs(tau) * (phi @ self.c2_)
        self.r_ = float(max(np.var(np.diff(resid)) / 2.0, 1e-12))
        self.residual_rms_ = float(np.std(resid))
        self._fit_noise(y, tau, phi, self._turns(encoder, encoder[0, 0]))
        self.index_mark_ = index_mark(calibration.encoder, calibration.index, self.spec_.counts_per_rev)

    def _fit_map(self, strain, tau, phi):
        """Least-squares gain, offset and ripple map (step 1 of :meth:`fit`)."""
        blocks = [tau[:, None], np.ones((len(tau), 1)), phi]
        if self.load_map:
            blocks += [tau[:, None] * phi, np.abs(tau)[:, None] * phi]
        coef, *_ = np.linalg.lstsq(np.hstack(blocks), strain, rcond=None)
        self.gain_ = float(1.0 / coef[0])
        self.offset_ = float(-coef[1] / coef[0])
        m = phi.shape[1]
        self.c0_ = self.gain_ * coef[2:2 + m]
        zero = np.zeros(m)
        self.c1_ = self.gain_ * coef[2 + m:2 + 2 * m] if self.load_map else zero
        self.c2_ = self.gain_ * coef[2 + 2 * m:2 + 3 * m] if self.load_map else zero

    def _fit_noise(self, y, tau, phi, turns):
        """Grid search of the process noise on the innovation likelihood (step 3)."""
        dt = self.tick_ / self.spec_.fs
        steps = np.diff(tau)
        q_tau0 = float(np.var(steps / dt if self.torque_rate else steps)) or self.r_
        grid = 10.0 ** np.asarray(self.q_grid, dtype=float)
        q_tau = [self.q_torque] if self.q_torque is not None else q_tau0 * grid
        q_rip = [self.q_ripple] if self.q_ripple is not None else self.r_ * grid
        pairs = np.array([(a, b) for a in q_tau for b in q_rip])
        # The torque column of H is linearised at the known torque_ref here, where the
        # filter uses its own prior later: the likelihood then scores the noise only.
        H = self._rows(phi, tau)
        x0, P0 = self._initial_state()
        G = len(pairs)
        x = np.repeat(x0[None], G, axis=0)
        P = np.repeat(P0[None], G, axis=0)
        q = np.stack([np.diag(self._q_torque_matrix(a)) for a in pairs[:, 0]])
        q_turn = np.stack([np.diag(self._q_ripple_matrix(b)) for b in pairs[:, 1]])
        F = self.F_ if self.torque_rate else None
        loglik = kf_run_batch(x, P, F, q, q_turn, turns, H, y, np.full(G, self.r_))
        best = int(np.argmax(loglik))
        self.q_torque_, self.q_ripple_ = (float(v) for v in pairs[best])
        self.loglik_grid_ = {"q_torque": pairs[:, 0], "q_ripple": pairs[:, 1], "loglik": loglik}

    # ------------------------------------------------------------ streaming
    def reset(self, spec: JointSpec) -> None:
        """Start the filter from the no-load ripple map and an unknown torque."""
        if not hasattr(self, "gain_"):
            raise RuntimeError("kalman-ripple needs fit(calibration) before reset")
        self._setup(spec)
        D = self.tick_
        self.q_tick_ = np.diag(self._q_torque_matrix(self.q_torque_)).copy()
        self.q_turn_ = np.diag(self._q_ripple_matrix(self.q_ripple_)).copy()
        self.x_, self.P_ = self._initial_state()
        self.homing_ = IndexHoming(mark=getattr(self, "index_mark_", None),
                                   counts_per_rev=int(spec.counts_per_rev))
        # the state of stream_block (positions named in _kalman_ripple_filter.py): the
        # samples of the open tick, counters (no tick yet, no map restart pending) and
        # constants with the latest posterior torque and rate
        self.counters_ = np.zeros(LOGGED + 1, dtype=np.int64)
        self.counters_[RESTART_AT] = -1
        self.scalars_ = np.array([self.gain_ / D, self.offset_, self.r_, float(spec.fs),
                                  0.5 * (D - 1), 0.0, 0.0])
        maps = np.stack([self.c0_, self.c1_, self.c2_])
        noise = np.stack([self.q_tick_, self.q_turn_])
        self.stream_state_ = (np.zeros(D), np.zeros(D, dtype=np.int64), self.orders_, self.table_,
                              maps, noise, self.F_, self.x_, self.P_, self.counters_, self.scalars_)

    def step(self, block: SensorBlock) -> np.ndarray:
        """One torque estimate [Nm] per sample: the latest tick's posterior, held."""
        out = np.empty(len(block.strain))
        homing = self.homing_
        index = NO_INDEX if block.index is None or homing.mark is None else block.index
        try:
            cold = stream_block(block.strain, block.encoder, homing.shift, index, out,
                                *self.stream_state_)
        except TypeError:   # columns of other dtypes than a log's: as a log holds them
            block, index = self._as_logged(block, index)
            cold = stream_block(block.strain, block.encoder, homing.shift, index, out,
                                *self.stream_state_)
        counts = None
        if cold < 0:   # an index pulse in the block: re-home its counts, then filter them
            counts = self._rehome(block)
            cold = stream_block(block.strain, counts, 0, NO_INDEX, out, *self.stream_state_)
            self.counters_[LOGGED_COUNT] = block.encoder[-1]
        if cold:       # before the first tick of the run ends
            if counts is None:
                counts = block.encoder[:cold] - homing.shift
            self._before_first_tick(out[:cold], block.strain[:cold], counts[:cold])
        return out

    @staticmethod
    def _as_logged(block: SensorBlock, index):
        """``block`` with the dtypes of a log's columns (float strain, int64 counts, int8
        index), and its index (``NO_INDEX`` stays)."""
        block = SensorBlock(block.t, np.asarray(block.strain, dtype=float),
                            np.asarray(block.encoder, dtype=np.int64), block.current,
                            None if block.index is None else (block.index != 0).astype(np.int8))
        return block, (index if index is NO_INDEX else block.index)

    def _rehome(self, block: SensorBlock) -> np.ndarray:
        """The block's counts in the calibration frame (:class:`IndexHoming`); the first
        homing of a run that moves the frame restarts the map at the tick that reaches it."""
        counters = self.counters_
        # stream_block keeps the last logged count; the homing needs it for a pulse at 0
        self.homing_.last = int(counters[LOGGED_COUNT]) if counters[LOGGED] else None
        counts, pulse = self.homing_.counts(block.encoder, block.index, int(counters[SAMPLES]))
        if pulse is not None:
            counters[RESTART_AT] = pulse
        return np.asarray(counts, dtype=np.int64)

    def _before_first_tick(self, out, strain, counts) -> None:
        """Strain in Nm minus the no-load ripple at each sample's count, in place of an
        estimate before the first tick ends."""
        phase = self.table_[(counts[:, None] * self.orders_) % len(self.table_)]
        ripple = phase.real @ self.c0_[0::2] + phase.imag @ self.c0_[1::2]
        out[:] = self.gain_ * strain + self.offset_ - ripple

    # -------------------------------------------------------------- helpers
    def _setup(self, spec):
        """Derived constants that depend on the joint only."""
        self.spec_ = spec
        self.tick_ = int(self.tick or spec.block_size)
        self.orders_ = np.asarray(self.orders, dtype=np.int64)
        self.table_ = phasor_table(int(spec.counts_per_rev))
        self.n_torque_ = 2 if self.torque_rate else 1
        n = self.n_torque_ + 2 * len(self.orders_)
        F = np.eye(n)
        if self.torque_rate:
            F[0, 1] = self.tick_ / spec.fs
        self.F_ = F

    def _turns(self, ticks, start):
        """Wave-generator revolutions turned in each tick, from the count before it."""
        ends = ticks[:, -1]
        before = np.empty(len(ends), dtype=ends.dtype)
        before[0] = start
        before[1:] = ends[:-1]
        return np.abs(ends - before) * (1.0 / self.spec_.counts_per_rev)

    def _rows(self, phi, tau):
        """Measurement rows ``H`` for regressors ``phi`` (ticks, 2m) about torques ``tau``.

        The torque column is ``1 + c1 . phi + sgn(tau) c2 . phi``: exact for the linear
        term and, for the ``|tau|`` term, linearised at the sign of ``tau``.
        """
        H = np.zeros((len(phi), self.n_torque_ + phi.shape[1]))
        H[:, 0] = 1.0 + phi @ self.c1_ + np.sign(tau) * (phi @ self.c2_)
        H[:, self.n_torque_:] = phi
        return H

    def _initial_state(self):
        """Torque unknown (variance of the rated torque squared), ripple at its no-load map."""
        n = self.n_torque_ + len(self.c0_)
        x = np.zeros(n)
        x[self.n_torque_:] = self.c0_
        P = np.zeros((n, n))
        P[0, 0] = self.spec_.rated_torque ** 2
        if self.torque_rate:
            P[1, 1] = (self.spec_.rated_torque / 0.1) ** 2  # rated torque within 0.1 s
        # the map is known to about the fit's noise level
        P[self.n_torque_:, self.n_torque_:] = np.eye(len(self.c0_)) * self.r_
        return x, P

    def _q_torque_matrix(self, q_torque):
        """Process noise per tick: on the torque, or on its rate."""
        n = self.n_torque_ + len(self.c0_)
        Q = np.zeros((n, n))
        Q[self.n_torque_ - 1, self.n_torque_ - 1] = q_torque
        return Q

    def _q_ripple_matrix(self, q_ripple):
        """Process noise per wave-generator revolution on each ripple coefficient."""
        n = self.n_torque_ + len(self.c0_)
        q = np.full(n, float(q_ripple))
        q[:self.n_torque_] = 0.0
        return np.diag(q)

"""The compiled Kalman filter of ``kalman-ripple``: one tick's predict and update, a bank of
filters for the noise fit, and the streaming step over one block (:func:`stream_block`: one
compiled call per ``step``, which is what keeps a 20-sample tick's cost near one
``lfilter`` call's).

The loops of :class:`~rippleb.methods.kalman_ripple.KalmanRipple`
(``methods/kalman_ripple.py``, whose docstring gives the model), kept beside it. A private
module (leading underscore), so method discovery skips it.
"""

from __future__ import annotations

import numpy as np
from numba import types

from rippleb.dsp import F8, F8_2D, IN_F8, IN_F8_2D, IN_I8, compiled

IN_C16 = types.Array(types.complex128, 1, "A", readonly=True)

LOG_2PI = float(np.log(2.0 * np.pi))


_INNOVATION = types.UniTuple(types.float64, 2)


@compiled(_INNOVATION(F8, F8_2D, IN_F8_2D, types.boolean, IN_F8, IN_F8, types.float64,
                      types.float64))
def kf_step(x, P, F, predict, q, h, z, r):
    """One predict and scalar update of a Kalman filter, in place; returns the innovation terms.

    Same equations as ``filterpy.kalman.KalmanFilter.predict`` with ``Q = diag(q)``,
    then ``update(z, R=r, H=h)``, with the short covariance update ``P - K S K'``
    (equal to filterpy's Joseph form for the optimal gain up to rounding).

    Parameters
    ----------
    x, P
        State ``(n,)`` and covariance ``(n, n)``, updated in place.
    F, predict
        Transition ``(n, n)``, applied only if ``predict`` (False: the identity, a random
        walk, which saves two matrix products per tick).
    q
        Diagonal of the process noise ``(n,)``.
    h, z, r
        Measurement row ``(n,)``, measurement and its variance.

    Returns
    -------
    innovation, innovation_variance
    """
    n = len(x)
    if predict:                  # x = F x, P = F P F'
        fx, fp = np.zeros(n), np.zeros((n, n))
        for i in range(n):
            for k in range(n):
                fx[i] += F[i, k] * x[k]
                for j in range(n):
                    fp[i, j] += F[i, k] * P[k, j]
        x[:] = fx
        for i in range(n):
            for j in range(n):
                P[i, j] = 0.0
                for k in range(n):
                    P[i, j] += fp[i, k] * F[j, k]
    for i in range(n):
        P[i, i] += q[i]
    ph = np.zeros(n)
    for i in range(n):
        for j in range(n):
            ph[i] += P[i, j] * h[j]
    s = r
    e = z
    for i in range(n):
        s += h[i] * ph[i]
        e -= h[i] * x[i]
    for i in range(n):
        k = ph[i] / s
        x[i] += k * e
        for j in range(n):
            P[i, j] -= k * ph[j]
    return e, s


def kf_run_batch(x, P, F, q, q_turn, turns, H, z, r):
    """Run a bank of filters that differ in their noise levels over the same ticks.

    Used by :meth:`KalmanRipple.fit` to score a grid of noise levels in one pass; the
    equations are those of :func:`kf_step`.

    Parameters
    ----------
    x, P
        Initial states ``(G, n)`` and covariances ``(G, n, n)``, updated in place.
    F
        Transition ``(n, n)``, shared; ``None`` for the identity.
    q, q_turn, turns
        Diagonal process noise per tick ``(G, n)``, per revolution of the wave
        generator ``(G, n)``, and revolutions turned in each tick ``(T,)``: tick ``t``
        adds ``q + turns[t] q_turn`` to the diagonal of ``P``.
    H, z
        Measurement rows ``(T, n)`` (the torque column already linearised) and
        measurements ``(T,)``.
    r
        Measurement variance ``(G,)``.

    Returns
    -------
    ndarray, shape ``(G,)``
        The Gaussian log-likelihood of the innovations, summed over ticks.
    """
    diagonal = np.arange(x.shape[1])
    loglik = np.zeros(len(x))
    for h, zk, turn in zip(H, z, turns):
        if F is not None:
            x[:] = x @ F.T
            P[:] = F @ P @ F.T
        P[:, diagonal, diagonal] += q + turn * q_turn
        ph = P @ h
        s = ph @ h + r
        e = zk - x @ h
        k = ph / s[:, None]
        x += k * e[:, None]
        P -= k[:, :, None] * ph[:, None, :]
        loglik -= 0.5 * (LOG_2PI + np.log(s) + e * e / s)
    return loglik


@compiled(types.float64(IN_F8, types.int64, types.int64))
def pairwise_sum(a, start, n):
    """``a[start:start + n]`` summed in numpy's order (``np.add.reduce``'s pairwise summation).

    Below 8 values one running sum; up to 128, eight running sums over strides of 8, joined
    pairwise, then the rest one by one; beyond, the two halves (split at a multiple of 8)
    summed apart. ``0.0 + pairwise_sum(a, 0, n)`` is ``a.sum()`` bit for bit, so that the
    streaming tick means equal the numpy ones they replaced (and :meth:`KalmanRipple.fit`'s).
    """
    if n < 8:
        total = -0.0
        for i in range(start, start + n):
            total += a[i]
        return total
    if n <= 128:
        r0, r1, r2, r3 = a[start], a[start + 1], a[start + 2], a[start + 3]
        r4, r5, r6, r7 = a[start + 4], a[start + 5], a[start + 6], a[start + 7]
        i = 8
        while i < n - n % 8:
            k = start + i
            r0 += a[k]
            r1 += a[k + 1]
            r2 += a[k + 2]
            r3 += a[k + 3]
            r4 += a[k + 4]
            r5 += a[k + 5]
            r6 += a[k + 6]
            r7 += a[k + 7]
            i += 8
        total = ((r0 + r1) + (r2 + r3)) + ((r4 + r5) + (r6 + r7))
        for k in range(start + i, start + n):
            total += a[k]
        return total
    half = n // 2
    half -= half % 8
    return pairwise_sum(a, start, half) + pairwise_sum(a, start + half, n - half)


@compiled(types.void(IN_I8, types.float64, types.int64, IN_I8, IN_C16, IN_F8, IN_F8, IN_F8_2D,
                     IN_F8, IN_F8, types.float64, F8, F8_2D, F8))
def filter_tick(counts, y, before, orders, table, c1, c2, F, q_tick, q_turn, r, x, P, h):
    """One tick of the filter: regressors, measurement row, predict and update.

    The tick means of ``[cos(k theta), sin(k theta)]`` of its ``counts``
    (:func:`tick_regressors`), the measurement row ``[1 + c1 . phi + sgn(prior) c2 . phi,
    (0), phi]`` with the ``|tau|`` term linearised at the sign of the predicted torque, the
    process noise ``q_tick + turns q_turn`` for the wave-generator revolutions turned since
    the count ``before``, then :func:`kf_step` on the tick's mean strain ``y`` [Nm].

    Parameters
    ----------
    F
        Transition; applied only with the torque rate in the state (``len(x) - len(c1) ==
        2``), otherwise the identity.
    x, P
        State and covariance, updated in place.
    h
        Work array ``(len(x),)`` for the measurement row, zero where no regressor goes (the
        torque-rate column).
    """
    n_torque = len(x) - len(c1)
    torque_rate = n_torque == 2
    m = len(table)
    lin, load = 1.0, 0.0
    for i in range(len(orders)):
        total = 0j
        for k in range(len(counts)):
            total += table[(counts[k] * orders[i]) % m]
        mean = total * (1.0 / len(counts))
        h[n_torque + 2 * i], h[n_torque + 2 * i + 1] = mean.real, mean.imag
    for i in range(n_torque, len(x)):
        lin += c1[i - n_torque] * h[i]
        load += c2[i - n_torque] * h[i]
    # linearise the |tau| term of the map at the sign of the predicted torque
    prior = x[0] + F[0, 1] * x[1] if torque_rate else x[0]
    h[0] = lin + (load if prior > 0 else -load if prior < 0 else 0.0)
    turns = abs(counts[-1] - before) * (1.0 / m)
    q = np.empty(len(x))
    for i in range(len(x)):
        q[i] = q_tick[i] + turns * q_turn[i]
    kf_step(x, P, F, torque_rate, q, h, y, r)


#: positions in the ``counters`` of :func:`stream_block`: samples held of the open tick,
#: samples output since the latest tick ended, whether a tick has ended (there is an
#: estimate), the count that ended the latest tick and whether there is one, the absolute
#: index of the next sample, the sample at which the map restarts (-1: none pending), the
#: last logged (not re-homed) count and whether there is one
HELD, SINCE_TICK, ESTIMATED, LAST_COUNT, COUNTED, SAMPLES, RESTART_AT, LOGGED_COUNT, LOGGED = range(9)
#: positions in its ``scalars``: ``gain / tick``, ``offset``, ``r``, ``fs``, the tick centre
#: before its last sample ``(tick - 1) / 2``, and the latest tick's posterior torque and rate
GAIN_PER_SAMPLE, OFFSET, R, FS, CENTRE, TORQUE, RATE = range(7)

IN_I1 = types.Array(types.int8, 1, "A", readonly=True)
I8 = types.int64[:]


@compiled(types.int64(IN_F8, IN_I8, types.int64, IN_I1, F8, F8, I8, IN_I8, IN_C16, IN_F8_2D,
                      IN_F8_2D, IN_F8_2D, F8, F8_2D, I8, F8))
def stream_block(strain, encoder, shift, index, out, held_strain, held_counts, orders, table,
                 maps, noise, F, x, P, counters, scalars):
    """One block of :meth:`KalmanRipple.step` in one call: the held samples of the open tick,
    the filter at every tick end, and one estimate per sample.

    ``encoder - shift`` are the counts in the calibration frame; a block with an index
    pulse (``index`` nonzero anywhere) is left untouched and -1 returned, for the caller
    to re-home it (:class:`~rippleb.methods._homing.IndexHoming`) and pass its counts with
    ``shift`` 0 and no ``index``. Ticks are cut on absolute sample indices: the
    ``len(held_strain)`` samples of a tick are held (``held_strain``, ``held_counts``)
    until its last one arrives, whatever block it comes in. At a tick end the map restarts
    first if the restart sample has come (``counters[RESTART_AT]``), then
    :func:`filter_tick` runs on the tick mean ``gain / tick * sum(strain) + offset``, the
    sum in numpy's order (:func:`pairwise_sum`). Each sample's output is the latest
    tick's posterior torque, extrapolated with the torque rate when the state has one,
    from the tick centre.

    Parameters
    ----------
    maps
        ``(3, 2m)``: the no-load ripple map ``c0`` (the restart value of the ripple state)
        and the load map ``c1``, ``c2``.
    noise
        ``(2, n)``: the process noise per tick and per wave-generator revolution.
    counters, scalars
        State and constants at the positions named above, updated in place.

    Returns
    -------
    int
        The number of leading samples before the first tick end of the run (not written:
        the caller writes them from the strain alone), or -1 for a block to re-home.
    """
    for s in range(len(index)):
        if index[s] != 0:
            return -1
    D = len(held_strain)
    n_torque = len(x) - maps.shape[1]
    torque_rate = n_torque == 2
    h = np.zeros(len(x))
    cold = 0
    for s in range(len(strain)):
        k = counters[HELD]
        held_strain[k] = strain[s]
        held_counts[k] = encoder[s] - shift
        counters[HELD] = k + 1
        if k + 1 == D:
            counters[HELD] = 0
            restart = counters[RESTART_AT]
            if 0 <= restart <= counters[SAMPLES] + s:   # back to the calibrated map first
                for i in range(n_torque, len(x)):
                    x[i] = maps[0, i - n_torque]
                    for j in range(len(x)):
                        P[i, j] = 0.0
                        P[j, i] = 0.0
                    P[i, i] = scalars[R]
                counters[RESTART_AT] = -1
            before = counters[LAST_COUNT] if counters[COUNTED] else held_counts[0]
            y = scalars[GAIN_PER_SAMPLE] * (0.0 + pairwise_sum(held_strain, 0, D)) + scalars[OFFSET]
            filter_tick(held_counts, y, before, orders, table, maps[1], maps[2], F, noise[0],
                        noise[1], scalars[R], x, P, h)
            counters[LAST_COUNT], counters[COUNTED] = held_counts[D - 1], 1
            scalars[TORQUE], scalars[RATE] = x[0], (x[1] if torque_rate else 0.0)
            counters[ESTIMATED], counters[SINCE_TICK] = 1, 0
        if counters[ESTIMATED] == 0:
            cold += 1
        elif torque_rate:
            k = counters[SINCE_TICK]
            out[s] = scalars[TORQUE] + scalars[RATE] * (k + scalars[CENTRE]) / scalars[FS]
            counters[SINCE_TICK] = k + 1
        else:
            out[s] = scalars[TORQUE]
    if len(encoder):
        counters[LOGGED_COUNT], counters[LOGGED] = encoder[-1], 1
    counters[SAMPLES] += len(strain)
    return cold

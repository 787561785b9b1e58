"""The compiled Kalman filter of ``kalman-ripple``: one tick's predict and update, a bank of
filters for the noise fit, and the run over a block's ticks.

The loops of :class:`~rippleb.methods.kalman_ripple.KalmanRipple`
(``methods/kalman_ripple.py``, whose docstring gives the model), kept beside it. A private
module (leading underscore), so method discovery skips it.
"""

from __future__ import annotations

import numpy as np
from numba import types

from rippleb.dsp import F8, F8_2D, IN_F8, IN_F8_2D, IN_I8, compiled

IN_I8_2D = types.Array(types.int64, 2, "A", readonly=True)
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


@compiled(types.void(IN_I8_2D, IN_F8, types.int64, IN_I8, IN_C16, IN_F8, IN_F8,
                     IN_F8_2D, types.boolean, IN_F8, IN_F8, types.float64, F8, F8_2D, F8_2D))
def filter_ticks(ticks, y, before, orders, table, c1, c2, F, torque_rate, q_tick, q_turn, r,
                 x, P, posterior):
    """Run the filter over whole ticks: regressors, measurement row, predict and update.

    Per tick ``j``: the tick means of ``[cos(k theta), sin(k theta)]``
    (:func:`tick_regressors`), the measurement row ``[1 + c1 . phi + sgn(prior) c2 . phi,
    (0), phi]`` with the ``|tau|`` term linearised at the sign of the predicted torque, the
    process noise ``q_tick + turns q_turn`` for the wave-generator revolutions turned since
    the count ``before``, then :func:`kf_step` on the tick's mean strain ``y[j]`` [Nm].

    Parameters
    ----------
    ticks
        Encoder counts, ``(ticks, samples_per_tick)``.
    F
        Transition; applied only with ``torque_rate`` (otherwise the identity).
    x, P
        State and covariance, updated in place.
    posterior
        ``(ticks, 2)``: the posterior torque and torque rate (0 without ``torque_rate``).
    """
    n_torque = 2 if torque_rate else 1
    m = len(table)
    h = np.zeros(len(x))
    for j in range(ticks.shape[0]):
        lin, load = 1.0, 0.0
        for i in range(len(orders)):
            total = 0j
            for k in range(ticks.shape[1]):
                total += table[(ticks[j, k] * orders[i]) % m]
            mean = total * (1.0 / ticks.shape[1])
            h[n_torque + 2 * i], h[n_torque + 2 * i + 1] = mean.real, mean.imag
        for i in range(n_torque, len(x)):
            lin += c1[i - n_torque] * h[i]
            load += c2[i - n_torque] * h[i]
        # linearise the |tau| term of the map at the sign of the predicted torque
        prior = x[0] + F[0, 1] * x[1] if torque_rate else x[0]
        h[0] = lin + (load if prior > 0 else -load if prior < 0 else 0.0)
        turns = abs(ticks[j, -1] - before) * (1.0 / m)
        before = ticks[j, -1]
        q = q_tick + turns * q_turn
        kf_step(x, P, F, torque_rate, q, h, y[j], r)
        posterior[j, 0] = x[0]
        posterior[j, 1] = x[1] if torque_rate else 0.0

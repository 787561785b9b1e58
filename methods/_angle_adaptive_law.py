"""The compiled online law of ``angle-adaptive``: RLS with stabilised forgetting, per tick.

The per-sample and per-period loops of :class:`~rippleb.methods.angle_adaptive.AngleAdaptive`
(``methods/angle_adaptive.py``, whose docstring gives the model), kept beside it: ``stream``
subtracts the map and gathers control ticks, ``learn_period`` folds them into the
information and ``solve`` re-solves the map, ``consistent`` is the innovation gate. Two
options serve ``gear-keeping`` (``methods/gear_keeping.py``) and leave ``angle-adaptive``
bit for bit as it was: a speed above which nothing is learned nor forgotten
(``LAW_MAX_COUNTS``, infinite for ``angle-adaptive``), and a model of the gear's torque
whose prediction each tick's learning sees taken out of the strain (``gear``, empty for
``angle-adaptive``). A private module (leading underscore), so method discovery skips it.
"""

from __future__ import annotations

import numpy as np
from numba import types

from rippleb.dsp import (F8, F8_2D_C, F8_C, IN_F8, IN_I8, backward_substitute, cholesky, compiled,
                         forward_substitute)

IN_C16 = types.Array(types.complex128, 1, "A", readonly=True)
I8 = types.int64[:]

#: Positions in the ``law`` array of the online law's constants (see ``AngleAdaptive.reset``).
LAW_R, LAW_GATE, LAW_MEMORY_COUNTS, LAW_FLOOR_INFO, LAW_MIN_COUNTS, LAW_MAX_JOLT, LAW_MAX_COUNTS = range(7)
#: Positions in the ``speed`` state of :func:`stream`'s gear model: the wave generator's
#: speed [rad/s] and acceleration [rad/s^2] as tracked, the last tick's end count, whether
#: there was one (1.0), the tracking filter's gain per tick, and seconds per tick.
SPEED_W, SPEED_A, SPEED_END, SPEED_SEEN, SPEED_GAIN, SPEED_TICK_S = range(6)


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


@compiled(types.void(F8_2D_C, F8, F8, I8, types.int64, IN_F8, IN_F8, IN_F8, F8, F8_2D_C, F8_2D_C,
                     F8, F8))
def learn_period(ticks_phi, ticks_y, ticks_gear, ticks_end, history, law, scale, prior_map, w,
                 chol, info, vec, scalars):
    """Fold one update period of ticks into the information, then re-solve the map.

    Rows ``2..`` of ``ticks_*`` hold the period's ticks (tick-mean regressors ``phi`` in
    the current frame, tick-mean ``y`` [Nm], the gear model's tick-mean torque ``g`` [Nm],
    0 without one, end count), rows 0-1 the two ticks before (copied from the first tick
    when there is no ``history`` yet: zero differences, gate closed). Per tick, second
    differences over three consecutive ticks (``v = y - g``)::

        psi = [d2 phi, y_{j-2} d2 phi, |y_{j-2}| d2 phi],  z = v_j - 2 v_{j-1} + v_{j-2}

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
    and :func:`solve`. A tick either of whose intervals turned by more than
    ``LAW_MAX_COUNTS`` is neither learned from nor counted in the revolutions: at speed
    the map is held as it stands.
    """
    if history == 0:
        ticks_phi[0, :] = ticks_phi[2]
        ticks_phi[1, :] = ticks_phi[2]
        ticks_y[:2] = ticks_y[2]
        ticks_gear[:2] = ticks_gear[2]
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
        z = (ticks_y[j] - ticks_gear[j]) - 2.0 * (ticks_y[j - 1] - ticks_gear[j - 1]) \
            + (ticks_y[j - 2] - ticks_gear[j - 2])
        last = abs(ticks_end[j] - ticks_end[j - 1])
        before = abs(ticks_end[j - 1] - ticks_end[j - 2])
        if max(last, before) > law[LAW_MAX_COUNTS]:
            continue
        moved = min(last, before)
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
    ticks_gear[:2] = ticks_gear[last_two:].copy()
    ticks_end[:2] = ticks_end[last_two:].copy()


@compiled(types.float64(F8, types.float64, types.int64))
def track_speed(speed, end, counts_per_rev):
    """Update the tracked speed and acceleration of ``speed`` (positions ``SPEED_*``) with a
    tick that ended at count ``end``; returns the speed [rad/s].

    The tick's count difference, a speed quantised to one count per tick (2.5 rad/s at 2500
    counts and 1 kHz), is followed by a first-order filter of gain ``SPEED_GAIN`` per tick;
    the acceleration is the filtered speed's change per tick, through the same filter. The
    first tick only sets the count."""
    if speed[SPEED_SEEN] != 0.0:
        tick_s, gain = speed[SPEED_TICK_S], speed[SPEED_GAIN]
        raw = (end - speed[SPEED_END]) * (2.0 * np.pi / counts_per_rev) / tick_s
        tracked = speed[SPEED_W] + gain * (raw - speed[SPEED_W])
        speed[SPEED_A] += gain * ((tracked - speed[SPEED_W]) / tick_s - speed[SPEED_A])
        speed[SPEED_W] = tracked
    speed[SPEED_END] = end
    speed[SPEED_SEEN] = 1.0
    return speed[SPEED_W]


#: Gear-model coefficients per gear order, in :func:`gear_torque`'s order.
GEAR_TERMS = 8


@compiled(types.float64(IN_F8, IN_I8, F8_C, F8, types.float64))
def gear_torque(gear, gear_index, phi, speed, load):
    """The gear model's torque [Nm] over one tick: per gear order ``k`` (at position
    ``gear_index`` of the map's orders, whose tick-mean ``cos k theta``, ``sin k theta``
    are in ``phi``), ``[w cos, w sin, w^2 cos, w^2 sin, a cos, a sin, y w^2 cos,
    y w^2 sin]`` times its :data:`GEAR_TERMS` coefficients in ``gear``; ``w``, ``a`` the
    tracked speed and acceleration (``speed``), ``y`` the tick's ``load`` [Nm]. Zero at
    rest, whatever the coefficients."""
    w, acc = speed[SPEED_W], speed[SPEED_A]
    w2 = w * w
    total = 0.0
    for g in range(len(gear_index)):
        c, sn = phi[2 * gear_index[g]], phi[2 * gear_index[g] + 1]
        k = GEAR_TERMS * g
        total += (w * (gear[k] * c + gear[k + 1] * sn) + w2 * (gear[k + 2] * c + gear[k + 3] * sn)
                  + acc * (gear[k + 4] * c + gear[k + 5] * sn) + load * w2 * (gear[k + 6] * c + gear[k + 7] * sn))
    return total


@compiled(types.void(IN_F8, IN_I8, F8, types.float64, types.float64, types.int64, IN_I8, IN_C16,
                     types.int64, types.int64, types.boolean, IN_F8, IN_F8, IN_F8, F8, F8_2D_C,
                     F8_2D_C, F8, F8, I8, F8, F8_2D_C, F8, I8, IN_F8, IN_I8, F8, F8))
def stream(strain, encoder, out, gain, offset, frame, orders, table, tick, update_ticks, adapt,
           law, scale, prior_map, w, chol, info, vec, scalars, counters, tick_phi, ticks_phi,
           ticks_y, ticks_end, gear, gear_index, speed, ticks_gear):
    """Subtract the current map from every sample; with ``adapt``, learn on the way.

    Per sample: ``out = y - phi(theta) . (c0 + c1 y + c2 |y|)`` with ``y`` the strain in
    Nm and ``theta`` the count relative to ``frame``. With ``adapt`` the sample is also
    added to its control tick (``tick`` samples, counted from the reset, so the output
    does not depend on the block cutting); each complete tick is stored, and after
    ``update_ticks`` ticks :func:`learn_period` re-solves the map, which applies from the
    next sample on. The open tick and period are carried over between calls in
    ``scalars``, ``counters``, ``tick_phi`` and ``ticks_*`` (see ``AngleAdaptive.reset``).
    With a gear model (``gear`` not empty, ``gear_index`` its orders' positions in
    ``orders``), each tick's speed is tracked (:func:`track_speed`, state ``speed``) and
    the model's torque over the tick (:func:`gear_torque`) is stored in ``ticks_gear``,
    which the learning takes out of the strain; the output never subtracts it.
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
        if len(gear):
            track_speed(speed, encoder[s], cpr)
            ticks_gear[row] = gear_torque(gear, gear_index, ticks_phi[row], speed, ticks_y[row])
        strain_sum, in_tick, in_period = 0.0, 0, in_period + 1
        if in_period == update_ticks:
            learn_period(ticks_phi, ticks_y, ticks_gear, ticks_end, counters[2], law, scale,
                         prior_map, w, chol, info, vec, scalars)
            counters[2] = 1
            in_period = 0
    scalars[1], counters[0], counters[1] = strain_sum, in_tick, in_period

"""The compiled streaming loops of ``switched-notch``: the warm bank, the active band's output,
the speed and the band switch, one compiled call per ``step`` (:func:`notch_stream`).

The loops of :class:`~rippleb.methods.switched_notch.SwitchedNotch`
(``methods/switched_notch.py``, whose docstring gives the method), kept beside it. A private
module (leading underscore), so method discovery skips it.

The bank's modes are held in arrays of shape ``(ROWS, columns)``, mode ``m`` at the flat
index ``m`` (row ``m // columns``); the last row is padded with idle modes (all
coefficients zero), which no band reads.
"""

from __future__ import annotations

import math

from numba import types

from rippleb.dsp import F8, F8_C, IN_F8, IN_I8, compiled

OFF = -1  # band index of the pass-through state below the lowest band
#: rows of the bank's mode arrays: the bank's loop advances one mode of each row together,
#: independent recursions the processor overlaps (one row leaves it waiting on each result)
ROWS = 2

#: C-contiguous arrays: contiguity lets the compiler vectorise the mode loop. ``IN_``: read-only
#: (the bank's design), the others written in place (its state and counters).
I8_C = types.int64[::1]
F8_2D_C = types.float64[:, ::1]
IN_I8_C = types.Array(types.int64, 1, "C", readonly=True)
IN_I8_2D_C = types.Array(types.int64, 2, "C", readonly=True)
IN_F8_C = types.Array(types.float64, 1, "C", readonly=True)
IN_F8_2D_C = types.Array(types.float64, 2, "C", readonly=True)
#: streaming counters of :func:`notch_stream`, kept in one int64 array between calls
BAND, PHASE, N_MARKS, OLDEST = range(4)

_PAIR = types.UniTuple(types.float64, 2)


@compiled(types.int64(types.float64, types.int64, IN_F8, types.float64))
def select_band(speed, current, centres, hysteresis):
    """The band for ``speed`` [rev/s] given the ``current`` one, with hysteresis.

    In the coordinate ``p = log(speed / c_0) / log(spacing)`` band ``j`` owns
    ``|p - j| <= 0.5``; the current band is kept while ``|p - j| <= 0.5 + hysteresis``.
    ``OFF`` (pass-through) sits at ``p = -1``.
    """
    spacing = math.log(centres[1] / centres[0]) if len(centres) > 1 else math.log(2.0)
    p = math.log(max(speed, 1e-12) / centres[0]) / spacing
    if abs(p - current) <= 0.5 + hysteresis:
        return current
    if current == len(centres) - 1 and p > current:
        return current
    return min(max(round(p), OFF), len(centres) - 1)


@compiled(types.float64(I8_C, I8_C, types.int64, types.int64, types.float64, types.float64))
def tick_speed(marks, at, count, tick, fs, counts_per_rev):
    """Record ``count`` in the ring ``marks`` of the last tick ends; the speed over it [rev/s]."""
    size = len(marks)
    if at[N_MARKS] < size:
        marks[(at[OLDEST] + at[N_MARKS]) % size] = count
        at[N_MARKS] += 1
    else:
        marks[at[OLDEST]] = count
        at[OLDEST] = (at[OLDEST] + 1) % size
    span = (at[N_MARKS] - 1) * tick / fs
    return abs(count - marks[at[OLDEST]]) / counts_per_rev / span


@compiled(_PAIR(types.float64, types.float64, types.float64, types.float64, types.float64))
def mode_step(x0, x1, decay, turn, u):
    """One sample of one mode: the pole ``p = decay + i turn`` as the real pair ``x0 - i x1``
    of the complex state ``xi' = p xi + u``, that is ``[x0, x1]' = [[decay, turn], [-turn,
    decay]] [x0, x1] + [u, 0]``."""
    return decay * x0 + turn * x1 + u, decay * x1 - turn * x0


@compiled(_PAIR(types.float64, types.float64, types.float64, types.float64, types.float64,
                types.float64, types.float64, types.float64))
def mode_pair_step(x0, x1, decay, turn, decay2, turn2, ua, ub):
    """Two samples ``ua, ub`` of one mode at once, ``xi'' = p^2 xi + p ua + ub`` (``p^2 =
    decay2 + i turn2``): the same filter as two :func:`mode_step` but for rounding."""
    return decay2 * x0 + turn2 * x1 + decay * ua + ub, decay2 * x1 - turn2 * x0 - turn * ua


@compiled(types.void(IN_F8, F8_2D_C, F8_2D_C, IN_F8_2D_C, IN_F8_2D_C, IN_F8_2D_C, IN_F8_2D_C))
def advance_bank(u, x0, x1, decay, turn, decay2, turn2):
    """Every mode of the bank over the samples ``u``, two samples a step, in place.

    The samples are taken in pairs from the first (:func:`mode_pair_step`), the last one
    alone when ``len(u)`` is odd (:func:`mode_step`). The loop over the modes is the inner
    one, which the compiler vectorises; each pass of it takes two pairs, so a mode's state
    stays in registers between them and the bank's arrays are read and written once per
    four samples. Each column holds one mode of each of the ``ROWS`` rows: independent
    recursions the processor overlaps. How the work is ordered changes no operation of
    any mode: the result is that of stepping pair by pair, bit for bit.
    """
    columns = x0.shape[1]
    i = 0
    while i + 4 <= len(u):
        ua, ub, uc, ud = u[i], u[i + 1], u[i + 2], u[i + 3]
        for m in range(columns):
            for r in range(ROWS):
                p, q = mode_pair_step(x0[r, m], x1[r, m], decay[r, m], turn[r, m], decay2[r, m],
                                      turn2[r, m], ua, ub)
                x0[r, m], x1[r, m] = mode_pair_step(p, q, decay[r, m], turn[r, m], decay2[r, m],
                                                    turn2[r, m], uc, ud)
        i += 4
    if i + 2 <= len(u):
        ua, ub = u[i], u[i + 1]
        for m in range(columns):
            for r in range(ROWS):
                x0[r, m], x1[r, m] = mode_pair_step(x0[r, m], x1[r, m], decay[r, m], turn[r, m],
                                                    decay2[r, m], turn2[r, m], ua, ub)
        i += 2
    if i < len(u):
        ua = u[i]
        for m in range(columns):
            for r in range(ROWS):
                x0[r, m], x1[r, m] = mode_step(x0[r, m], x1[r, m], decay[r, m], turn[r, m], ua)


@compiled(types.void(IN_F8, F8, F8_C, F8_C, IN_F8_C, IN_F8_C, IN_I8_C, IN_F8_C, IN_F8_C,
                     types.float64))
def band_output(u, y, x0, x1, decay, turn, modes, c0, c1, d):
    """One band's output over the samples ``u``, into ``y``: ``d u`` plus ``c0 x0 + c1 x1`` of
    each of its ``modes`` (flat indices), stepped sample by sample (:func:`mode_step`) from
    the bank's state, which is left unchanged."""
    for i in range(len(u)):
        y[i] = d * u[i]
    for k in range(len(modes)):
        p, q = x0[modes[k]], x1[modes[k]]
        s, w = decay[modes[k]], turn[modes[k]]
        for i in range(len(u)):
            y[i] += c0[k] * p + c1[k] * q
            p, q = mode_step(p, q, s, w, u[i])


@compiled(types.void(IN_F8, IN_I8, F8, F8_2D_C, F8_2D_C, IN_F8_2D_C, IN_F8_2D_C, IN_F8_2D_C,
                     IN_F8_2D_C, IN_I8_2D_C, IN_F8_2D_C, IN_F8_2D_C, IN_F8, IN_F8, I8_C, I8_C,
                     types.float64, types.int64, types.float64, types.float64))
def notch_stream(u, counts, y, x0, x1, decay, turn, decay2, turn2, band_modes, c0, c1, d, centres,
                 marks, at, hysteresis, tick, fs, counts_per_rev):
    """Filter ``u`` into ``y`` with the active band while the whole bank runs, in place.

    The bank is kept as its distinct notch pole pairs (``notch_modes``), in ``(ROWS,
    columns)`` arrays; band ``j`` reads its modes ``band_modes[j]`` (flat indices) with the
    weights ``c0[j], c1[j]`` and its feed-through ``d[j]``. Up to the end of each control
    tick (``tick`` samples, counted from ``reset``) the active band's output is made from
    its own modes (:func:`band_output`) and the whole bank steps on (:func:`advance_bank`);
    at the end the encoder speed picks the band for the next tick (:func:`select_band`).
    """
    flat0, flat1 = x0.reshape(x0.size), x1.reshape(x1.size)
    flat_decay, flat_turn = decay.reshape(decay.size), turn.reshape(turn.size)
    band = at[BAND]
    i = 0
    while i < len(u):
        end = min(len(u), i + tick - at[PHASE])          # up to the end of this tick
        if band == OFF:
            y[i:end] = u[i:end]
        else:
            band_output(u[i:end], y[i:end], flat0, flat1, flat_decay, flat_turn, band_modes[band],
                        c0[band], c1[band], d[band])
        advance_bank(u[i:end], x0, x1, decay, turn, decay2, turn2)
        at[PHASE] += end - i
        if at[PHASE] == tick:
            at[PHASE] = 0
            speed = tick_speed(marks, at, counts[end - 1], tick, fs, counts_per_rev)
            band = select_band(speed, band, centres, hysteresis)
        i = end
    at[BAND] = band

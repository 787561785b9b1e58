"""The dynamic-response columns: how fast the estimate follows a torque step
(``step_latency_ms``) and up to which frequency it follows a chirp (``bandwidth_hz``).

Both are measured on the scenario's known loads, which :class:`rippleb.scoring.metrics.Truth`
(``truth_info`` below) carries: its ``steps``, ``chirps``, ``fs``, ``eval_mask`` and
``torque_true``. :func:`rippleb.scoring.metrics.score` puts them in each row;
``docs/metrics.md`` repeats the formulas.
"""

from __future__ import annotations

import numpy as np

STEP_MAX_RISE_S = 0.100           # step_latency_ms: a load edge rising within 100 ms is a step
STEP_BASELINE_S = 0.010           # the estimate's level before a step: its mean over 10 ms
STEP_HORIZON_S = 0.200            # a step not half-reached 200 ms after its 50 % time counts 200 ms
BAND_FRACTION = 0.5               # bandwidth_hz: H1 averaged over half-octave bands ...
BAND_STEP = 1.0 / 12.0            # ... centred every 1/12 octave
BAND_MIN_BINS = 4.0               # lowest centre: at least 4 FFT bins of the shortest chirp window
HALF_POWER = 1.0 / np.sqrt(2.0)   # -3 dB


def _half_step(y: np.ndarray, i0: int, end: int, baseline: int, change: float) -> int | None:
    """First sample ``n >= i0`` (before ``end``) where ``y`` has moved by half of ``change``
    from its mean over the ``baseline`` samples before ``i0``; None if it never does."""
    level = np.mean(y[i0 - baseline: i0])
    reached = np.flatnonzero(np.sign(change) * (y[i0:end] - level) >= 0.5 * abs(change))
    return i0 + int(reached[0]) if len(reached) else None


def step_latency_ms(estimate: np.ndarray, truth_info) -> float:
    """Mean time [ms] from each known torque step's 50 % point in the true torque to 50 %
    of it in the estimate.

    The steps are the edges ``(start, rise, change)`` of the scenario's step loads
    (``Truth.steps``) with ``rise <= 100 ms`` whose start lies in ``W``. A signal's level
    before the edge is its mean over the 10 ms before ``start``; it reaches 50 % at the
    first sample ``n >= start`` where it has moved by ``|change| / 2`` in the step's
    direction, searched until 200 ms after the load's own half point ``start + rise / 2``
    or the next edge's start. The truth's 50 % point ``t50`` is that of ``torque_true``
    (the shaft torque lags the load by the joint's own dynamics), or ``start + rise / 2``
    where the true torque is not known or never gets there. The step's latency is the
    estimate's ``n / fs - t50`` (negative if the estimate leads), or 200 ms if it never
    gets there. NaN if there is no such step.
    """
    fs, mask, y = truth_info.fs, truth_info.eval_mask, np.asarray(estimate, float)
    truth = None if truth_info.torque_true is None else np.asarray(truth_info.torque_true, float)
    steps = np.asarray(truth_info.steps, float).reshape(-1, 3)
    starts = np.round(steps[:, 0] * fs).astype(np.int64)
    baseline = max(1, int(round(STEP_BASELINE_S * fs)))
    latencies = []
    for k, (start, rise, change) in enumerate(steps):
        i0 = starts[k]
        if rise > STEP_MAX_RISE_S or change == 0 or i0 < baseline or i0 >= len(y) or not mask[i0]:
            continue
        t50 = start + 0.5 * rise
        end = min(int(round((t50 + STEP_HORIZON_S) * fs)) + 1, len(y),
                  *[s for s in starts[k + 1:] if s > i0])
        true_half = None if truth is None else _half_step(truth, i0, end, baseline, change)
        if true_half is not None:
            t50 = true_half / fs
        reached = _half_step(y, i0, end, baseline, change)
        latencies.append(reached / fs - t50 if reached is not None else STEP_HORIZON_S)
    return 1000.0 * float(np.mean(latencies)) if latencies else float("nan")


def bandwidth_hz(estimate: np.ndarray, truth: np.ndarray | None, truth_info) -> float:
    """The highest frequency [Hz] up to which the estimate's gain over the truth stays
    within -3 dB, measured on the scenario's chirp loads (``Truth.chirps``).

    The H1 estimate of the transfer function truth -> estimate over the chirp windows
    (each ``[start, stop]`` wholly in ``W``): in each window, truth ``x`` and estimate
    ``y`` are detrended (least-squares line), multiplied by a Hann window and Fourier
    transformed (``X``, ``Y``); in a band ``B`` of half an octave around a centre ``f_c``,
    summed over the windows and the FFT bins in ``B``::

        H(f_c) = sum Y conj(X) / sum |X|^2

    (averaging over frequency and windows like Welch's method averages over segments:
    error uncorrelated with the truth, ripple and noise, averages out). The centres step
    down by 1/12 octave from ``f_hi = f1`` to no lower than ``f_lo = max(2^(1/4) f0, 4 / T)``
    (``T`` the shortest window: 4 FFT bins at least; the common range of the chirps). The result is
    the first centre with ``|H| < 1/sqrt(2)``, interpolated linearly in log frequency on
    the gain in dB against the centre before it; ``f_hi`` if the gain never drops that
    low (the bandwidth is at least that), ``f_lo`` if it is low from the start (at most
    that). NaN without a chirp in ``W`` or without a truth.
    """
    fs, mask = truth_info.fs, truth_info.eval_mask
    chirps = np.asarray(truth_info.chirps, float).reshape(-1, 4)
    spans = [(int(round(a * fs)), min(int(round(b * fs)) + 1, len(mask))) for a, b in chirps[:, :2]]
    keep = [k for k, (i0, i1) in enumerate(spans) if i1 - i0 > 8 and mask[i0:i1].all()]
    if truth is None or not keep:
        return float("nan")
    shortest = min(spans[k][1] - spans[k][0] for k in keep) / fs
    f_lo = max(2.0 ** (BAND_FRACTION / 2) * chirps[keep, 2].max(), BAND_MIN_BINS / shortest)
    f_hi = chirps[keep, 3].min()
    if f_lo >= f_hi:
        return float("nan")
    centres = f_hi * 2.0 ** (-BAND_STEP * np.arange(int(np.log2(f_hi / f_lo) / BAND_STEP) + 1)[::-1])
    edges = np.stack([centres * 2.0 ** (-BAND_FRACTION / 2), centres * 2.0 ** (BAND_FRACTION / 2)])
    cross = np.zeros(len(centres), complex)
    power = np.zeros(len(centres))
    for k in keep:
        i0, i1 = spans[k]
        c, p = _band_spectra(np.asarray(estimate[i0:i1], float), np.asarray(truth[i0:i1], float),
                             fs, edges)
        cross += c
        power += p
    with np.errstate(divide="ignore", invalid="ignore"):
        gain = np.abs(cross) / power
    return _first_crossing(centres, gain, HALF_POWER)


def _band_spectra(y: np.ndarray, x: np.ndarray, fs: float, edges: np.ndarray):
    """Band sums of ``Y conj(X)`` and ``|X|^2`` (detrended, Hann-windowed) over ``edges``."""
    from scipy.signal import detrend

    taper = np.hanning(len(x))
    X = np.fft.rfft(detrend(x) * taper)
    Y = np.fft.rfft(detrend(y) * taper)
    freqs = np.fft.rfftfreq(len(x), 1.0 / fs)
    lo, hi = np.searchsorted(freqs, edges[0], "left"), np.searchsorted(freqs, edges[1], "right")
    cross = _cumsum0(Y * np.conj(X))
    power = _cumsum0(np.abs(X) ** 2)
    return cross[hi] - cross[lo], power[hi] - power[lo]


def _first_crossing(centres: np.ndarray, gain: np.ndarray, level: float) -> float:
    """The first frequency where ``gain`` falls below ``level`` (log-f / dB interpolation)."""
    below = np.flatnonzero(~(gain >= level))   # NaN counts as below: no gain measured
    if len(below) == 0:
        return float(centres[-1])
    k = int(below[0])
    if k == 0:
        return float(centres[0])
    g0, g1 = 20 * np.log10(gain[k - 1]), 20 * np.log10(max(gain[k], 1e-300))
    target = 20 * np.log10(level)
    frac = (g0 - target) / (g0 - g1) if g0 != g1 else 0.0
    return float(centres[k - 1] * (centres[k] / centres[k - 1]) ** frac)


def _cumsum0(values: np.ndarray) -> np.ndarray:
    return np.concatenate([[0.0], np.cumsum(values)])

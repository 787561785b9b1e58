"""Scores an engineer can read on their own recording: no ``torque_true``, no ``torque_ref``.

Each function takes the estimate and what the method itself saw (the strain and the
encoder angle) and nothing else, so it is computed the same way on a simulated and on a
recorded log. Lower is better for each. What each cannot tell is in ``docs/metrics.md``
("Scores without ground truth"): each measures one symptom, not the error.

- :func:`ripple_wg_nm`: the ripple left at the wave-generator orders 2, 4 and 8, in the
  angle domain, while the joint turns;
- :func:`rest_std_nm`: the estimate's spread while the encoder stands still;
- :func:`strain_delay_ms`: the estimate's lag behind the strain.
"""

from __future__ import annotations

import numpy as np

from rippleb.scoring.metrics import REST_HOLD_S, Truth, moving_from_encoder

#: The orders of the wave-generator angle the paper notches (its Sec. II; the simulator's
#: dominant ones, rippleb/simulator/gauge.py).
WG_ORDERS = (2, 4, 8)
#: Points per wave-generator revolution of the angle-domain re-sampling: 64 puts the
#: Nyquist order at 32, four times the highest order measured.
POINTS_PER_REV = 64
#: A rest shorter than this is not used: at a reversal or the end of a slow move the encoder
#: can stand still for a few tens of ms while the torque still follows the acceleration.
MIN_REST_S = 0.1
#: Welch segment of :func:`strain_delay_ms`: 2 s resolves 0.5 Hz, below the content of the
#: scenarios' slowest moves (1-2 s each, docs/scenarios.md).
DELAY_SEGMENT_S = 2.0
#: Its band: the torque's, up to 50 Hz, above the methods' bandwidths (docs/metrics.md,
#: "Choosing the lowpass cutoff": 30 Hz); a wider band adds only incoherent bins.
DELAY_MAX_HZ = 50.0
#: Coherence from which a bin counts: 0.9, i.e. 90 % of the estimate's power in that bin is
#: a linear function of the strain's.
DELAY_MIN_COHERENCE = 0.9
#: Fewer coherent bins than this give no slope worth a number.
DELAY_MIN_BINS = 3


def encoder_motion(encoder_angle: np.ndarray, fs: float) -> np.ndarray:
    """Moving where the encoder changed within the last 10 ms (:func:`rippleb.scoring.metrics.moving_from_encoder`)."""
    return moving_from_encoder(encoder_angle, fs)


def ripple_wg_nm(estimate: np.ndarray, encoder_angle: np.ndarray, fs: float) -> float:
    """RMS [Nm] of the estimate's component at wave-generator orders 2, 4 and 8.

    Over each run of motion in one direction, the estimate is re-sampled at
    :data:`POINTS_PER_REV` equally spaced encoder angles per revolution (linear
    interpolation between the samples where the count changes, as order tracking does).
    The torque's own slow change is taken out by subtracting a centred moving average of
    one revolution (the 2 x P average of classical seasonal decomposition: it passes a
    straight line unchanged and holds nothing of any whole order). What is left is cut into
    whole revolutions, and per revolution ``a_k = 2/P sum r cos(k phi)``, ``b_k`` likewise
    with ``sin`` (``phi`` the angle from the revolution's start; whole orders are orthogonal
    over a revolution, so orders 1, 3, 6 ... do not leak in). Returns
    ``sqrt(mean over revolutions of sum_k (a_k^2 + b_k^2) / 2)``; NaN without two whole
    revolutions in one direction (half a revolution at each end feeds the average).
    """
    revolutions = [rev for run in _monotonic_runs(encoder_angle, fs)
                   for rev in _revolutions(estimate, encoder_angle, run)]
    if not revolutions:
        return float("nan")
    coef = _harmonic_basis() @ np.stack(revolutions, axis=1)
    power = np.sum(coef ** 2, axis=0) / 2.0
    return float(np.sqrt(np.mean(power)))


def _harmonic_basis() -> np.ndarray:
    """Rows ``2/P cos(k phi)`` and ``2/P sin(k phi)`` for each order of :data:`WG_ORDERS`."""
    phi = 2.0 * np.pi * np.arange(POINTS_PER_REV) / POINTS_PER_REV
    return np.stack([f(k * phi) for k in WG_ORDERS for f in (np.cos, np.sin)]) * (2.0 / POINTS_PER_REV)


def _monotonic_runs(encoder_angle: np.ndarray, fs: float) -> list[np.ndarray]:
    """Per run of motion in one direction, the indices of the samples where the count changed."""
    edges = np.flatnonzero(np.diff(encoder_angle)) + 1
    if len(edges) < 2:
        return []
    direction = np.sign(encoder_angle[edges] - encoder_angle[edges - 1])
    # A new run where the direction flips, or where the joint rested between two changes
    # (no change for REST_HOLD_S, the rule of rippleb.scoring.metrics.moving_from_encoder).
    rested = np.diff(edges) > max(1, int(round(REST_HOLD_S * fs)))
    breaks = np.flatnonzero(rested | (direction[1:] != direction[:-1])) + 1
    return [run for run in np.split(edges, breaks) if len(run) > 1]


def _revolutions(estimate: np.ndarray, encoder_angle: np.ndarray, run: np.ndarray) -> list[np.ndarray]:
    """The estimate minus its one-revolution moving average, re-sampled on each whole
    revolution of one run."""
    angle = encoder_angle[run]
    sign = 1.0 if angle[-1] > angle[0] else -1.0
    travel = sign * (angle - angle[0])               # increasing from 0
    points = int(np.floor(travel[-1] / (2.0 * np.pi) * POINTS_PER_REV)) + 1
    if points < 2 * POINTS_PER_REV + 1:
        return []
    grid = np.arange(points) * (2.0 * np.pi / POINTS_PER_REV)
    values = np.interp(grid, travel, estimate[run])
    average = np.full(POINTS_PER_REV + 1, 1.0 / POINTS_PER_REV)
    average[[0, -1]] *= 0.5
    half = POINTS_PER_REV // 2
    residual = values[half: points - half] - np.convolve(values, average, mode="valid")
    whole = len(residual) // POINTS_PER_REV
    return list(residual[: whole * POINTS_PER_REV].reshape(whole, POINTS_PER_REV))


def rest_std_nm(estimate: np.ndarray, encoder_angle: np.ndarray, fs: float,
                min_rest_s: float = MIN_REST_S) -> float:
    """Pooled standard deviation [Nm] of the estimate over the rests of the log.

    A rest is a run of samples that are not moving (:func:`encoder_motion`) at least
    ``min_rest_s`` long. Returns ``sqrt(sum_r sum_{n in r} (y[n] - mean_r y)^2 / sum_r |r|)``;
    NaN without such a rest.
    """
    still = ~encoder_motion(encoder_angle, fs)
    bounds = np.flatnonzero(np.diff(np.concatenate(([0], still.astype(np.int8), [0]))))
    squares, count = 0.0, 0
    for start, stop in zip(bounds[::2], bounds[1::2]):
        if stop - start < min_rest_s * fs:
            continue
        part = np.asarray(estimate[start:stop], float)
        squares += float(np.sum((part - part.mean()) ** 2))
        count += stop - start
    return float(np.sqrt(squares / count)) if count else float("nan")


def strain_delay_ms(estimate: np.ndarray, strain: np.ndarray, fs: float, memo: Truth | None = None) -> float:
    """Delay [ms] of the estimate behind the strain, from the phase of their cross-spectrum.

    Welch cross- and auto-spectra (Hann segments of :data:`DELAY_SEGMENT_S`, or a quarter
    of the log if shorter, half overlap, each segment's mean removed: ``scipy.signal.csd``'s
    defaults) give ``Pxy(f)`` and the coherence ``C(f)``; over the bins
    ``0 < f <= DELAY_MAX_HZ`` with ``C >= DELAY_MIN_COHERENCE`` (where strain and estimate
    are one linear relation: the torque's band, not the ripple the estimate removed) the
    phase ``angle(Pxy) = -2 pi f tau`` is fitted through the origin, weighted by ``abs(Pxy)``:
    ``tau = -sum w f angle(Pxy) / (2 pi sum w f^2)``. Positive: the estimate lags; negative
    where it leads (a current-based estimate sees the motor accelerate first). The bridge's
    sign is unknown, so the strain is turned over when it correlates negatively with the
    estimate. NaN with fewer than :data:`DELAY_MIN_BINS` coherent bins.

    ``memo``, the :class:`Truth` that holds ``strain``, keeps the strain's spectra for the
    next estimate of the same log (the same numbers, computed once).
    """
    x, y = np.asarray(strain, float), np.asarray(estimate, float)
    n = int(min(round(DELAY_SEGMENT_S * fs), len(x) // 4))
    if n < 16 or np.ptp(x) == 0 or np.ptp(y) == 0:
        return float("nan")
    key = ("strain-spectra", id(strain), n, fs)
    freq, xs, pxx = (memo.remembered(key, lambda: _segment_spectra(x, n, fs)) if memo is not None
                     else _segment_spectra(x, n, fs))
    _, ys, pyy = _segment_spectra(y, n, fs)
    pxy = np.sum(np.conj(xs) * ys, axis=0)
    if np.dot(x - x.mean(), y - y.mean()) < 0:
        pxy = -pxy                                   # the strain turned over
    with np.errstate(divide="ignore", invalid="ignore"):
        coherence = np.abs(pxy) ** 2 / (pxx * pyy)
    use = (freq > 0) & (coherence >= DELAY_MIN_COHERENCE)
    if use.sum() < DELAY_MIN_BINS:
        return float("nan")
    weight, freq, phase = np.abs(pxy[use]), freq[use], np.angle(pxy[use])
    tau_ms = -1000.0 * np.sum(weight * freq * phase) / (2.0 * np.pi * np.sum(weight * freq * freq))
    return round(float(tau_ms), 9) + 0.0  # to the ns: a strain copy is 0, not -3e-17 (and not -0)


def _segment_spectra(values: np.ndarray, n: int, fs: float):
    """Frequencies up to :data:`DELAY_MAX_HZ`, the Hann-windowed spectrum of each half-overlapping
    segment of ``n`` samples (mean removed) there, and their summed power (unscaled: only
    ratios and phases are used)."""
    window = np.hanning(n + 1)[:n]                   # periodic Hann, scipy's get_window("hann", n)
    step = n - n // 2
    freq = np.fft.rfftfreq(n, 1.0 / fs)
    keep = freq <= DELAY_MAX_HZ
    spectra = []
    for start in range(0, len(values) - n + 1, step):
        segment = values[start: start + n]
        spectra.append(np.fft.rfft((segment - segment.mean()) * window)[keep])
    spectra = np.array(spectra)
    return freq[keep], spectra, np.sum(np.abs(spectra) ** 2, axis=0)


def truth_free_scores(estimate: np.ndarray, truth: Truth) -> dict[str, float]:
    """The truth-free columns of a row, over the span of the evaluation window.

    Of ``truth`` only what the method saw is read (``strain``, ``encoder_angle``), and the
    window; NaN everywhere when the case does not carry them.
    """
    if truth.strain is None or truth.encoder_angle is None or not truth.eval_mask.any():
        return {name: float("nan") for name in TRUTH_FREE_COLUMNS}
    idx = np.flatnonzero(truth.eval_mask)
    span = slice(int(idx[0]), int(idx[-1]) + 1)
    y, angle = np.asarray(estimate, float)[span], truth.encoder_angle[span]
    return {"ripple_wg_nm": ripple_wg_nm(y, angle, truth.fs),
            "rest_std_nm": rest_std_nm(y, angle, truth.fs),
            "strain_delay_ms": strain_delay_ms(y, truth.strain[span], truth.fs, memo=truth)}


TRUTH_FREE_COLUMNS = ("ripple_wg_nm", "rest_std_nm", "strain_delay_ms")

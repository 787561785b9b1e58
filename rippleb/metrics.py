"""Every result column, with its formula.

Notation: ``e[n] = y[n] - tau[n]`` is the estimate ``y`` minus the truth ``tau``
(``torque_true`` or ``torque_ref``), ``W`` the samples of the evaluation window, ``|W|``
their count. Each metric is NaN where it is undefined (no truth column, no restart, no
rest in the window). ``docs/metrics.md`` repeats these formulas.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from rippleb.dsp import encoder_angle

MAX_DELAY_S = 0.100
RESTART_ANGLE_RAD = 4.0 * np.pi   # two wave-generator revolutions
REST_HOLD_S = 0.010               # recorded logs: no encoder count for 10 ms is "at rest"


@dataclass(frozen=True)
class Truth:
    """What the metrics compare an estimate with; the runner builds it, methods never see it.

    ``torque_true`` and ``torque_ref`` may be None (a recorded log has no ``torque_true``).
    ``moving``, ``wave_angle`` [rad] and ``eval_mask`` are per sample; ``fs`` in Hz.
    """

    fs: float
    eval_mask: np.ndarray
    moving: np.ndarray
    wave_angle: np.ndarray
    torque_true: np.ndarray | None = None
    torque_ref: np.ndarray | None = None

    @classmethod
    def from_simulation(cls, sim) -> "Truth":
        """From a simulator ``Simulation`` (its ``log``, ``moving``, ``wave_angle``, ``eval_mask``)."""
        log = sim.log
        return cls(fs=log.spec.fs, eval_mask=np.asarray(sim.eval_mask, bool),
                   moving=np.asarray(sim.moving, bool), wave_angle=np.asarray(sim.wave_angle, float),
                   torque_true=log.torque_true, torque_ref=log.torque_ref)

    @classmethod
    def from_recording(cls, log) -> "Truth":
        """From a recorded log: motion and angle derived from the encoder.

        ``wave_angle = 2 pi encoder / counts_per_rev`` (the encoder sits on the motor, i.e.
        the wave generator). A sample is *moving* when the encoder count changed within
        the last ``REST_HOLD_S`` = 10 ms, inclusive: at the paper's 2500 counts/rev this
        treats motor speeds below 2.4 rpm as rest. The whole log is the evaluation window.
        """
        return cls(fs=log.spec.fs, eval_mask=np.ones(len(log), bool),
                   moving=moving_from_encoder(log.encoder, log.spec.fs),
                   wave_angle=encoder_angle(log.encoder, log.spec.counts_per_rev),
                   torque_true=log.torque_true, torque_ref=log.torque_ref)


def moving_from_encoder(encoder: np.ndarray, fs: float, hold_s: float = REST_HOLD_S) -> np.ndarray:
    """True where the encoder count changed within the last ``hold_s`` seconds."""
    encoder = np.asarray(encoder)
    changed = np.zeros(len(encoder), bool)
    changed[1:] = encoder[1:] != encoder[:-1]
    hold = max(1, int(round(hold_s * fs)))
    # index of the latest change at or before each sample; "long ago" before the first
    idx = np.where(changed, np.arange(len(encoder)), -hold - 1)
    last = np.maximum.accumulate(idx)
    return (np.arange(len(encoder)) - last) < hold


def rms_error(estimate: np.ndarray, truth: np.ndarray | None, mask: np.ndarray) -> float:
    """``sqrt( sum_{n in W} e[n]^2 / |W| )`` [Nm]."""
    if truth is None or not mask.any():
        return float("nan")
    err = estimate[mask] - truth[mask]
    return float(np.sqrt(np.mean(err * err)))


def max_error(estimate: np.ndarray, truth: np.ndarray | None, mask: np.ndarray) -> float:
    """``max_{n in W} |e[n]|`` [Nm]."""
    if truth is None or not mask.any():
        return float("nan")
    return float(np.max(np.abs(estimate[mask] - truth[mask])))


def delay_ms(estimate: np.ndarray, truth: np.ndarray | None, mask: np.ndarray, fs: float,
             max_delay_s: float = MAX_DELAY_S) -> float:
    """The lag ``L`` in [0, 100] ms maximising the cross-correlation of estimate and truth.

    Over the samples from the first to the last index of ``W`` (``N`` of them), for each
    lag ``L = 0 .. round(0.1 fs)`` the estimate shifted back by ``L`` samples,
    ``z_L = y[L:N]``, is compared with ``x_L = tau[0:N-L]`` by the Pearson correlation::

        r[L] = sum_n (z_L[n] - mean z_L)(x_L[n] - mean x_L) / ((N - L) std z_L std x_L)

    i.e. the mean-removed cross-correlation normalised on the overlap, so that neither
    the shrinking overlap nor a trend in the signal favours a lag. Returns
    ``1000 argmax_L r[L] / fs`` [ms] (the estimate lags the truth by ``L``); NaN if the
    truth or the estimate is constant over the window.
    """
    if truth is None or not mask.any():
        return float("nan")
    idx = np.flatnonzero(mask)
    x = np.asarray(truth[idx[0]: idx[-1] + 1], float)
    z = np.asarray(estimate[idx[0]: idx[-1] + 1], float)
    x = x - x.mean()
    z = z - z.mean()
    n = len(x)
    max_lag = min(int(round(max_delay_s * fs)), n - 2)
    if max_lag < 0 or not np.any(x) or not np.any(z):
        return float("nan")
    lags = np.arange(max_lag + 1)
    count = n - lags
    size = 1 << int(np.ceil(np.log2(2 * n)))
    cross = np.fft.irfft(np.fft.rfft(z, size) * np.conj(np.fft.rfft(x, size)), size)[: max_lag + 1]
    # Sums over the overlaps from cumulative sums: x over [0, n-L), z over [L, n).
    cx, cxx = _cumsum0(x), _cumsum0(x * x)
    cz, czz = _cumsum0(z), _cumsum0(z * z)
    sx, sxx = cx[n - lags], cxx[n - lags]
    sz, szz = cz[n] - cz[lags], czz[n] - czz[lags]
    cov = cross - sx * sz / count
    var = np.maximum(sxx - sx * sx / count, 0.0) * np.maximum(szz - sz * sz / count, 0.0)
    with np.errstate(divide="ignore", invalid="ignore"):
        r = np.where(var > 0, cov / np.sqrt(var), -np.inf)
    return float(1000.0 * np.argmax(r) / fs)


def _cumsum0(values: np.ndarray) -> np.ndarray:
    return np.concatenate([[0.0], np.cumsum(values)])


def restart_max_error(estimate: np.ndarray, truth: np.ndarray | None, truth_info: Truth) -> float:
    """Max ``|e[n]|`` from each restart until the wave generator has turned two revolutions.

    A restart is a sample ``i`` in ``W`` with ``moving[i-1]`` False and ``moving[i]`` True.
    Its segment runs from ``i`` while the travelled wave-generator angle
    ``sum_{j=i+1..n} |theta[j] - theta[j-1]|`` is below 4 pi rad (so a reversal still
    counts as travel), or to the end of the log. The metric is the maximum over all
    segments; NaN if the window has no restart.
    """
    moving, mask = truth_info.moving, truth_info.eval_mask
    if truth is None:
        return float("nan")
    starts = np.flatnonzero(moving[1:] & ~moving[:-1]) + 1
    starts = starts[mask[starts]]
    if len(starts) == 0:
        return float("nan")
    travel = np.concatenate([[0.0], np.cumsum(np.abs(np.diff(truth_info.wave_angle)))])
    worst = 0.0
    for i in starts:
        stop = np.searchsorted(travel, travel[i] + RESTART_ANGLE_RAD, side="left")
        worst = max(worst, float(np.max(np.abs(estimate[i:stop + 1] - truth[i:stop + 1]))))
    return worst


def tick_stats(ticks_ns: np.ndarray, n_samples: int) -> dict[str, float]:
    """``us_per_tick_p50``, ``us_per_tick_p99``: percentiles of the ``step`` times [us];
    ``samples_per_s = n_samples / sum(step times)``.
    """
    if len(ticks_ns) == 0:
        return {"us_per_tick_p50": float("nan"), "us_per_tick_p99": float("nan"),
                "samples_per_s": float("nan")}
    us = ticks_ns / 1000.0
    total_s = float(np.sum(ticks_ns)) / 1e9
    return {"us_per_tick_p50": float(np.percentile(us, 50)),
            "us_per_tick_p99": float(np.percentile(us, 99)),
            "samples_per_s": n_samples / total_s if total_s > 0 else float("inf")}


def score(estimate: np.ndarray, truth: Truth) -> dict[str, float]:
    """All accuracy columns of one result row (the timing columns come from :func:`tick_stats`).

    ``delay_ms`` is against ``torque_true``, or against ``torque_ref`` when there is no
    ``torque_true`` (recorded logs); likewise ``restart_max_error_nm`` and
    ``stopped_rms_error_nm``.
    """
    mask = truth.eval_mask
    best = truth.torque_true if truth.torque_true is not None else truth.torque_ref
    rest = mask & ~truth.moving
    return {
        "rms_error_nm": rms_error(estimate, truth.torque_true, mask),
        "max_error_nm": max_error(estimate, truth.torque_true, mask),
        "rms_error_ref_nm": rms_error(estimate, truth.torque_ref, mask),
        "max_error_ref_nm": max_error(estimate, truth.torque_ref, mask),
        "delay_ms": delay_ms(estimate, best, mask, truth.fs),
        "restart_max_error_nm": restart_max_error(estimate, best, truth),
        "stopped_rms_error_nm": rms_error(estimate, best, rest),
    }


METRIC_COLUMNS = ("rms_error_nm", "max_error_nm", "rms_error_ref_nm", "max_error_ref_nm",
                  "delay_ms", "restart_max_error_nm", "stopped_rms_error_nm",
                  "us_per_tick_p50", "us_per_tick_p99", "samples_per_s")

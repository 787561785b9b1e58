"""Every result column, with its formula.

Notation: ``e[n] = y[n] - tau[n]`` is the estimate ``y`` minus the truth ``tau``
(``torque_true`` or ``torque_ref``), ``W`` the samples of the evaluation window, ``|W|``
their count. Each metric is NaN where it is undefined (no truth column, no restart, no
rest in the window, no distinct correlation peak, no torque step or chirp in the
scenario). ``docs/metrics.md`` repeats these formulas. The two columns of the dynamic
response, ``step_latency_ms`` and ``bandwidth_hz``, are computed in :mod:`rippleb.scoring.response`.
"""

from __future__ import annotations

import dataclasses
import weakref
from dataclasses import dataclass, field

import numpy as np
from scipy.fft import next_fast_len

from rippleb.data import MAX_TORQUE_FACTOR
from rippleb.scoring.response import (BAND_FRACTION, BAND_MIN_BINS, BAND_STEP, HALF_POWER,  # noqa: F401 - re-exported
                                      STEP_BASELINE_S, STEP_HORIZON_S, STEP_MAX_RISE_S, bandwidth_hz, step_latency_ms)

MAX_DELAY_S = 0.100
RESTART_ANGLE_RAD = 4.0 * np.pi   # two wave-generator revolutions
REST_HOLD_S = 0.010               # recorded logs: no encoder count for 10 ms is "at rest"
DELAY_PEAK_FACTOR = 2.0           # delay_ms: lags whose misfit 1 - r is within 2x the best ...
DELAY_PEAK_WIDTH_S = 0.025        # ... must all lie within 25 ms of it, else the peak is not distinct
#: gear_removed_fraction is NaN where the gear's torque is below this RMS [Nm]: the ripple a
#: method removes at orders 1 and 2 (0.1-1 Nm) projects onto g by its ratio to g, and on
#: creep and static-contact (g 0.009-0.044 Nm RMS on devices 2000-2009) moved the share
#: of the angle-map methods by up to +-5; the moving scenarios carry 0.22-0.84 Nm.
GEAR_TORQUE_FLOOR_NM = 0.1

_MEMO: dict[int, dict] = {}       # id of a live Truth -> what Truth.remembered computed for it


@dataclass(frozen=True)
class Truth:
    """What the metrics compare an estimate with; the runner builds it, methods never see it.

    ``torque_true`` and ``torque_ref`` may be None (a recorded log has no ``torque_true``);
    ``torque_gear`` is the part of ``torque_true`` the gear's transmission error adds
    (:mod:`rippleb.simulator.transmission`; None for a recording).
    ``moving``, ``wave_angle`` [rad] and ``eval_mask`` are per sample; ``fs`` in Hz.
    The scenario's known events (empty when it has none, or for a recording):
    ``steps`` rows ``(start, rise, change)`` [s, s, Nm] of the step loads' edges,
    ``chirps`` rows ``(start, stop, f0, f1)`` [s, s, Hz, Hz] of the chirp loads.
    ``torque_limit`` [Nm], recorded logs only: the largest torque the joint can carry; a row
    whose estimate goes beyond it is not scored (:mod:`rippleb.scoring.scorable`).
    What the method itself saw, for the truth-free columns (:mod:`rippleb.scoring.truthfree`):
    ``strain`` [V] and ``encoder_angle`` [rad], the wave-generator angle from the encoder
    counts (on a simulated log ``wave_angle`` is the true angle, not the encoder's); None
    on a truth built without them.
    ``reference_kind``, recorded logs with a ``torque_ref`` only: what it is (``transducer`` or
    ``model``, :data:`rippleb.joint_file.REFERENCE_KINDS`), which decides how a row is scored
    against it (:mod:`rippleb.scoring.rebuilt`); None for a simulated log, whose ``torque_true`` is known.
    All fields but ``fs``, ``torque_limit`` and the torques are arrays, so a case file stores
    them as such (:data:`TRUTH_ARRAYS`).
    """

    fs: float
    eval_mask: np.ndarray
    moving: np.ndarray
    wave_angle: np.ndarray
    torque_true: np.ndarray | None = None
    torque_ref: np.ndarray | None = None
    torque_gear: np.ndarray | None = None
    steps: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    chirps: np.ndarray = field(default_factory=lambda: np.zeros((0, 4)))
    torque_limit: float | None = None
    strain: np.ndarray | None = None
    encoder_angle: np.ndarray | None = None
    reference_kind: str | None = None

    def remembered(self, key, compute):
        """``compute()``, computed once per ``key`` while this truth lives.

        For what the metrics compute from the truth alone (its spectrum, running sums):
        the rows of a case are scored against one ``Truth``, so each estimate pays only
        for its own side. Kept beside the instance, not in it, so its fields stay its data.
        """
        memo = _MEMO.get(id(self))
        if memo is None:
            memo = _MEMO[id(self)] = {}
            weakref.finalize(self, _MEMO.pop, id(self), None)
        if key not in memo:
            memo[key] = compute()
        return memo[key]

    @classmethod
    def from_simulation(cls, sim) -> "Truth":
        """From a simulator ``Simulation`` (its ``log``, ``moving``, ``wave_angle``, ``eval_mask``,
        and the step edges and chirps of its ``scenario``)."""
        from rippleb.dsp import encoder_angle  # see from_recording

        log = sim.log
        truth = cls(fs=log.spec.fs, eval_mask=np.asarray(sim.eval_mask, bool),
                    moving=np.asarray(sim.moving, bool), wave_angle=np.asarray(sim.wave_angle, float),
                    torque_true=log.torque_true, torque_ref=log.torque_ref,
                    torque_gear=getattr(sim, "torque_gear", None), strain=log.strain,
                    encoder_angle=encoder_angle(log.encoder, log.spec.counts_per_rev))
        sc = getattr(sim, "scenario", None)   # a stand-in simulation may have none: no events
        if sc is None:
            return truth
        return dataclasses.replace(truth, steps=sc.step_edges(),
                                   chirps=np.hstack([sc.chirp_windows(), sc.chirp_bands()]))

    @classmethod
    def from_recording(cls, log) -> "Truth":
        """From a recorded log: motion and angle derived from the encoder.

        ``wave_angle = 2 pi encoder / counts_per_rev`` (the encoder sits on the motor, i.e.
        the wave generator). A sample is *moving* when the encoder count changed within
        the last ``REST_HOLD_S`` = 10 ms, inclusive: at the paper's 2500 counts/rev this
        treats motor speeds below 2.4 rpm as rest. The whole log is the evaluation window.
        ``torque_limit`` is :data:`~rippleb.data.MAX_TORQUE_FACTOR` times the rated torque;
        ``reference_kind`` the log's ``meta["reference_kind"]`` (``model`` if it does not say).
        """
        # imported here: rippleb.dsp compiles the methods' numba kernels at import, which
        # the runner, and with it every CLI command, would otherwise pay for at start-up
        from rippleb.dsp import encoder_angle

        angle = encoder_angle(log.encoder, log.spec.counts_per_rev)
        return cls(fs=log.spec.fs, eval_mask=np.ones(len(log), bool),
                   moving=moving_from_encoder(log.encoder, log.spec.fs), wave_angle=angle,
                   torque_true=log.torque_true, torque_ref=log.torque_ref, strain=log.strain,
                   encoder_angle=angle, torque_limit=MAX_TORQUE_FACTOR * log.spec.rated_torque,
                   reference_kind=None if log.torque_ref is None else log.meta.get("reference_kind", "model"))


#: The array fields of :class:`Truth` besides the torques: what a case file must store.
TRUTH_ARRAYS = ("moving", "wave_angle", "eval_mask", "steps", "chirps", "strain", "encoder_angle")


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


def gear_removed(estimate: np.ndarray, strain: np.ndarray | None, gear: np.ndarray | None,
                 mask: np.ndarray, memo: "Truth | None" = None) -> float:
    """The share of the gear's real torque ``g`` (``torque_gear``) the method took out of the
    strain it read: ``-sum_W r g / sum_W g^2``, with ``r = y - (a s + b)`` the part of the
    estimate ``y`` that no gain ``a`` and offset ``b`` of the strain ``s`` explain (least
    squares over ``W``).

    0: the estimate passes on what the strain carries of ``g`` (``raw``, a gain and an
    offset of the strain, scores exactly 0, up to rounding); 1: it took out as much as the
    gear puts in. What the strain itself lacks of ``g`` (the gauges' hysteresis absorbs
    small oscillations) is not the method's doing and is not counted. It may leave [0, 1]:
    ripple a method removes at orders 1 and 2 is locked to the angle ``g`` is locked to,
    so it projects onto ``g`` with the sign of the device's ripple phase (docs/metrics.md,
    "What a method erased", measures both). NaN where the gear torque is below
    :data:`GEAR_TORQUE_FLOOR_NM` RMS (an ideal gear, a joint that barely turns, a
    recording) or without the strain. ``memo``, the :class:`Truth` that holds ``strain``,
    ``gear`` and ``mask``, keeps their side for the next estimate.
    """
    if strain is None or gear is None or not mask.any():
        return float("nan")
    side = (memo.remembered("gear_removed", lambda: _strain_side(strain, gear, mask)) if memo is not None
            else _strain_side(strain, gear, mask))
    if side is None:
        return float("nan")
    q, g, power = side
    y = np.asarray(estimate[mask], float)
    residual = y - q @ (q.T @ y)
    return float(-np.dot(residual, g) / power)


def _strain_side(strain, gear, mask):
    """What :func:`gear_removed` needs of the truth alone: an orthonormal basis of the
    strain's columns ``[s, 1]`` over ``W`` (the projection ``a s + b`` of any estimate is
    ``q q' y``), ``g`` there and its power; None when ``g`` is below the floor."""
    g = np.asarray(gear[mask], float)
    power = float(np.dot(g, g))
    if not power > GEAR_TORQUE_FLOOR_NM ** 2 * len(g):
        return None
    s = np.asarray(strain[mask], float)
    return np.linalg.qr(np.column_stack([s, np.ones(len(s))]))[0], g, power


def max_error(estimate: np.ndarray, truth: np.ndarray | None, mask: np.ndarray) -> float:
    """``max_{n in W} |e[n]|`` [Nm]."""
    if truth is None or not mask.any():
        return float("nan")
    return float(np.max(np.abs(estimate[mask] - truth[mask])))


def delay_ms(estimate: np.ndarray, truth: np.ndarray | None, mask: np.ndarray, fs: float,
             max_delay_s: float = MAX_DELAY_S, memo: Truth | None = None) -> float:
    """The lag ``L`` in [0, 100] ms maximising the cross-correlation of estimate and truth.

    Over the samples from the first to the last index of ``W`` (``N`` of them), for each
    lag ``L = 0 .. round(0.1 fs)`` the estimate shifted back by ``L`` samples,
    ``z_L = y[L:N]``, is compared with ``x_L = tau[0:N-L]`` by the Pearson correlation::

        r[L] = sum_n (z_L[n] - mean z_L)(x_L[n] - mean x_L) / ((N - L) std z_L std x_L)

    i.e. the mean-removed cross-correlation normalised on the overlap, so that neither
    the shrinking overlap nor a trend in the signal favours a lag. Returns
    ``1000 L* / fs`` [ms] with ``L* = argmax_L r[L]`` (the estimate lags the truth by
    ``L*``).

    NaN if the truth or the estimate is constant over the window, or if the peak is not
    distinct: with the misfit ``m[L] = 1 - r[L]``, every lag with
    ``m[L] <= 2 m[L*]`` must lie within 25 ms (a quarter of the searched range) of
    ``L*``. Doubling the misfit means the shift has added as much error as the estimate
    already has; on a torque that varies slowly against that error (ripple, noise) it
    takes a shift of tens of milliseconds, and ``L*`` is set by the error, not by a delay.

    ``memo``, the :class:`Truth` that holds ``truth`` and ``mask``, keeps what depends on
    them alone for the next estimate (the same numbers, computed once).
    """
    r = _lag_correlation(estimate, truth, mask, fs, max_delay_s, memo)
    if r is None:
        return float("nan")
    best = int(np.argmax(r))
    misfit = 1.0 - r
    close = np.flatnonzero(misfit <= DELAY_PEAK_FACTOR * max(misfit[best], 0.0) + 1e-12)
    if np.max(np.abs(close - best)) > DELAY_PEAK_WIDTH_S * fs:
        return float("nan")
    return float(1000.0 * best / fs)


def _lag_correlation(estimate, truth, mask, fs, max_delay_s, memo=None) -> np.ndarray | None:
    """``r[L]`` of :func:`delay_ms` for ``L = 0 .. max lag`` (``-inf`` where undefined);
    None if it is undefined for every lag."""
    if truth is None or not mask.any():
        return None
    key = ("lag", id(truth), id(mask), fs, max_delay_s)
    side = (memo.remembered(key, lambda: _truth_side(truth, mask, fs, max_delay_s)) if memo is not None
            else _truth_side(truth, mask, fs, max_delay_s))
    if side is None:
        return None
    first, n, max_lag, size, x_spectrum_conj, sx, sxx = side
    z = np.asarray(estimate[first: first + n], float)
    z = z - z.mean()
    if not np.any(z):
        return None
    lags = np.arange(max_lag + 1)
    count = n - lags
    cross = np.fft.irfft(np.fft.rfft(z, size) * x_spectrum_conj, size)[: max_lag + 1]
    # Sums over the overlaps from cumulative sums: x over [0, n-L), z over [L, n).
    cz, czz = _cumsum0(z), _cumsum0(z * z)
    sz, szz = cz[n] - cz[lags], czz[n] - czz[lags]
    cov = cross - sx * sz / count
    var = np.maximum(sxx - sx * sx / count, 0.0) * np.maximum(szz - sz * sz / count, 0.0)
    with np.errstate(divide="ignore", invalid="ignore"):
        r = np.where(var > 0, cov / np.sqrt(var), -np.inf)
    return None if not np.isfinite(r).any() else r


def _truth_side(truth, mask, fs, max_delay_s):
    """What :func:`_lag_correlation` needs of the truth alone: the window's first index and
    length, the largest lag, the FFT size, the conjugate spectrum of the mean-removed truth
    and its overlap sums per lag; None if the correlation is undefined whatever the estimate."""
    idx = np.flatnonzero(mask)
    first = int(idx[0])
    x = np.asarray(truth[first: idx[-1] + 1], float)
    x = x - x.mean()
    n = len(x)
    max_lag = min(int(round(max_delay_s * fs)), n - 2)
    if max_lag < 0 or not np.any(x):
        return None
    lags = np.arange(max_lag + 1)
    # A circular correlation of length >= n + max_lag wraps the negative lags past max_lag,
    # so lags 0..max_lag are exact; a 5-smooth length costs a fifth of the next power of two
    # above 2 n (3 ms against 16 ms for three transforms of 95 000 samples).
    size = next_fast_len(n + max_lag, real=True)
    cx, cxx = _cumsum0(x), _cumsum0(x * x)
    return first, n, max_lag, size, np.conj(np.fft.rfft(x, size)), cx[n - lags], cxx[n - lags]


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
    travel = truth_info.remembered("travel", lambda: np.concatenate(
        [[0.0], np.cumsum(np.abs(np.diff(truth_info.wave_angle)))]))
    worst = 0.0
    for i in starts:
        stop = np.searchsorted(travel, travel[i] + RESTART_ANGLE_RAD, side="left")
        worst = max(worst, float(np.max(np.abs(estimate[i:stop + 1] - truth[i:stop + 1]))))
    return worst


def tick_stats(ticks_ns: np.ndarray, n_samples: int, method_s: float | None = None) -> dict[str, float]:
    """``us_per_tick_p50``, ``us_per_tick_p99``: percentiles of the ``step`` times [us];
    ``samples_per_s``: ``n_samples`` over the method's time on the row as measured outside
    its process (``method_s``: loading its fitted state, ``reset``, every ``step``, handing
    back the estimate; :mod:`rippleb.engine.process.keeper`), or, in a process of one's own
    (tests, tools), over the sum of the step times.
    """
    if len(ticks_ns) == 0:
        return {"us_per_tick_p50": float("nan"), "us_per_tick_p99": float("nan"),
                "samples_per_s": float("nan")}
    us = ticks_ns / 1000.0
    total_s = float(np.sum(ticks_ns)) / 1e9 if method_s is None else method_s
    return {"us_per_tick_p50": float(np.percentile(us, 50)),
            "us_per_tick_p99": float(np.percentile(us, 99)),
            "samples_per_s": n_samples / total_s if total_s > 0 else float("inf")}


def score(estimate: np.ndarray, truth: Truth) -> dict[str, float]:
    """All accuracy columns of one result row (the timing columns come from :func:`tick_stats`).

    ``delay_ms`` is against ``torque_true``, or against ``torque_ref`` when there is no
    ``torque_true`` (recorded logs); likewise ``bandwidth_hz``, ``restart_max_error_nm``
    and ``stopped_rms_error_nm``.
    """
    mask = truth.eval_mask
    best = truth.torque_true if truth.torque_true is not None else truth.torque_ref
    rest = mask & ~truth.moving
    return {
        "rms_error_nm": rms_error(estimate, truth.torque_true, mask),
        "max_error_nm": max_error(estimate, truth.torque_true, mask),
        "rms_error_ref_nm": rms_error(estimate, truth.torque_ref, mask),
        "max_error_ref_nm": max_error(estimate, truth.torque_ref, mask),
        "delay_ms": delay_ms(estimate, best, mask, truth.fs, memo=truth),
        "bandwidth_hz": bandwidth_hz(estimate, best, truth),
        "step_latency_ms": step_latency_ms(estimate, truth),
        "restart_max_error_nm": restart_max_error(estimate, best, truth),
        "stopped_rms_error_nm": rms_error(estimate, best, rest),
        # the same for every method of a case: computed once per truth
        "gear_torque_rms_nm": truth.remembered(
            "gear_rms", lambda: rms_error(np.zeros(len(mask)), truth.torque_gear, mask)),
        "gear_removed_fraction": gear_removed(estimate, truth.strain, truth.torque_gear, mask, memo=truth),
        "rms_error_without_gear_nm": rms_error(estimate, _without_gear(truth), mask),
        # the paper's Table I: "during the motion" (the commanded velocity is not zero)
        "rms_error_ref_motion_nm": rms_error(estimate, truth.torque_ref, mask & truth.moving),
        "max_error_ref_motion_nm": max_error(estimate, truth.torque_ref, mask & truth.moving),
    }


def _without_gear(truth: Truth) -> np.ndarray | None:
    """``torque_true - torque_gear``: the torque of the same joint with an ideal gear."""
    if truth.torque_true is None or truth.torque_gear is None:
        return None
    return truth.remembered("without_gear", lambda: truth.torque_true - truth.torque_gear)


METRIC_COLUMNS = ("rms_error_nm", "max_error_nm", "rms_error_ref_nm", "max_error_ref_nm",
                  "delay_ms", "bandwidth_hz", "step_latency_ms", "restart_max_error_nm",
                  "stopped_rms_error_nm", "gear_torque_rms_nm", "gear_removed_fraction",
                  "rms_error_without_gear_nm", "rms_error_ref_motion_nm", "max_error_ref_motion_nm",
                  "us_per_tick_p50", "us_per_tick_p99", "samples_per_s")
#: Columns that came later than the file format: a results file without them still reads
#: (as n/a). ``gear_removed_fraction`` replaced ``gear_erased_fraction`` (issue 38), which an
#: older file holds instead and which is read as an extra column.
LATER_COLUMNS = ("gear_removed_fraction", "rms_error_ref_motion_nm", "max_error_ref_motion_nm")

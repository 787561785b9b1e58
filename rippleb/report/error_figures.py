"""Figures of what each method leaves behind: error against joint speed over every device,
residual error spectra over order and frequency, the zoom on a restart, and accuracy
against per-tick cost from the rows."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from rippleb.report.plotting import ScenarioSignals, _amplitude, _pyplot, _save, plot_text, style

def speed_edges(signals, n_bins: int = 12) -> np.ndarray:
    """Equal-width bin edges of ``|joint speed|`` from 0 to its maximum while moving,
    inside the evaluation windows of ``signals``."""
    speed = np.concatenate([np.abs(s.sim.joint_velocity) for s in signals])
    inside = np.concatenate([np.asarray(s.sim.eval_mask, bool) for s in signals])
    moving = np.concatenate([np.asarray(s.sim.moving, bool) for s in signals])
    top = speed[inside & moving].max() if (inside & moving).any() else 1.0
    return np.linspace(0.0, top, n_bins + 1)


def error_by_speed(signals, n_bins: int = 12, edges=None) -> dict:
    """RMS error against ``torque_true`` per bin of joint speed, pooled over scenarios.

    Samples inside each scenario's evaluation window; bin 0 holds the samples at rest
    (commanded speed zero), the others equal widths of ``|joint speed|`` up to its maximum
    (or the given ``edges``, so that several devices share the bins).
    Returns ``{"speed": bin centres [rad/s], method: RMS per bin [Nm] (NaN if empty)}``.
    """
    speeds, mask_all = [], []
    for sig in signals:
        speeds.append(np.abs(sig.sim.joint_velocity))
        mask_all.append(np.asarray(sig.sim.eval_mask, bool))
    speed = np.concatenate(speeds)
    inside = np.concatenate(mask_all)
    moving = np.concatenate([np.asarray(s.sim.moving, bool) for s in signals])
    edges = speed_edges(signals, n_bins) if edges is None else np.asarray(edges, float)
    n_bins = len(edges) - 1
    which = np.where(moving, np.clip(np.digitize(speed, edges[1:-1]) + 1, 1, n_bins), 0)
    out = {"speed": np.concatenate([[0.0], 0.5 * (edges[:-1] + edges[1:])])}
    methods = set.intersection(*(set(s.estimates) for s in signals)) if signals else set()
    for name in methods:
        err = np.concatenate([s.estimates[name] - s.sim.log.torque_true for s in signals])
        rms = np.full(n_bins + 1, np.nan)
        for b in range(n_bins + 1):
            sel = inside & (which == b)
            if sel.any():
                rms[b] = np.sqrt(np.mean(err[sel] ** 2))
        out[name] = rms
    return out


def error_by_speed_over_seeds(tables) -> dict:
    """Mean and 95 % t-interval over devices of per-seed :func:`error_by_speed` tables
    (computed on shared bin edges).

    Returns
    -------
    dict
        ``{"speed": bin centres, "n": seeds, method: (mean, half) arrays per bin}``.
    """
    from rippleb.report.stats import t_interval

    out = {"speed": tables[0]["speed"], "n": len(tables)}
    methods = set.intersection(*(set(t) - {"speed"} for t in tables))
    for name in methods:
        per_seed = np.array([t[name] for t in tables])
        cells = [t_interval(per_seed[:, b]) for b in range(per_seed.shape[1])]
        out[name] = (np.array([c[0] for c in cells]), np.array([c[1] for c in cells]))
    return out


def plot_error_vs_speed(tables, out_png, seeds_text: str = "seed 0", scenarios=None) -> Path:
    """RMS error against joint speed per method, log scale: the mean over devices of each
    device's RMS per speed bin, with its 95 % t-interval as an error bar
    (:func:`error_by_speed_over_seeds`). ``tables`` is that function's result, or a list
    of :class:`ScenarioSignals` of one device. A bar whose lower end is at or below zero
    runs off the bottom of the (log) axis, which is set by the means."""
    from rippleb.report.stats import method_order

    if isinstance(tables, list):
        scenarios = scenarios or [s.sim.log.meta.get("scenario", "?") for s in tables]
        tables = error_by_speed_over_seeds([error_by_speed(tables)])
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(9, 5.5))
    names = method_order(k for k in tables if k not in ("speed", "n"))
    width = np.diff(tables["speed"][1:3])[0] if len(tables["speed"]) > 2 else 1.0
    lows, highs = [], []
    for i, name in enumerate(names):
        mean, half = tables[name]
        kw = style(name, i, points=True)
        shift = (i - (len(names) - 1) / 2) * 0.6 * width / max(len(names), 1)  # bars side by side
        bars = np.where(np.isfinite(half), half, 0.0)
        ax.errorbar(tables["speed"] + shift, mean, yerr=bars, ms=3.5, lw=1.2, capsize=2, **kw)
        lows.append(np.nanmin(mean))
        highs.append(np.nanmax(mean + bars))
    if lows:
        ax.set_ylim(max(min(lows) / 5.0, 1e-9), max(highs) * 1.5)
    ax.set_yscale("log")
    where = ", ".join(plot_text(s) for s in scenarios) if scenarios else "the signal scenarios"
    ax.set(xlabel="|joint speed| [rad/s] (0: at rest)", ylabel="RMS error against torque_true [Nm]",
           title=f"Error against joint speed, pooled over {where}\nmean over {seeds_text} "
                 f"(bar: 95 % t-interval over devices)")
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=8, ncols=2)
    fig.tight_layout()
    return _save(fig, out_png)


def residual_spectra(sig: ScenarioSignals, max_order: float = 10.0, max_freq: float = 200.0) -> dict:
    """Amplitude spectra of each method's error ``estimate - torque_true`` over the
    evaluation window: over frequency, and over wave-generator order after re-sampling at
    encoder positions on the longest stretch of motion in one direction.

    Returns
    -------
    dict
        ``{"freq": [Hz], "order": [1/rev], method: (amp_over_freq, amp_over_order)}`` [Nm];
        ``order`` is empty if the scenario has no stretch of at least two revolutions.
    """
    log = sig.sim.log
    mask = np.asarray(sig.sim.eval_mask, bool)
    first, last = np.flatnonzero(mask)[[0, -1]]
    window = slice(first, last + 1)
    n = last + 1 - first
    freq = np.fft.rfftfreq(n, 1.0 / log.spec.fs)
    grid, cpr = _order_grid(log.encoder[window], log.spec.counts_per_rev)
    order = np.fft.rfftfreq(len(grid[1]), 1.0 / cpr) if grid is not None else np.array([])
    out = {"freq": freq[freq <= max_freq], "order": order[order <= max_order]}
    for name, est in sig.estimates.items():
        err = (est - log.torque_true)[window]
        amp_f = _amplitude(err)[freq <= max_freq]
        if grid is not None:
            edge, revs_grid = grid
            amp_o = _amplitude(np.interp(revs_grid, edge[1], err[edge[0]]))[order <= max_order]
        else:
            amp_o = np.array([])
        out[name] = (amp_f, amp_o)
    return out


def _order_grid(counts, cpr):
    """Sample indices and motor revolutions of the encoder edges on the longest monotonic
    stretch, and a uniform grid of whole revolutions over it; None if under two revolutions."""
    edge = np.flatnonzero(np.diff(counts)) + 1
    if len(edge) < 2:
        return None, cpr
    step = np.sign(np.diff(counts[edge]))
    breaks = np.flatnonzero(np.diff(step)) + 1
    runs = np.split(np.arange(len(edge)), breaks + 1) if len(breaks) else [np.arange(len(edge))]
    best = max(runs, key=len)
    idx = edge[best]
    revs = counts[idx] / cpr * (1 if step[min(best[0], len(step) - 1)] > 0 else -1)
    whole = int(np.floor(revs[-1] - revs[0]))
    if whole < 2:
        return None, cpr
    return ((idx, revs), revs[0] + np.arange(whole * cpr) / cpr), cpr


def plot_residual_spectra(sig: ScenarioSignals, out_png, seed: int = 0) -> Path:
    """What each method leaves behind: amplitude spectrum of its error against
    ``torque_true`` over wave-generator order (left; ripple sits at orders 2, 4, 8) and
    over frequency (right), one line per method, log scale."""
    from rippleb.report.stats import method_order

    plt = _pyplot()
    spectra = residual_spectra(sig)
    names = method_order(k for k in spectra if k not in ("freq", "order"))
    fig, (ax_o, ax_f) = plt.subplots(1, 2, figsize=(12, 5))
    for i, name in enumerate(names):
        amp_f, amp_o = spectra[name]
        kw = style(name, i)
        if len(amp_o):
            ax_o.plot(spectra["order"][1:], amp_o[1:], lw=0.9, **kw)
        ax_f.plot(spectra["freq"][1:], amp_f[1:], lw=0.9, **kw)
    for k in (2, 4, 8):
        ax_o.axvline(k, color="k", lw=0.6, ls=":", label="ripple orders 2, 4, 8" if k == 2 else None)
    scenario = sig.sim.log.meta.get("scenario", "?")
    ax_o.set(xlabel="order [per wave-generator revolution]", ylabel="error amplitude [Nm]", yscale="log",
             title="(a) over angle: ripple left behind" if len(spectra["order"]) else
             "(a) over angle: no stretch of two revolutions in one direction")
    ax_f.set(xlabel="frequency [Hz]", yscale="log", title="(b) over time: noise, lag and drift left behind")
    for a in (ax_o, ax_f):
        a.grid(alpha=0.3, which="both")
    ax_o.legend(fontsize=7, ncols=2)
    fig.suptitle(f"Spectrum of each method's error against torque_true on {scenario}, device seed {seed}",
                 fontsize=10)
    fig.tight_layout()
    return _save(fig, out_png)


def longest_rest_restart(sig: ScenarioSignals) -> int | None:
    """Index of the restart (rest to motion, inside the window) after the longest rest."""
    moving = np.asarray(sig.sim.moving, bool)
    starts = np.flatnonzero(moving[1:] & ~moving[:-1]) + 1
    starts = starts[np.asarray(sig.sim.eval_mask, bool)[starts]]
    if len(starts) == 0:
        return None
    stops = np.flatnonzero(moving[:-1] & ~moving[1:]) + 1
    rest = [i - (stops[stops < i].max() if (stops < i).any() else 0) for i in starts]
    return int(starts[int(np.argmax(rest))])


def plot_restart_zoom(sig: ScenarioSignals, out_png, seed: int = 0,
                      before_s: float = 0.15, after_s: float = 0.35) -> Path | None:
    """Zoom on the restart after the longest rest of ``stop-restart``: estimates (top) and
    their error (bottom); this is where the dead zone and back propagation act."""
    from rippleb.report.stats import method_order

    i = longest_rest_restart(sig)
    if i is None:
        return None
    plt = _pyplot()
    log = sig.sim.log
    t0 = log.t[i]
    sel = (log.t >= t0 - before_s) & (log.t <= t0 + after_s)
    fig, (ax, ax_e) = plt.subplots(2, 1, figsize=(10, 7), sharex=True)
    ax.plot(log.t[sel], log.torque_true[sel], color="k", lw=2.0, label="torque_true")
    names = method_order(sig.estimates)
    for k, name in enumerate(names):
        est = sig.estimates[name][sel]
        ax.plot(log.t[sel], est, lw=1.0, **style(name, k))
        ax_e.plot(log.t[sel], est - log.torque_true[sel], lw=1.0, **style(name, k))
    for a in (ax, ax_e):
        a.axvline(t0, color="k", ls="--", lw=0.8)
        a.grid(alpha=0.3)
    ax.set(ylabel="torque [Nm]", title=f"Restart after the longest rest of stop-restart (at {t0:.3f} s, "
                                      f"dashed), device seed {seed}")
    ax_e.set(xlabel="time [s]", ylabel="estimate - torque_true [Nm]")
    ax.legend(fontsize=7, ncols=3, loc="best")
    fig.tight_layout()
    return _save(fig, out_png)


def plot_accuracy_vs_cost(frame, out_png, column: str = "rms_error_nm") -> Path:
    """Accuracy against per-tick cost, from the rows: per method, ``column`` (``rms_error_nm``,
    or on a recorded log what it is ranked by) averaged over scenarios for each seed (point:
    mean over seeds, bar: 95 % t-interval) against the median over rows of ``us_per_tick_p99``
    (bar: 25th to 75th percentile)."""
    from rippleb.report.stats import measured_rows, method_order, t_interval

    plt = _pyplot()
    ok = measured_rows(frame)
    names = method_order(ok["method"].unique())
    # Average only over scenarios every method finished, so that a method is not favoured
    # by missing its hardest scenario.
    common = set.intersection(*(set(ok.loc[ok["method"] == m, "scenario"]) for m in names)) if names else set()
    ok = ok[ok["scenario"].isin(common)]
    fig, ax = plt.subplots(figsize=(9, 6))
    for k, name in enumerate(names):
        rows = ok[ok["method"] == name]
        per_seed = rows.groupby("seed")[column].mean()
        y, half, _ = t_interval(per_seed)
        cost = rows["us_per_tick_p99"].dropna()
        if cost.empty or not np.isfinite(y) or y <= 0:  # a log axis has no place for 0
            continue
        x, lo, hi = np.percentile(cost, [50, 25, 75])
        kw = style(name, k, points=True)
        ax.errorbar([x], [y], xerr=[[x - lo], [hi - x]], yerr=[[half if np.isfinite(half) else 0]] * 2,
                    fmt=kw["marker"], ms=7, color=kw["color"], capsize=3, label=kw["label"])
    ax.set_xscale("log")
    ax.set_yscale("log")
    n_seeds, n_scen = ok["seed"].nunique(), ok["scenario"].nunique()
    ax.set(xlabel="compute time of one control tick, p99 [us] (median over rows; bar 25-75 %)",
           ylabel=COST_FIGURE_LABELS.get(column, column),
           title=f"Accuracy against per-tick cost: mean over the {n_scen} scenarios every method "
                 f"finished,\nthen over {n_seeds} seed(s) (bar: 95 % t-interval)")
    ax.grid(alpha=0.3, which="both")
    # a legend, not labels at the points: the order-tracking family sits too close for text;
    # none when no point was drawn (matplotlib warns about an empty legend)
    if ax.get_legend_handles_labels()[0]:
        ax.legend(fontsize=8, loc="lower left")
    fig.tight_layout()
    return _save(fig, out_png)


#: The y label of :func:`plot_accuracy_vs_cost` per column it may plot.
COST_FIGURE_LABELS = {"rms_error_nm": "RMS error against torque_true [Nm]",
                      "rms_error_ref_nm": "RMS error against torque_ref [Nm]",
                      "ripple_wg_nm": "ripple left at WG orders 2, 4, 8 [Nm] (truth-free)"}

"""Matplotlib figures of the benchmark.

``plot_order_spectra`` replicates the paper's Fig. 2: the strain spectrum at several
constant wave-generator speeds, over time (peaks move with speed) beside over angle,
re-sampled at encoder positions (peaks stay at orders 2, 4, 8).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

#: Wave-generator speeds of the Fig. 2 replica [rev/s]: slow to brisk motor speeds.
DEFAULT_SPEEDS = (1.0, 2.0, 4.0, 6.0, 8.0)


@dataclass(frozen=True)
class SpeedSpectra:
    """Strain spectra at one constant wave-generator speed ``speed`` [rev/s].

    ``freq`` [Hz] with ``time_amp`` [V]; ``order`` [1/rev] with ``angle_amp`` [V].
    """

    speed: float
    freq: np.ndarray
    time_amp: np.ndarray
    order: np.ndarray
    angle_amp: np.ndarray


def _amplitude(x: np.ndarray) -> np.ndarray:
    window = np.hanning(len(x))
    return 2.0 * np.abs(np.fft.rfft((x - x.mean()) * window)) / window.sum()


def constant_speed_run(speed: float, seed: int, revolutions: float = 16.0, load: float = 20.0):
    """Simulate the shoulder pan joint (no gravity) at ``speed`` wave-generator rev/s.

    A known constant load ``load`` [Nm] makes the load-dependent ripple visible.
    Returns the :class:`~rippleb.simulator.Simulation` and the start of the cruise [s].
    """
    from rippleb.scenario import scenario_from_dict
    from rippleb.simulator import simulate

    ratio = 100.0
    ramp = 0.2
    scenario = scenario_from_dict({
        "robot": {"joint": "shoulder_pan_joint"},
        "joint": {"gear_ratio": ratio},
        "trajectory": {"segment": [
            {"kind": "ramp", "velocity": speed * 2 * np.pi / ratio, "duration": ramp},
            {"kind": "cruise", "duration": max(1.0, revolutions / speed)}]},
        "load": [{"torque": load, "start": 0.0, "rise": 0.05, "known": True}],
    }, name=f"fig2-{speed:g}")
    return simulate(scenario, seed), ramp + 0.05


def speed_spectra(speed: float, seed: int = 0, revolutions: float = 16.0) -> SpeedSpectra:
    """Time-domain and angle-domain amplitude spectra of the strain at one speed."""
    sim, start = constant_speed_run(speed, seed, revolutions)
    log = sim.log
    keep = log.t >= start
    strain, counts = log.strain[keep], log.encoder[keep]
    freq = np.fft.rfftfreq(len(strain), 1.0 / log.spec.fs)
    # Re-sample where the encoder count changes (the paper's order tracking); fill any
    # count the DAQ skipped by interpolation, on whole revolutions.
    cpr = log.spec.counts_per_rev
    edge = np.flatnonzero(np.diff(counts)) + 1
    revs = counts[edge] / cpr
    grid = revs[0] + np.arange(int(np.floor(revs[-1] - revs[0])) * cpr) / cpr
    resampled = np.interp(grid, revs, strain[edge])
    order = np.fft.rfftfreq(len(grid), 1.0 / cpr)
    return SpeedSpectra(speed, freq, _amplitude(strain), order, _amplitude(resampled))


def plot_order_spectra(out_png: str | Path, seed: int = 0,
                       speeds: tuple[float, ...] = DEFAULT_SPEEDS,
                       revolutions: float = 16.0) -> Path:
    """Save a replica of the paper's Fig. 2 as PNG and return its path.

    Left: strain amplitude over frequency at each wave-generator speed (fixed time
    step). Right: over order, after re-sampling at encoder positions (fixed angle step).
    One curve per speed, stacked bottom (slow) to top (fast); ``revolutions`` of the
    wave generator at each speed set the order resolution.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    spectra = [speed_spectra(s, seed, revolutions) for s in speeds]
    fmax = 10.0 * max(speeds)
    scale = 1e3  # V -> mV
    step = max(max(sp.time_amp[(sp.freq > 0.5 * sp.speed) & (sp.freq < fmax)].max(),
                   sp.angle_amp[(sp.order > 0.5) & (sp.order < 10)].max())
               for sp in spectra) * scale * 1.1
    fig, (ax_t, ax_o) = plt.subplots(1, 2, figsize=(11, 5.5), sharey=True)
    colors = plt.cm.viridis(np.linspace(0.1, 0.85, len(spectra)))
    for i, (sp, color) in enumerate(zip(spectra, colors)):
        base = i * step
        sel = (sp.freq > 0.5 * sp.speed) & (sp.freq <= fmax)
        ax_t.plot(sp.freq[sel], base + scale * sp.time_amp[sel], color=color, lw=1)
        ax_t.text(fmax, base + 0.1 * step, f"{sp.speed:g} rev/s", ha="right", fontsize=8)
        osel = (sp.order > 0.5) & (sp.order <= 10)
        ax_o.plot(sp.order[osel], base + scale * sp.angle_amp[osel], color=color, lw=1)
        for k in (2, 4, 8):
            ax_t.plot(k * sp.speed, base, marker="|", color="k", ms=6)
    for k in (2, 4, 8):
        ax_o.axvline(k, color="k", lw=0.6, ls=":")
    ax_t.set(xlabel="frequency [Hz]", ylabel="strain amplitude [mV], offset per speed",
             title="(a) fixed time step: ripple moves with speed", xlim=(0, fmax))
    ax_o.set(xlabel="order [per wave-generator revolution]",
             title="(b) fixed angular step: ripple stays at orders 2, 4, 8", xlim=(0, 10))
    ax_t.set_yticks([i * step for i in range(len(spectra))],
                    [f"{s:g}" for s in speeds])
    ax_t.set_ylabel(f"wave-generator speed [rev/s]; rows {step:.0f} mV apart")
    fig.suptitle(f"Strain spectra of simulated device seed {seed} under a 20 Nm load "
                 f"(replica of Jung et al. 2017, Fig. 2); bar = 2, 4, 8 x speed", fontsize=10)
    fig.tight_layout()
    out = Path(out_png)
    fig.savefig(out, dpi=120)
    plt.close(fig)
    return out


# --------------------------------------------------------------------------- report figures
#
# The figures below show signals of one device (``seed``), re-simulated and streamed through
# the runner's own loop (:mod:`rippleb.streaming`, methods from the registry), or summarise
# the result rows. ``draw_all`` makes every figure the run's methods and scenarios allow.

#: One colour and line style per built-in method, the same in every figure.
METHOD_STYLE = {
    "raw": ("tab:blue", "-"), "lowpass": ("tab:cyan", "-"), "current-based": ("m", "--"),
    "order-tracking": ("tab:red", "-"), "order-tracking-no-deadzone": ("tab:orange", "-."),
    "order-tracking-no-backprop": ("tab:brown", ":"), "switched-notch": ("tab:green", "-"),
    "kalman-ripple": ("tab:purple", "-"),
}
#: Scenarios whose signals the figures need: Table I/Fig. 5/6, speed coverage, restarts.
SIGNAL_SCENARIOS = ("paper-quintic", "speed-sweep", "stop-restart")
_OTHER_COLORS = ("tab:olive", "tab:gray", "tab:pink", "k")


def style(method: str, index: int = 0) -> dict:
    """matplotlib keyword arguments of ``method``'s line."""
    color, ls = METHOD_STYLE.get(method, (_OTHER_COLORS[index % len(_OTHER_COLORS)], "-"))
    return {"color": color, "ls": ls, "label": method}


@dataclass
class ScenarioSignals:
    """One re-simulated scenario and each method's causal estimate on it.

    ``sim`` is the :class:`~rippleb.simulator.Simulation`; ``estimates`` maps a method to its
    estimate [Nm] per sample; ``errors`` a method that failed to the reason.
    """

    sim: object
    estimates: dict
    errors: dict


def fit_methods(methods, seed: int) -> tuple[dict, dict]:
    """Instantiate and ``fit`` each method on the calibration log of ``seed``, once.

    Returns ``(fitted, errors)``: method name to fitted instance, and to a one-line error.
    """
    from rippleb.registry import Registry, one_line
    from rippleb.simulator import simulate

    registry = Registry.discover()
    calibration = simulate("calibration", seed).log.for_method(keep_ref=True)
    fitted, errors = {}, {}
    for name in methods:
        try:
            method = registry.get(name).load()()
            method.fit(calibration)
        except Exception as exc:  # a failing method costs its curves, not the report
            errors[name] = one_line(exc)
        else:
            fitted[name] = method
    return fitted, errors


def stream_methods(fitted: dict, scenario: str, seed: int) -> ScenarioSignals:
    """Simulate ``scenario`` on ``seed`` and stream it through each fitted method.

    Each method is ``reset`` before its run (the Method contract), then fed blocks exactly
    as the runner does (:func:`rippleb.streaming.prepare_blocks`, :func:`~rippleb.streaming.stream`).
    """
    from rippleb.registry import one_line
    from rippleb.simulator import simulate
    from rippleb.streaming import prepare_blocks, stream

    sim = simulate(scenario, seed)
    visible = sim.log.for_method(keep_ref=False)
    estimates, errors = {}, {}
    for name, method in fitted.items():
        try:
            method.reset(visible.spec)
            estimates[name], _ = stream(method.step, prepare_blocks(visible), len(visible))
        except Exception as exc:
            errors[name] = one_line(exc)
    return ScenarioSignals(sim, estimates, errors)


def _pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _save(fig, out_png) -> Path:
    out = Path(out_png)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=110)
    fig.clf()
    _pyplot().close(fig)
    return out


MOTION_EDGE_LABEL = "joint starts or stops moving"


def _motion_edges(ax, sig: ScenarioSignals) -> None:
    """Dashed verticals where the joint starts and stops (as in the paper's Figs. 4-6),
    labelled once so the legend says what they are."""
    t, moving = sig.sim.log.t, np.asarray(sig.sim.moving, bool)
    for k, i in enumerate(np.flatnonzero(np.diff(moving.astype(int))) + 1):
        ax.axvline(t[i], color="k", lw=0.7, ls="--", alpha=0.6, label=None if k else MOTION_EDGE_LABEL)


def plot_trajectory(sig: ScenarioSignals, out_png) -> Path:
    """Replica of the paper's Fig. 4: desired position, velocity and acceleration of the
    ``paper-quintic`` joint, with the start and end of the motion dashed."""
    plt = _pyplot()
    t = sig.sim.log.t
    q, qd, qdd = sig.sim.scenario.trajectory(t)
    fig, ax = plt.subplots(figsize=(9, 4.5))
    ax.plot(t, q, "r:", lw=2, label="position $q_d$ [rad]")
    ax.plot(t, qd, "b--", lw=1.5, label=r"velocity $\omega_d$ [rad/s]")
    ax.plot(t, qdd, "k-", lw=1.2, label=r"acceleration $\alpha_d$ [rad/s$^2$]")
    _motion_edges(ax, sig)
    ax.set(xlabel="time [s]", ylabel="rad, rad/s, rad/s$^2$",
           title=f"Trajectory of paper-quintic, {sig.sim.scenario.joint} "
                 "(replica of Jung et al. 2017, Fig. 4)")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    return _save(fig, out_png)


def plot_ripple_compensation(sig: ScenarioSignals, out_png, seed: int = 0) -> Path:
    """Replica of the paper's Fig. 5: the raw strain torque against the order-tracking
    filtered torque on ``paper-quintic`` (top), and their error against the true torque
    (bottom), which is the ripple and offset the filter removes."""
    plt = _pyplot()
    log = sig.sim.log
    fig, (ax, ax_e) = plt.subplots(2, 1, figsize=(10, 6.5), sharex=True,
                                   gridspec_kw={"height_ratios": [3, 2]})
    ax.plot(log.t, log.torque_true, color="k", lw=1.0, label="torque_true (flexspline)")
    for i, name in enumerate(m for m in ("raw", "order-tracking") if m in sig.estimates):
        kw = style(name, i)
        kw["label"] = {"raw": "raw strain x gain", "order-tracking": "order-tracking filtered"}[name]
        ax.plot(log.t, sig.estimates[name], lw=0.8, **{**kw, "ls": "-"})
        ax_e.plot(log.t, sig.estimates[name] - log.torque_true, lw=0.8, **{**kw, "ls": "-"})
    for a in (ax, ax_e):
        _motion_edges(a, sig)
        a.grid(alpha=0.3)
    ax.set(ylabel="joint torque [Nm]",
           title=f"Ripple and offset compensation on paper-quintic, device seed {seed} "
                 "(replica of Jung et al. 2017, Fig. 5)")
    ax_e.set(xlabel="time [s]", ylabel="estimate - torque_true [Nm]")
    ax.legend(loc="best", fontsize=8)
    ax_e.legend(loc="best", fontsize=8)
    fig.tight_layout()
    return _save(fig, out_png)


def plot_estimates(sig: ScenarioSignals, out_png, seed: int = 0) -> Path:
    """Replica of the paper's Fig. 6: each method's estimate against the model reference
    ``torque_ref`` (eq. 7) on ``paper-quintic``, one panel per method; the first panel
    is the paper's own pair, current-based and order tracking."""
    plt = _pyplot()
    from rippleb.stats import method_order

    log = sig.sim.log
    names = method_order(sig.estimates)
    panels = [[m for m in ("current-based", "order-tracking") if m in sig.estimates]]
    panels = [p for p in panels if p] + [[m] for m in names if m not in panels[0]]
    ncols = 2
    nrows = int(np.ceil(len(panels) / ncols))
    fig, axes = plt.subplots(nrows, ncols, figsize=(11, 2.4 * nrows + 0.8), sharex=True, sharey=True,
                             squeeze=False)
    mask = np.asarray(sig.sim.eval_mask, bool)
    for ax, panel in zip(axes.flat, panels):
        ax.plot(log.t, log.torque_ref, color="k", lw=2.2, ls="--", label="torque_ref (model, eq. 7)")
        for name in panel:
            est = sig.estimates[name]
            rms = float(np.sqrt(np.mean((est[mask] - log.torque_ref[mask]) ** 2)))
            ax.plot(log.t, est, lw=0.9, **{**style(name, names.index(name)),
                                          "label": f"{name} (RMS vs ref {rms:.2g} Nm)"})
        _motion_edges(ax, sig)
        ax.legend(loc="upper right", fontsize=7)
        ax.grid(alpha=0.3)
    for ax in axes.flat[len(panels):]:
        ax.set_visible(False)
    if len(panels) % ncols:  # the panel above an empty slot ends its column: give it the time axis
        above = axes[-2, len(panels) % ncols] if nrows > 1 else None
        if above is not None:
            above.xaxis.set_tick_params(labelbottom=True)
            above.set_xlabel("time [s]")
    for ax in axes[:, 0]:
        ax.set_ylabel("torque [Nm]")
    for ax in axes[-1, : len(panels) - (nrows - 1) * ncols]:
        ax.set_xlabel("time [s]")
    fig.suptitle(f"Estimates against the model reference on paper-quintic, device seed {seed} "
                 "(replica of Jung et al. 2017, Fig. 6)", fontsize=10)
    fig.tight_layout()
    return _save(fig, out_png)


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
    from rippleb.stats import t_interval

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
    from rippleb.stats import method_order

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
        kw = style(name, i)
        shift = (i - (len(names) - 1) / 2) * 0.6 * width / max(len(names), 1)  # bars side by side
        bars = np.where(np.isfinite(half), half, 0.0)
        ax.errorbar(tables["speed"] + shift, mean, yerr=bars, marker="o", ms=3.5, lw=1.2, capsize=2, **kw)
        lows.append(np.nanmin(mean))
        highs.append(np.nanmax(mean + bars))
    if lows:
        ax.set_ylim(max(min(lows) / 5.0, 1e-9), max(highs) * 1.5)
    ax.set_yscale("log")
    where = ", ".join(scenarios) if scenarios else "the signal scenarios"
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
    from rippleb.stats import method_order

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
    from rippleb.stats import method_order

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


def plot_accuracy_vs_cost(frame, out_png) -> Path:
    """Accuracy against per-tick cost, from the rows: per method, ``rms_error_nm`` averaged
    over scenarios for each seed (point: mean over seeds, bar: 95 % t-interval) against the
    median over rows of ``us_per_tick_p99`` (bar: 25th to 75th percentile)."""
    from rippleb.stats import method_order, t_interval

    plt = _pyplot()
    ok = frame[frame["status"] == "ok"]
    names = method_order(ok["method"].unique())
    # Average only over scenarios every method finished, so that a method is not favoured
    # by missing its hardest scenario.
    common = set.intersection(*(set(ok.loc[ok["method"] == m, "scenario"]) for m in names)) if names else set()
    ok = ok[ok["scenario"].isin(common)]
    fig, ax = plt.subplots(figsize=(9, 6))
    for k, name in enumerate(names):
        rows = ok[ok["method"] == name]
        per_seed = rows.groupby("seed")["rms_error_nm"].mean()
        y, half, _ = t_interval(per_seed)
        cost = rows["us_per_tick_p99"].dropna()
        if cost.empty or not np.isfinite(y):
            continue
        x, lo, hi = np.percentile(cost, [50, 25, 75])
        kw = style(name, k)
        ax.errorbar([x], [y], xerr=[[x - lo], [hi - x]], yerr=[[half if np.isfinite(half) else 0]] * 2,
                    fmt="o", ms=7, color=kw["color"], capsize=3, label=name)
    ax.set_xscale("log")
    ax.set_yscale("log")
    n_seeds, n_scen = ok["seed"].nunique(), ok["scenario"].nunique()
    ax.set(xlabel="compute time of one control tick, p99 [us] (median over rows; bar 25-75 %)",
           ylabel="RMS error against torque_true [Nm]",
           title=f"Accuracy against per-tick cost: mean over the {n_scen} scenarios every method "
                 f"finished,\nthen over {n_seeds} seed(s) (bar: 95 % t-interval)")
    ax.grid(alpha=0.3, which="both")
    # a legend, not labels at the points: the order-tracking family sits too close for text
    ax.legend(fontsize=8, loc="lower left")
    fig.tight_layout()
    return _save(fig, out_png)


FORMATS = ("png", "svg", "pdf")


def draw_all(frame, out_dir, seed: int = 0, fmt: str = "png", speed_seeds=None,
             keep: dict | None = None) -> tuple[dict, list]:
    """Every figure the run allows, into ``out_dir``, as ``fmt`` (png, svg or pdf).

    Signal figures use the run's methods with at least one ok row of the ``same-session``
    condition, on the scenarios of :data:`SIGNAL_SCENARIOS` that the run scored,
    re-simulated on ``seed``; the error-against-speed figure repeats that on every seed of
    ``speed_seeds`` (default: every seed of the run) to show the mean over devices.
    ``keep``, if given, receives the signals of ``seed`` per scenario (for the HTML page).

    Returns
    -------
    figures, warnings
        ``{name: (path, caption)}`` in README order, and one line per method or figure
        that could not be drawn.
    """
    from rippleb.conditions import DEFAULT_CONDITION
    from rippleb.provenance import seeds_text
    from rippleb.stats import method_order, with_condition

    if fmt not in FORMATS:
        from rippleb.errors import InputError

        raise InputError(f"--format {fmt}: choose one of {', '.join(FORMATS)}")
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    path = lambda name: out_dir / f"{name}.{fmt}"  # noqa: E731
    figures, warnings = {}, []
    figures["fig2_order_spectra"] = (plot_order_spectra(path("fig2_order_spectra"), seed=seed),
                                     f"Strain spectra over time and over angle (Fig. 2 replica, seed {seed})")
    frame = with_condition(frame)
    ok = frame[(frame["status"] == "ok") & (frame["condition"] == DEFAULT_CONDITION)]
    methods = method_order(ok["method"].unique())
    scenarios = [s for s in SIGNAL_SCENARIOS if s in set(ok["scenario"])]
    signals = {}
    if methods and scenarios:
        signals, more = _signals_of_seed(methods, scenarios, seed)
        warnings += more
        for scenario in scenarios:
            warnings += _check_against_rows(signals[scenario], ok, scenario, seed)
        if keep is not None:
            keep.update(signals)
    if "paper-quintic" in signals:
        sig = signals["paper-quintic"]
        figures["fig4_trajectory"] = (plot_trajectory(sig, path("fig4_trajectory")),
                                      "Trajectory of paper-quintic (Fig. 4 replica)")
        figures["fig5_ripple_compensation"] = (
            plot_ripple_compensation(sig, path("fig5_ripple_compensation"), seed),
            f"Raw against order-tracking filtered torque on paper-quintic (Fig. 5 replica, seed {seed})")
        figures["fig6_estimates"] = (
            plot_estimates(sig, path("fig6_estimates"), seed),
            f"Each estimate against the model reference on paper-quintic (Fig. 6 replica, seed {seed})")
    if signals:
        seeds = sorted(int(k) for k in (ok["seed"].unique() if speed_seeds is None else speed_seeds))
        edges = speed_edges(list(signals.values()))
        tables = [error_by_speed(list(signals.values()), edges=edges)]
        for other in (k for k in seeds if k != seed):
            more_signals, _ = _signals_of_seed(methods, scenarios, other)
            tables.append(error_by_speed(list(more_signals.values()), edges=edges))
        text = seeds_text(sorted(set(seeds) | {seed})).replace("(", "devices (")
        figures["error_vs_speed"] = (
            plot_error_vs_speed(error_by_speed_over_seeds(tables), path("error_vs_speed"), text, scenarios),
            f"RMS error against joint speed per method, mean over {text}")
        spectral = next((signals[s] for s in ("speed-sweep", "paper-quintic", "stop-restart") if s in signals))
        figures["residual_spectra"] = (
            plot_residual_spectra(spectral, path("residual_spectra"), seed),
            f"What each method leaves behind: spectrum of its error over order and over frequency (seed {seed})")
    if "stop-restart" in signals:
        zoom = plot_restart_zoom(signals["stop-restart"], path("restart_zoom"), seed)
        if zoom is not None:
            figures["restart_zoom"] = (zoom, f"Zoom on a restart of stop-restart (seed {seed})")
    figures["accuracy_vs_cost"] = (plot_accuracy_vs_cost(ok, path("accuracy_vs_cost")),
                                   "Accuracy against per-tick cost, from the rows (same-session)")
    return figures, warnings


def _signals_of_seed(methods, scenarios, seed: int) -> tuple[dict, list]:
    """Fit ``methods`` on the calibration log of ``seed`` and stream each scenario."""
    fitted, errors = fit_methods(methods, seed)
    warnings = [f"figures: {m} not drawn on seed {seed}, fit failed: {e}" for m, e in errors.items()]
    signals = {}
    for scenario in scenarios:
        signals[scenario] = stream_methods(fitted, scenario, seed)
        warnings += [f"figures: {m} not drawn on {scenario} seed {seed}: {e}"
                     for m, e in signals[scenario].errors.items()]
    return signals, warnings


def _check_against_rows(sig: ScenarioSignals, ok, scenario: str, seed: int) -> list[str]:
    """A figure's signal must be the one its row scored; a method whose ``reset`` leaks
    state between runs (or a stale table) shows up here as a mismatch."""
    from rippleb.metrics import rms_error

    out = []
    mask = np.asarray(sig.sim.eval_mask, bool)
    for name, est in sig.estimates.items():
        rows = ok[(ok["method"] == name) & (ok["scenario"] == scenario) & (ok["seed"] == seed)]
        if rows.empty:
            continue
        mine = rms_error(est, sig.sim.log.torque_true, mask)
        theirs = float(rows["rms_error_nm"].iloc[0])
        if not np.isclose(mine, theirs, rtol=1e-9, atol=1e-12):
            out.append(f"figures: {name} on {scenario} seed {seed}: rms_error_nm {mine:.6g} in the figure, "
                       f"{theirs:.6g} in the row (does reset() clear all state? is the run stale?)")
    return out

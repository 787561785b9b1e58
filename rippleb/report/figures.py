"""Matplotlib figures of the benchmark.

The replicas of the paper's figures, and :func:`draw_all`, which draws every figure a run
allows (the others live in :mod:`rippleb.report.error_figures`, the shared style and signals in
:mod:`rippleb.report.plotting`).

``plot_order_spectra`` replicates the paper's Fig. 2: the strain spectrum at several
constant wave-generator speeds, over time (peaks move with speed) beside over angle,
re-sampled at encoder positions (peaks stay at orders 2, 4, 8).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from rippleb.report.error_figures import (COST_FIGURE_LABELS, error_by_speed,  # noqa: F401
                                          error_by_speed_over_seeds, longest_rest_restart, plot_accuracy_vs_cost,
                                          plot_error_vs_speed, plot_residual_spectra, plot_restart_zoom,
                                          residual_spectra, speed_edges)
from rippleb.report.plotting import (MOTION_EDGE_LABEL, SIGNAL_SCENARIOS, ScenarioSignals,  # noqa: F401
                                     _amplitude, _motion_edges, _pyplot, _save, plot_text, restream, style)

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


def constant_speed_run(speed: float, seed: int, revolutions: float = 16.0, load: float = 20.0):
    """Simulate the shoulder pan joint (no gravity) at ``speed`` wave-generator rev/s.

    A known constant load ``load`` [Nm] makes the load-dependent ripple visible.
    Returns the :class:`~rippleb.simulator.Simulation` and the start of the cruise [s].
    """
    from rippleb.simulator.scenario import scenario_from_dict
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
    return _save(fig, out_png, dpi=120)


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
    from rippleb.report.stats import method_order

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
                                          "label": f"{plot_text(name)} (RMS vs ref {rms:.2g} Nm)"})
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


FORMATS = ("png", "svg", "pdf")


def draw_all(frame, out_dir, seed: int = 0, fmt: str = "png", speed_seeds=None,
             keep: dict | None = None, sealed: bool = False) -> tuple[dict, list]:
    """Every figure the run allows, into ``out_dir``, as ``fmt`` (png, svg or pdf).

    Signal figures use the run's methods with at least one ok row of the ``same-session``
    condition, on the scenarios of :data:`SIGNAL_SCENARIOS` that the run scored,
    re-simulated on ``seed``; the error-against-speed figure repeats that on every seed of
    ``speed_seeds`` (default: every seed of the run) to show the mean over devices.
    ``keep``, if given, receives the signals of ``seed`` per scenario (for the HTML page).
    ``sealed``: the rows are a sealed run's, whose devices are secret; the figures then
    re-simulate the public devices of the same numbers, and their captions say so.

    Returns
    -------
    figures, warnings
        ``{name: (path, caption)}`` in README order, and one line per method or figure
        that could not be drawn.
    """
    from rippleb.simulator.conditions import DEFAULT_CONDITION
    from rippleb.report.provenance import seeds_text
    from rippleb.engine.results import swept_columns
    from rippleb.report import order_figure
    from rippleb.report.tables import is_recorded
    from rippleb.report.stats import measured_rows, method_order, with_condition

    if fmt not in FORMATS:
        from rippleb.errors import InputError

        raise InputError(f"--format {fmt}: choose one of {', '.join(FORMATS)}")
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    path = lambda name: out_dir / f"{name}.{fmt}"  # noqa: E731
    figures, warnings = {}, []
    device = f"public seed {seed}, not a sealed device" if sealed else f"seed {seed}"
    figures["fig2_order_spectra"] = (plot_order_spectra(path("fig2_order_spectra"), seed=seed),
                                     f"Strain spectra over time and over angle (Fig. 2 replica, {device})")
    if not is_recorded(frame):   # simulated devices: the run's own, re-simulated
        population_seeds = sorted(int(k) for k in (frame["seed"].unique() if speed_seeds is None else speed_seeds))
        devices = seeds_text(population_seeds).replace("(", "devices (")
        if sealed:   # the sealed devices are secret: the figure shows the public ones of those numbers
            devices = f"public {devices}, not the sealed run's"
        cases = order_figure.population(population_seeds)
        figures["fig2_orders_vs_speed"] = (
            order_figure.plot_orders_vs_speed(cases, path("fig2_orders_vs_speed"), devices),
            f"Strain order amplitudes against wave-generator speed over {devices} (Fig. 2 over the "
            f"population): {order_figure.fraction_sentence(cases)}")
    frame = with_condition(frame)
    # a recording without a reference (no-reference rows) is still drawn by its truth-free column
    ok = measured_rows(frame)
    ok = ok[ok["condition"] == DEFAULT_CONDITION]
    methods = method_order(ok["method"].unique())
    scenarios = [s for s in SIGNAL_SCENARIOS if s in set(ok["scenario"])]
    signals = {}
    if methods and scenarios:
        signals, more = _signals_of_seed(methods, scenarios, seed)
        warnings += more
        # a sweep's rows ran at swept values, and a sealed run's on secret devices, not the
        # public device re-simulated here: nothing to check the figure against
        if not swept_columns(frame.columns) and not sealed:
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
            f"Raw against order-tracking filtered torque on paper-quintic (Fig. 5 replica, {device})")
        figures["fig6_estimates"] = (
            plot_estimates(sig, path("fig6_estimates"), seed),
            f"Each estimate against the model reference on paper-quintic (Fig. 6 replica, {device})")
    if signals:
        seeds = sorted(int(k) for k in (ok["seed"].unique() if speed_seeds is None else speed_seeds))
        edges = speed_edges(list(signals.values()))
        tables = [error_by_speed(list(signals.values()), edges=edges)]
        for other in (k for k in seeds if k != seed):
            more_signals, _ = _signals_of_seed(methods, scenarios, other)
            tables.append(error_by_speed(list(more_signals.values()), edges=edges))
        text = seeds_text(sorted(set(seeds) | {seed})).replace("(", "devices (")
        text = f"public {text}, not the sealed run's" if sealed else text
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
    column = _cost_figure_column(ok)
    if column is not None:  # no row with a score: no empty figure
        what = "Accuracy" if column == "rms_error_nm" else f"`{column}`"
        figures["accuracy_vs_cost"] = (plot_accuracy_vs_cost(ok, path("accuracy_vs_cost"), column),
                                       f"{what} against per-tick cost, from the rows (same-session)")
    return figures, warnings


def _cost_figure_column(ok) -> str | None:
    """What the accuracy-against-cost figure plots: ``rms_error_nm``, or on a recorded log the
    column it is ranked by (:func:`rippleb.report.recorded.ranking_column`); None if no ok row
    has a value in it."""
    from rippleb.report.recorded import ranking_column
    from rippleb.report.tables import is_recorded

    column = ranking_column(ok) if len(ok) and is_recorded(ok) else "rms_error_nm"
    # only the columns the figure's log axis can show (a delay may be negative or zero)
    plottable = column in COST_FIGURE_LABELS and column in ok and ok[column].notna().any()
    return column if plottable else None


def _signals_of_seed(methods, scenarios, seed: int) -> tuple[dict, list]:
    """Fit ``methods`` on the calibration log of ``seed`` and stream each scenario, in the
    methods' sandboxed workers (:func:`rippleb.report.plotting.restream`)."""
    return restream(methods, scenarios, seed)


def _check_against_rows(sig: ScenarioSignals, ok, scenario: str, seed: int) -> list[str]:
    """A figure's signal must be the one its row scored; a method whose ``reset`` leaks
    state between runs (or a stale table) shows up here as a mismatch."""
    from rippleb.scoring.metrics import rms_error

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

"""What every matplotlib figure of rippleb shares: one style per method, the re-simulated
signals of one device streamed through each method (in the methods' sandboxed workers,
:func:`restream`), and saving in any format."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from rippleb.printable import escaped


def _amplitude(x: np.ndarray) -> np.ndarray:
    window = np.hanning(len(x))
    return 2.0 * np.abs(np.fft.rfft((x - x.mean()) * window)) / window.sum()


#: Scenarios whose signals the figures need: Table I/Fig. 5/6, speed coverage, restarts.
SIGNAL_SCENARIOS = ("paper-quintic", "speed-sweep", "stop-restart")


def style(method: str, index: int = 0, *, points: bool = False) -> dict:
    """matplotlib keyword arguments of ``method``'s line (:mod:`rippleb.report.palette`), with
    its marker when ``points``: the figures that draw a point per value. Its label is
    :func:`plot_text`: a method's name is not the report's to trust."""
    from rippleb.report.palette import matplotlib_marker, matplotlib_style

    return {**matplotlib_style(method, index), "label": plot_text(method),
            **({"marker": matplotlib_marker(method, index)} if points else {})}


def plot_text(value) -> str:
    """A name (a method's label, a scenario's) as matplotlib text: matplotlib reads text
    between two ``$`` as mathtext, and a name that is not valid mathtext (``$\\x$``) stopped
    the whole report with a ParseFatalException; an escaped ``\\$`` is a dollar sign."""
    return escaped(value).replace("$", r"\$")


@dataclass
class ScenarioSignals:
    """One re-simulated scenario and each method's causal estimate on it.

    ``sim`` is the :class:`~rippleb.simulator.Simulation`; ``estimates`` maps a method to its
    estimate [Nm] per sample; ``errors`` a method that failed to the reason.
    """

    sim: object
    estimates: dict
    errors: dict


def restream(methods, scenarios, seed: int, timeout: float | None = None,
             memory_mb: float | None = None) -> tuple[dict, list[str]]:
    """Each of ``methods`` fitted on the calibration log of ``seed`` and streamed through each
    of ``scenarios`` re-simulated on ``seed``, exactly as a run's rows run
    (:func:`rippleb.engine.runner.run_plan`): in the sandboxed worker of a method, under the
    run's limits, so the report's process never imports a plugin nor runs a method's code.

    Returns ``({scenario: ScenarioSignals}, warnings)``: a method whose row is not ``ok`` is
    left out of that scenario's signals, its reason in ``ScenarioSignals.errors``. A name
    may be a variant's label (``order-tracking[q=20]``).
    """
    import os

    from rippleb.engine.rows import CALIBRATION, FITTING, SCORED, Case, RowKey, scenario_hash
    from rippleb.engine.runner import DEFAULT_MEMORY_MB, DEFAULT_TIMEOUT_S, fork_server, run_plan
    from rippleb.engine.plan import Plan
    from rippleb.registry import Registry
    from rippleb.scoring.metrics import Truth
    from rippleb.simulator import simulate
    from rippleb.simulator.conditions import DEFAULT_CONDITION

    registry = Registry.discover()
    plan, estimates = Plan(calibration_label=CALIBRATION), {}
    with fork_server(registry) as server:   # before the simulations: no job's memory holds their truth
        calibration = simulate("calibration", seed)
        cal_case = Case(CALIBRATION, scenario_hash(calibration.scenario), DEFAULT_CONDITION, seed, FITTING)
        plan.ready[cal_case] = (calibration.log, None)
        sims = {}
        for scenario in scenarios:
            sims[scenario] = sim = simulate(scenario, seed)
            case = Case(scenario, scenario_hash(sim.scenario), DEFAULT_CONDITION, seed, SCORED)
            plan.ready[case] = (sim.log, Truth.from_simulation(sim))
            for method in methods:
                plan.add_row(RowKey(method, scenario, DEFAULT_CONDITION, seed), case, cal_case)
        rows = run_plan(registry, plan, jobs=os.cpu_count() or 1, server=server, estimates=estimates,
                        timeout=DEFAULT_TIMEOUT_S if timeout is None else timeout,
                        memory_mb=DEFAULT_MEMORY_MB if memory_mb is None else memory_mb)
    signals, warnings = {}, []
    for scenario, sim in sims.items():
        mine = rows[rows["scenario"] == scenario]
        failed = mine[mine["status"] != "ok"]
        errors = {m: f"{s}: {msg}" for m, s, msg in zip(failed["method"], failed["status"], failed["message"])}
        signals[scenario] = ScenarioSignals(sim, {k.method: e for k, e in estimates.items() if k.scenario == scenario},
                                            errors)
        warnings += [f"figures: {m} not drawn on {scenario} seed {seed}: {e}" for m, e in errors.items()]
    return signals, warnings


def _pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _save(fig, out_png, dpi: int = 110) -> Path:
    from rippleb.files import atomic_path

    out = Path(out_png)
    out.parent.mkdir(parents=True, exist_ok=True)
    with atomic_path(out) as tmp:   # replaced, never written through (a link there is replaced)
        fig.savefig(tmp, dpi=dpi)
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

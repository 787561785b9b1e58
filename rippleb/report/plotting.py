"""What every matplotlib figure of rippleb shares: one style per method, the re-simulated
signals of one device streamed through each method, and saving in any format."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

def _amplitude(x: np.ndarray) -> np.ndarray:
    window = np.hanning(len(x))
    return 2.0 * np.abs(np.fft.rfft((x - x.mean()) * window)) / window.sum()


#: Scenarios whose signals the figures need: Table I/Fig. 5/6, speed coverage, restarts.
SIGNAL_SCENARIOS = ("paper-quintic", "speed-sweep", "stop-restart")


def style(method: str, index: int = 0, *, points: bool = False) -> dict:
    """matplotlib keyword arguments of ``method``'s line (:mod:`rippleb.report.palette`), with
    its marker when ``points``: the figures that draw a point per value."""
    from rippleb.report.palette import matplotlib_marker, matplotlib_style

    return {**matplotlib_style(method, index), **({"marker": matplotlib_marker(method, index)} if points else {})}


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
    A name may be a variant's label (``order-tracking[q=20]``): built with its parameters.
    """
    from rippleb.registry import Registry, one_line
    from rippleb.simulator import simulate
    from rippleb.variants import parse_label

    registry = Registry.discover()
    calibration = simulate("calibration", seed).log.for_method(keep_ref=True)
    fitted, errors = {}, {}
    for name in methods:
        try:
            variant = parse_label(name)
            method = registry.get(variant.name).load()(**variant.params)
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

"""What every matplotlib figure of rippleb shares: one style per method, the re-simulated
signals of one device streamed through each method, and saving in any format."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from rippleb.printable import escaped


def _amplitude(x: np.ndarray) -> np.ndarray:
    window = np.hanning(len(x))
    return 2.0 * np.abs(np.fft.rfft((x - x.mean()) * window)) / window.sum()


#: One colour and line style per built-in method, the same in every figure.
METHOD_STYLE = {
    "raw": ("tab:blue", "-"), "lowpass": ("tab:cyan", "-"), "current-based": ("m", "--"),
    "order-tracking": ("tab:red", "-"), "order-tracking-no-deadzone": ("tab:orange", "-."),
    "order-tracking-no-backprop": ("tab:brown", ":"), "switched-notch": ("tab:green", "-"),
    "kalman-ripple": ("tab:purple", "-"), "spatial-filter": ("tab:blue", "--"),
    "fourier-lms": ("tab:pink", "-"), "periodic-dob": ("tab:purple", "--"),
    "gear-aware": ("tab:gray", "--"), "gear-keeping": ("#98df8a", "-"),
}
#: Scenarios whose signals the figures need: Table I/Fig. 5/6, speed coverage, restarts.
SIGNAL_SCENARIOS = ("paper-quintic", "speed-sweep", "stop-restart")
_OTHER_COLORS = ("tab:olive", "tab:gray", "tab:pink", "k")


def style(method: str, index: int = 0) -> dict:
    """matplotlib keyword arguments of ``method``'s line."""
    color, ls = METHOD_STYLE.get(method, (_OTHER_COLORS[index % len(_OTHER_COLORS)], "-"))
    return {"color": color, "ls": ls, "label": plot_text(method)}


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


def fit_methods(methods, seed: int) -> tuple[dict, dict]:
    """Instantiate and ``fit`` each method on the calibration log of ``seed``, once.

    Returns ``(fitted, errors)``: method name to fitted instance, and to a one-line error.
    A name may be a variant's label (``order-tracking[q=20]``): built with its parameters.
    """
    from rippleb import harness
    from rippleb.registry import Registry, one_line
    from rippleb.simulator import simulate
    from rippleb.variants import parse_label

    registry = Registry.discover()
    calibration = simulate("calibration", seed).log
    fitted, errors = {}, {}
    for name in methods:
        try:
            variant = parse_label(name)
            method = harness.fit(registry.get(variant.name).load()(**variant.params), calibration)
        except Exception as exc:  # a failing method costs its curves, not the report
            errors[name] = one_line(exc)
        else:
            fitted[name] = method
    return fitted, errors


def stream_methods(fitted: dict, scenario: str, seed: int) -> ScenarioSignals:
    """Simulate ``scenario`` on ``seed`` and stream it through each fitted method.

    Each method is ``reset`` before its run (the Method contract), then fed blocks exactly
    as the runner does (:func:`rippleb.harness.run`).
    """
    from rippleb import harness
    from rippleb.registry import one_line
    from rippleb.simulator import simulate

    sim = simulate(scenario, seed)
    estimates, errors = {}, {}
    for name, method in fitted.items():
        try:
            estimates[name], _ = harness.run(method, sim.log)
        except Exception as exc:
            errors[name] = one_line(exc)
    return ScenarioSignals(sim, estimates, errors)


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

"""One tuning protocol for every method: its declared ranges, one sampler, one budget.

A method declares the constructor parameters worth tuning and their ranges as a class
attribute ``tunable = {"param": (low, high, "log" | "linear" | "int"), ...}`` (``{}``:
nothing to tune, e.g. a method whose parameters come from its sources or are fitted on
the calibration log). :func:`candidates` turns a declaration into the same number of
points for every method: the default, then ``budget - 1`` points of a scrambled Sobol
sequence (``scipy.stats.qmc``, seeded, so the points re-run) mapped onto the ranges. The
tuner (``benchmarks/tune_all.py``) scores each point on the ``calibration`` scenario only,
against its ``torque_ref`` (the only torque a real calibration knows), and reports the
best; the budget is the number of calibration evaluations per method, whatever the
method. docs/tuning.md says what it found.

Examples
--------
>>> points = candidates({"q": (1.0, 100.0, "log")}, {"q": 30.0}, budget=4)
>>> len(points), points[0]
(4, {'q': 30.0})
"""

from __future__ import annotations

import numpy as np

KINDS = ("log", "linear", "int")
#: The seed of the Sobol scrambling: every method sees the same sequence of unit points.
SEED = 33


def check_tunable(name: str, tunable: dict) -> None:
    """Refuse a malformed ``tunable`` declaration with one line naming the method."""
    for param, spec in tunable.items():
        if not (isinstance(spec, tuple) and len(spec) == 3 and spec[2] in KINDS and spec[0] < spec[1]):
            raise ValueError(f"{name}.tunable[{param!r}] must be (low, high, one of {KINDS}) with low < high, "
                             f"got {spec!r}")
        if spec[2] == "log" and spec[0] <= 0:
            raise ValueError(f"{name}.tunable[{param!r}]: a log range must be positive, got {spec!r}")


def candidates(tunable: dict, defaults: dict, budget: int) -> list[dict]:
    """``budget`` parameter sets: ``defaults`` first, then Sobol points over ``tunable``."""
    if budget < 1:
        raise ValueError(f"budget must be at least 1, got {budget}")
    first = {p: defaults[p] for p in tunable}
    if not tunable or budget == 1:
        return [first]
    from scipy.stats import qmc

    # the first budget - 1 points of a power-of-two Sobol block (scipy warns on other sizes)
    m = int(np.ceil(np.log2(budget - 1))) if budget > 2 else 0
    unit = qmc.Sobol(len(tunable), scramble=True, seed=SEED).random_base2(m)[:budget - 1]
    points = [first]
    for row in unit:
        points.append({p: _scale(u, *spec) for u, (p, spec) in zip(row, tunable.items())})
    return points


def _scale(u: float, low: float, high: float, kind: str):
    """A unit coordinate ``u`` in [0, 1) onto the range."""
    if kind == "log":
        return float(np.exp(np.log(low) + u * (np.log(high) - np.log(low))))
    if kind == "int":
        return int(low + np.floor(u * (high - low + 1)))
    return float(low + u * (high - low))

"""``gain-tuned``: the hardware remedy, each amplifier channel's gain tuned to null the ripple,
then any software method on the compensated sum.

The field's first remedy (Jung et al. 2017, Sec. I: "multiple measurement elements are
aligned to cancel the ripple of each element", then "gain tuning based signal
compensation"): gauges at several angles of the flexspline cancel the wave generator's
orders by their geometry, but only as far as they sit where they should. Godler, Ninomiya
& Horiuchi (IEEE TIM 50(1), 2001) and Harmonic Drive Systems' patent (US 6,840,118) amplify
each gauge set with its own gain and tune the gains so the ripple's components cancel:
with ``2n + 1`` channels, ``n`` orders cancel exactly whatever the positions.

Here the gains are fitted on the calibration log, on control-tick means: each channel
``x_c`` is regressed on ``1, torque_ref`` and the harmonics ``cos k theta, sin k theta`` of
the encoder angle for ``k = 1 .. max_order``, each also times ``|torque_ref|`` (the ripple
grows with load). The weights ``w`` minimise the ripple harmonics of ``sum_c w_c x_c`` with
its torque gain held at the plain mean's (``sum_c w_c g_c = mean g``), with a small pull
``ridge`` towards equal weights so an ill-posed fit cannot amplify noise. Real torque is in
every channel alike, so no weights can tune it away. What they cannot tell from ripple
either: real torque at the wave-generator orders that ``torque_ref`` does not know (the
gear's transmission error, at orders 1 and 2) looks like ripple common to the channels, and
the fit then trades some gauge ripple against it. Modelling it as ``gear-aware`` does
(inertial rows in ``theta'^2`` and ``theta''``) or fitting only the calibration's slow ticks
both measured worse (docs/methods/gain-tuned.md). A log without channels (the paper's one
bridge) has nothing to tune: the sum is ``strain`` itself.

The compensated sum then goes to the software method ``then`` (any method's name or variant
label, ``raw`` by default), fitted and streamed as if it were the log's ``strain``: one
composition for every method, so ``gain-tuned[then=order-tracking]`` is the paper's method
on the tuned hardware. Per tick it costs one weighted sum of the channels beside the inner
method's own work. docs/methods/gain-tuned.md.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from rippleb.method import Method


def harmonic_design(angle: np.ndarray, torque: np.ndarray, max_order: int, load_scale: float) -> np.ndarray:
    """``[1, tau, cos k th, sin k th, |tau| cos k th / L, |tau| sin k th / L]`` for ``k = 1 ..
    max_order`` (``L = load_scale``: the load terms in the units of the base terms)."""
    load = np.abs(torque) / load_scale
    cols = [np.ones_like(angle), torque]
    for k in range(1, max_order + 1):
        c, s = np.cos(k * angle), np.sin(k * angle)
        cols += [c, s, load * c, load * s]
    return np.column_stack(cols)


def tick_means(log) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(channels, torque_ref, angle [rad])`` of ``log``, averaged per control tick."""
    size = log.spec.block_size
    n = len(log) // size * size

    def mean(x):
        return x[:n].reshape(n // size, size, *x.shape[1:]).mean(axis=1)

    angle = mean(log.encoder.astype(float)) * 2.0 * np.pi / log.spec.counts_per_rev
    return mean(log.channels), mean(log.torque_ref), angle


def harmonic_coefficients(channels: np.ndarray, torque: np.ndarray, angle: np.ndarray, max_order: int,
                          extra: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """``(g, M)``: each channel's torque gain and its harmonic coefficients (rows of
    :func:`harmonic_design` but the first two), by least squares on per-tick ``channels``,
    ``torque`` (the reference) and ``angle``; ``extra`` regressors are fitted beside and left
    out of ``M`` (a variant's model of other signals)."""
    load_scale = max(float(np.sqrt(np.mean(torque ** 2))), 1e-9)
    design = harmonic_design(angle, torque, max_order, load_scale)
    width = design.shape[1]
    if extra is not None:
        design = np.hstack([design, extra])
    scale = np.maximum(np.linalg.norm(design, axis=0), 1e-300)   # columns of other units: unit columns
    coef = np.linalg.lstsq(design / scale, channels, rcond=None)[0] / scale[:, None]
    return coef[1], coef[2:width]


def null_weights(gains: np.ndarray, harmonics: np.ndarray, ridge: float) -> np.ndarray:
    """The channel weights that null the harmonics at the plain mean's torque gain:
    minimise ``|M w|^2 + lam |w - 1/K|^2`` subject to ``g . w = mean(g)``,
    ``lam = ridge x trace(M'M) / K``."""
    k = len(gains)
    normal = harmonics.T @ harmonics
    lam = ridge * np.trace(normal) / k
    # the constrained least squares as one linear system (Lagrange): [[A, g], [g', 0]]
    # [w, mu] = [lam / K, mean g]; it stays solvable where A alone is singular (ridge 0
    # with more channels than the harmonics constrain)
    system = np.block([[normal + lam * np.eye(k), gains[:, None]], [gains[None, :], np.zeros((1, 1))]])
    rhs = np.concatenate([np.full(k, lam / k), [gains.mean()]])
    return np.linalg.lstsq(system, rhs, rcond=None)[0][:k]


def tuned_weights(channels: np.ndarray, torque: np.ndarray, angle: np.ndarray, max_order: int,
                  ridge: float) -> np.ndarray:
    """The channel weights that null the ripple harmonics of the sum at the plain mean's
    torque gain, from per-tick ``channels``, ``torque`` (the reference) and ``angle``."""
    return null_weights(*harmonic_coefficients(channels, torque, angle, max_order), ridge)


def compensated(data, weights):
    """``data`` (a log or a block) with ``strain`` the weighted sum of its channels; a log
    whose channels are not those the weights were tuned on is refused in one line."""
    if weights is None:
        return data
    count = 0 if data.channels is None else data.channels.shape[1]
    if count != len(weights):
        raise ValueError(f"the calibration log has {len(weights)} strain channels, this log {count}: "
                         f"tuned gains need the same channels in both")
    return dataclasses.replace(data, strain=data.channels @ weights)


def inner_method(then: str) -> Method:
    """A fresh instance of the method (or variant label) ``then``."""
    from rippleb.registry import Registry
    from rippleb.variants import split_label

    name, params = split_label(then)
    if name == GainTuned.name:
        raise ValueError(f"then={then!r}: gain-tuned cannot run on its own output")
    return Registry.discover().get(name).load()(**params)


class GainTuned(Method):
    """Per-channel gains fitted on the calibration log to null the wave-generator orders,
    then the method ``then`` on the compensated sum (see the module).

    Parameters
    ----------
    then
        The software method on the compensated sum: a method name or variant label.
    max_order
        The highest order of the wave-generator angle nulled: 8, the highest the paper
        names (orders 2, 4 and 8 dominate; 1 to 7 in between are nulled as well).
    ridge
        Pull towards equal weights, relative to the harmonics' size: 1e-3 keeps the fit
        determined when channels and orders are many and costs nothing measurable where
        they are not. Not tuned.
    """

    name = "gain-tuned"
    description = ("per-channel gains fitted on the calibration log to null wave-generator orders 1-8 "
                   "(Godler et al. 2001; US 6,840,118), then a software method on the compensated sum "
                   "(then=raw, max_order=8, ridge=0.001)")
    #: nothing to tune: the gains are fitted on the calibration log; the inner method's own
    #: defaults are its tuning record's
    tunable = {}

    def __init__(self, then: str = "raw", max_order: int = 8, ridge: float = 1e-3):
        self.then = then
        self.max_order = max_order
        self.ridge = ridge

    def fit(self, calibration):
        self.weights_ = None
        if calibration.channels is not None and calibration.channels.shape[1] > 1:
            self.weights_ = tuned_weights(*tick_means(calibration), self.max_order, self.ridge)
        self.inner_ = inner_method(self.then)
        self.inner_.fit(compensated(calibration, self.weights_))

    def reset(self, spec):
        super().reset(spec)
        self.inner_.reset(spec)

    def step(self, block):
        return self.inner_.step(compensated(block, self.weights_))

"""Gauges on the flexspline: the wave generator's ripple field, read by sensing elements at
their angles with their own placement, orientation and gain errors (the paper's eq. (1)-(5)).

The wave generator's ellipse turns inside the flexspline and drags a deformation wave round
it. A sensing element at angle ``phi_i`` (two perpendicular gauges read as a half bridge,
Jung et al. 2017, Fig. 1) reads, besides the torque's shear strain ``k_i tau``:

* the wave's **shear** strain, which it reads as it reads the torque (``k_i`` times the
  field ``sum_n (S_n + T_n |tau|) cos(n (theta - phi_i) + psi_n + c_n tau)``): a shear pair
  cannot tell it from torque, and only elements at other angles can cancel it;
* the wave's **normal** strain, which a perfect pair cancels (the paper's eq. (1)) and a real
  one picks up through its gauges' orientation errors and gauge-factor mismatch: ``beta_i``
  times the same harmonics a quarter period on (the shear of a wave is the derivative of
  its displacement along the circumference).

So element ``i`` keeps ``(k_i + j beta_i) exp(-j n phi_i)`` of the field's order ``n``, and a
channel summing elements ``i`` keeps, per unit torque gain,

    G_cn = sum_i (k_i + j beta_i) exp(-j n phi_i) / sum_i k_i          (rippleb.layouts.order_weights)

Its ripple is again a Fourier series in the motor angle with amplitudes affine in ``|tau|``:
``|G_cn| (S_n + T_n |tau|) cos(n theta + psi_n + arg G_cn + c_n tau)``. That is the shape of
:meth:`Device.ripple`, so each channel is the device with its ripple terms replaced
(:func:`channel_devices`) and goes through the same bridge, knobs and ADC as before
(:func:`rippleb.simulator.sensors.strain_bridge`). Every element reads the same shaft
torque ``tau``: the gear's real torque is in every channel alike.

The field's per-device spread, phases and load shifts are the device's drawn ripple terms
(``Device.ripple_*``, per order, over their nominals): the deployment conditions that age or
redraw them (``aged``, ``re-assembled``) act on the field as they acted on the ripple. The
gauges' errors come from their own stream (``conditions.stream(seed, "gauges", layout)``), so
the gauge model changes nothing else of a device, and a re-assembled joint (drive swapped or
gauges re-bonded) draws them again. Sizes and sources: docs/physics.md, "Gauges on the
flexspline".
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from rippleb.layouts import GaugeSettings, Layout, order_weights
from rippleb.simulator.scenario import REFERENCE_TEMPERATURE_C
from rippleb.simulator.conditions import stream
from rippleb.simulator.device import RIPPLE_ORDERS

#: The ripple field one sensing element reads, per order of the wave-generator angle:
#: ``(order, base [Nm], per Nm of |tau|)``, in torque units of the element's own gain.
#: **Estimate**: no source gives one element's ripple; these are the sizes with which the
#: paper's layout and the documented gauge errors read the documented bridge amplitudes
#: (docs/physics.md, "Strain bridge") on average over devices: the paper's two elements
#: keep ``|G_n|`` = 0.71 of order 1, 1.00 of orders 4 and 8, and on average 0.041 of order
#: 2 and 0.071 of order 6 (``tests/test_flexspline.py`` measures both). Order 2, the
#: ellipse's own, is the field's largest by far, as a single element shows it.
FIELD_ORDERS = (
    (1, 0.071, 0.0028),
    (2, 6.0, 0.29),
    (4, 0.60, 0.035),
    (6, 0.71, 0.042),
    (8, 0.15, 0.008),
)
#: Sigma of an element's angle on the circumference [rad]. **Estimate**: 1 deg, half a
#: millimetre of a marked position at the flexspline's 25-30 mm radius; Godler et al. (IEEE
#: TIM 2001) and Schuller et al. (Front. Robot. AI 2024) name this error as the ripple's
#: cause but give no size.
PLACEMENT_SIGMA = np.radians(1.0)
#: Sigma of one gauge's orientation error [rad]. **Estimate**: 1 deg; the NACA study of
#: misaligned rosette grids (DTIC ADA801368) works with +-2 deg, taken as 2 sigma.
ORIENTATION_SIGMA = np.radians(1.0)
#: Sigma of one gauge's gauge factor, relative: foil gauges of one lot are specified to +-1 %
#: (taken as 2 sigma; HBM and Vishay Micro-Measurements datasheets).
GAUGE_FACTOR_SIGMA = 0.005
#: Sigma of ``beta``, an element's pick-up of the normal strain per unit of the shear field:
#: ``2 (delta_1 + delta_2)`` from the pair's orientation errors (Vishay TN-511: a gauge
#: turned by ``delta`` off 45 deg reads ``-d sin 2 delta`` of the normal-strain difference
#: ``d``) plus the gauges' gauge-factor mismatch times the mean normal strain, both taken as
#: large as the shear field (estimate).
PICKUP_SIGMA = float(np.sqrt(8.0 * ORIENTATION_SIGMA**2 + 2.0 * GAUGE_FACTOR_SIGMA**2))
#: Sigma of an element's torque sensitivity, relative. **Estimate**: gauge factor, bond
#: thickness and the radius it sits at (shear on a diaphragm falls as ``1 / r^2``: 0.3 mm
#: at 20 mm is 3 %).
ELEMENT_GAIN_SIGMA = 0.03
#: Sigma of an element's sensitivity change per kelvin [1/K], against the others.
#: **Estimate**: foil gauge factors change by about 1e-4 /K; gauges of one lot and their
#: bonds differ by a fifth of that.
ELEMENT_TC_SIGMA = 2.0e-5
#: Per channel of a layout with several, beside the device's own (the amplifier board's):
#: bridge zero [V], its thermal shift [V/K] and drift [V/s], sigmas as the device's one
#: bridge (docs/physics.md, "Strain bridge").
CHANNEL_ZERO_SIGMA, CHANNEL_ZERO_TC_SIGMA, CHANNEL_DRIFT_SIGMA = 0.05, 5.0e-4, 1.0e-3


@dataclass(frozen=True)
class GaugeErrors:
    """The installation errors of one layout's elements (per element) and its channels.

    Attributes
    ----------
    placement
        Angle error of each element [rad].
    pickup
        ``beta`` of each element: normal strain read per unit of the shear field.
    gain
        Relative torque-sensitivity error of each element (``k_i - 1``).
    gain_tc
        Relative sensitivity change of each element per kelvin from 25 degC [1/K].
    zero, zero_tc, drift
        Per channel: bridge zero [V], its thermal shift [V/K], drift [V/s].
    """

    placement: np.ndarray
    pickup: np.ndarray
    gain: np.ndarray
    gain_tc: np.ndarray
    zero: np.ndarray
    zero_tc: np.ndarray
    drift: np.ndarray

    @classmethod
    def draw(cls, seed: int, lay: Layout, scale: float = 1.0, rebonded: bool = False) -> "GaugeErrors":
        """The errors of ``lay`` on the device of ``seed``, ``scale`` times the documented
        sizes; ``rebonded``: the gauges of a re-assembled joint, drawn anew. The draws do not
        depend on ``scale``, so a sweep of it moves one installation further along one
        direction."""
        words = ("gauges", lay.name) + (("re-assembled",) if rebonded else ())
        rng = stream(seed, *words)
        n, c = lay.elements, lay.amplifiers
        unit = rng.standard_normal((4, n))
        channel = rng.standard_normal((3, c))
        return cls(placement=scale * PLACEMENT_SIGMA * unit[0], pickup=scale * PICKUP_SIGMA * unit[1],
                   gain=scale * ELEMENT_GAIN_SIGMA * unit[2], gain_tc=scale * ELEMENT_TC_SIGMA * unit[3],
                   zero=CHANNEL_ZERO_SIGMA * channel[0], zero_tc=CHANNEL_ZERO_TC_SIGMA * channel[1],
                   drift=CHANNEL_DRIFT_SIGMA * channel[2])

    @classmethod
    def perfect(cls, lay: Layout) -> "GaugeErrors":
        zeros = np.zeros(lay.elements)
        channel = np.zeros(lay.amplifiers)
        return cls(zeros, zeros, zeros, zeros, channel, channel, channel)


def element_gains(errors: GaugeErrors, temperature_c: float) -> np.ndarray:
    """``k_i`` of each element at the gauges' temperature [degC]."""
    return (1.0 + errors.gain) * (1.0 + errors.gain_tc * (temperature_c - REFERENCE_TEMPERATURE_C))


def channel_weights(lay: Layout, errors: GaugeErrors, orders, temperature_c: float) -> tuple[np.ndarray, np.ndarray]:
    """``(G, K)``: ``G[c, n]`` the share of the field's order ``orders[n]`` channel ``c``
    reads per unit of its torque gain, ``K[c]`` that torque gain over the channels' mean."""
    k = element_gains(errors, temperature_c)
    angles = lay.angles + errors.placement
    sensitivity = k + 1j * errors.pickup
    members = np.asarray(lay.channels)
    weights, gains = [], []
    for c in range(lay.amplifiers):
        mine = members == c
        gains.append(k[mine].sum())
        weights.append(order_weights(angles[mine], sensitivity[mine], orders) / gains[-1])
    gains = np.asarray(gains)
    return np.array(weights), gains / gains.mean()


def field(device) -> tuple[tuple[int, ...], np.ndarray, np.ndarray]:
    """``(orders, S, T)``: the per-element field of ``device`` (:data:`FIELD_ORDERS` times the
    device's drawn spread of each order over its nominal; an order the field does not list
    keeps the drawn amplitude)."""
    nominal = {o: (a, b) for o, a, b in RIPPLE_ORDERS}
    sizes = {o: (a, b) for o, a, b in FIELD_ORDERS}
    base, load = [], []
    for order, a, b in zip(device.ripple_orders, device.ripple_base, device.ripple_load):
        (a0, b0), (s, t) = nominal.get(order, (1.0, 1.0)), sizes.get(order, (1.0, 1.0))
        base.append(s * a / a0)
        load.append(t * b / b0)
    return tuple(device.ripple_orders), np.array(base), np.array(load)


def channel_devices(device, settings: GaugeSettings, temperature_c: float, rebonded: bool = False) -> list:
    """One :class:`~rippleb.simulator.device.Device` per channel of the layout: ``device``
    with the ripple the channel reads and, with several channels, each channel's own zero
    and drift. ``[device]`` itself for ``drawn``."""
    lay = settings.resolved()
    if not lay.geometric:
        return [device]
    errors = GaugeErrors.draw(device.seed, lay, settings.misalignment, rebonded)
    orders, base, load = field(device)
    weights, gains = channel_weights(lay, errors, orders, temperature_c)
    out = []
    for c in range(lay.amplifiers):
        size = np.abs(weights[c])
        replaced = dict(ripple_base=tuple(size * base), ripple_load=tuple(size * load),
                        ripple_phase=tuple(np.asarray(device.ripple_phase) + np.angle(weights[c])))
        if lay.amplifiers > 1:
            # each bridge's own imbalance and drift beside what the board shares (and ages)
            replaced.update(gain=device.gain * gains[c], offset=device.offset + float(errors.zero[c]),
                            offset_temp_coeff=device.offset_temp_coeff + float(errors.zero_tc[c]),
                            drift_rate=device.drift_rate + float(errors.drift[c]))
        out.append(dataclasses.replace(device, **replaced))
    return out


__all__ = ["FIELD_ORDERS", "GaugeErrors", "channel_devices", "channel_weights", "element_gains", "field"]

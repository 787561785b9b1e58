"""Strain-gauge layouts on the flexspline: where the sensing elements sit and how they are read.

A *sensing element* is the paper's pair of perpendicular gauges at one angle of the
flexspline (Jung et al. 2017, Fig. 1 and eq. (1)): read as a half bridge, it gives the
torque's shear strain and cancels the normal ("radial") strain of the wave generator's
ellipse up to its gauges' errors. A *layout* puts elements at angles ``phi_i`` and wires
them into amplifier *channels*; the log's ``strain`` is the mean of the channels (the
bridge itself for a one-channel layout), and a layout with several channels also logs each
one (``SensorLog.channels``).

The worked relation every layout follows (docs/physics.md, "Gauges on the flexspline"): an
element at ``phi_i`` reads the wave generator's ripple field at ``theta - phi_i``, so a sum
with weights ``g_i`` keeps ``sum_i g_i exp(-j n phi_i)`` of the field's order ``n``
(:func:`order_weights`). Two elements 90 degrees apart cancel orders 2 and 6 and add 4 and
8: the paper's own reason for its Fig. 2. The physics of one device (its field and its
gauges' errors) is :mod:`rippleb.simulator.flexspline`.

A scenario picks a layout in its ``[gauges]`` table (:class:`GaugeSettings`); ``rippleb
sweep --param gauges.layout=...`` makes it a dimension of a run.

Examples
--------
>>> from rippleb.layouts import layout, cancelled_orders
>>> paper = layout("paper")
>>> paper.gauges, paper.amplifiers
(4, 1)
>>> cancelled_orders(paper, (1, 2, 4, 6, 8))
(2, 6)
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: Rings of ``2n + 1`` elements, one channel each: ``n`` = 1 (Godler et al.'s three gauges)
#: to 4 (enough to null orders 2, 4, 6 and 8 by gain tuning).
RING_SIZES = (3, 5, 7, 9)
#: Every layout, in a fixed order: a sweep stores a layout as its position here, so names
#: are only ever appended.
LAYOUT_NAMES = ("paper", "paper-channels", "rosettes-4") + tuple(f"ring-{n}" for n in RING_SIZES) + ("drawn",)
DEFAULT_LAYOUT = "paper"
#: Gauges per sensing element: the paper's two perpendicular gauges.
GAUGES_PER_ELEMENT = 2
#: The largest multiple of the documented gauge errors a scenario may ask for.
MAX_MISALIGNMENT = 10.0


@dataclass(frozen=True)
class Layout:
    """One layout: the nominal angle of each sensing element and the channel it is wired to.

    Attributes
    ----------
    name
        One of :data:`LAYOUT_NAMES`.
    angles_deg
        Nominal angle of each element on the flexspline [deg]; empty for ``drawn``.
    channels
        The amplifier channel (0, 1, ...) of each element.
    summary, source
        One line each for ``rippleb list`` and the report.
    """

    name: str
    angles_deg: tuple[float, ...]
    channels: tuple[int, ...]
    summary: str
    source: str

    @property
    def elements(self) -> int:
        return len(self.angles_deg)

    @property
    def gauges(self) -> int:
        """Strain gauges bonded: two per element (``drawn``, without geometry, stands for the
        paper's bridge of four)."""
        return GAUGES_PER_ELEMENT * self.elements or GAUGES_PER_ELEMENT * 2

    @property
    def amplifiers(self) -> int:
        """Amplifier (and ADC) channels: one per bridge."""
        return max(self.channels) + 1 if self.channels else 1

    @property
    def geometric(self) -> bool:
        """False for ``drawn``, the earlier simulator's series without geometry."""
        return bool(self.angles_deg)

    @property
    def angles(self) -> np.ndarray:
        return np.radians(np.asarray(self.angles_deg, float))


def layout(name: str) -> Layout:
    """The layout ``name`` (one of :data:`LAYOUT_NAMES`)."""
    if name not in LAYOUT_NAMES:
        raise ValueError(f"unknown gauge layout {name!r}; known: {', '.join(LAYOUT_NAMES)}")
    if name == "paper":
        return Layout(name, (0.0, 90.0), (0, 0),
                      "two sensing elements 90 deg apart in one full bridge (the default)",
                      "Jung et al., IEEE/ASME TMECH 22(4) 2017, Fig. 1 and eq. (2)")
    if name == "paper-channels":
        return Layout(name, (0.0, 90.0), (0, 1),
                      "the paper's two elements, each its own half bridge and amplifier, for gain tuning",
                      "Jung et al. 2017's gauges read as Godler et al.'s separate channels "
                      "(IEEE TIM 50(1) 2001; US 6,840,118)")
    if name == "rosettes-4":
        return Layout(name, (0.0, 90.0, 180.0, 270.0), (0, 0, 0, 0),
                      "four sensing elements 90 deg apart in one bridge",
                      "Taghirad & Belanger, IEEE TIM 47(4) 1998 (four rosettes); Hashimoto et al., "
                      "J. Robot. Mechatron. 3(4) 1991")
    if name.startswith("ring-"):
        n = int(name[5:])
        return Layout(name, tuple(360.0 * i / n for i in range(n)), tuple(range(n)),
                      f"{n} sensing elements equally spaced, each its own amplifier channel: "
                      f"gain tuning nulls {(n - 1) // 2} order(s)",
                      ("Godler, Ninomiya & Horiuchi, AMC 2000 (three gauges); " if n == 3 else "")
                      + "Godler, Horiuchi & Hashimoto, US 6,840,118 (Harmonic Drive Systems: 2n+1 "
                      "gauges null n orders)")
    return Layout(name, (), (), "the earlier simulator's bridge: a Fourier series drawn per device, "
                  "no geometry (kept to compare)", "rippleb before issue 42 (docs/physics.md)")


def order_weights(angles: np.ndarray, sensitivity: np.ndarray, orders) -> np.ndarray:
    """``sum_i g_i exp(-j n phi_i)`` for each order ``n``: the share of a field's order ``n``
    that elements at ``angles`` [rad] read with (complex) weights ``sensitivity`` keep."""
    phase = np.exp(-1j * np.outer(np.asarray(orders, float), np.asarray(angles, float)))
    return phase @ np.asarray(sensitivity, complex)


def cancelled_orders(lay: Layout, orders) -> tuple[int, ...]:
    """The orders the equal-gain sum of ``lay``'s perfectly placed elements cancels."""
    if not lay.geometric:
        return ()
    weights = order_weights(lay.angles, np.ones(lay.elements), orders) / lay.elements
    return tuple(int(n) for n, w in zip(orders, weights) if abs(w) < 1e-9)


@dataclass(frozen=True)
class GaugeSettings:
    """A scenario's ``[gauges]`` table.

    Attributes
    ----------
    layout
        One of :data:`LAYOUT_NAMES` (default :data:`DEFAULT_LAYOUT`).
    misalignment
        The gauges' placement, orientation and gain errors in multiples of the documented
        sizes (docs/physics.md): 0 is a perfect installation, 1 the default.
    """

    layout: str = DEFAULT_LAYOUT
    misalignment: float = 1.0

    def resolved(self) -> Layout:
        return layout(self.layout)


#: Keys of the ``[gauges]`` table and their types (the first named in errors). A layout is
#: a name; a sweep writes it as its position in :data:`LAYOUT_NAMES`, an integer.
GAUGE_KEYS = {"layout": (str, int), "misalignment": (float, int)}


def parse_gauges(raw: dict, fail) -> GaugeSettings:
    """The :class:`GaugeSettings` of a type-checked ``[gauges]`` table; ``fail(key, what)``
    raises the scenario parser's one-line error."""
    name = raw.get("layout", DEFAULT_LAYOUT)
    if isinstance(name, int):
        if not 0 <= name < len(LAYOUT_NAMES):
            fail("gauges.layout", f"layout number {name} is not one of 0..{len(LAYOUT_NAMES) - 1} "
                 f"({', '.join(LAYOUT_NAMES)})")
        name = LAYOUT_NAMES[name]
    if name not in LAYOUT_NAMES:
        fail("gauges.layout", f"unknown layout {name!r}; known: {', '.join(LAYOUT_NAMES)}")
    misalignment = float(raw.get("misalignment", 1.0))
    if not 0.0 <= misalignment <= MAX_MISALIGNMENT:
        fail("gauges.misalignment", f"must be within [0, {MAX_MISALIGNMENT:g}] (multiples of the "
             f"documented gauge errors), got {misalignment:g}")
    return GaugeSettings(layout=name, misalignment=misalignment)


__all__ = ["DEFAULT_LAYOUT", "GAUGE_KEYS", "GaugeSettings", "LAYOUT_NAMES", "Layout", "cancelled_orders",
           "layout", "order_weights", "parse_gauges"]

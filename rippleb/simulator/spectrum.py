"""The strain's order spectrum across wave-generator speeds: the paper's Fig. 2, measured.

Jung et al. (TMECH 2017, Sec. II-B and Fig. 2) re-sample the strain of a real joint at its
encoder's positions and find, at every wave-generator speed they ran, the largest line at
order 4 (two sensing elements x the two lobes of the wave generator) and clear lines at
orders 2 and 8. That is the one observation of a real joint the benchmark has; this module
measures the same thing on a simulated log, so a test can hold the simulator to it and
``rippleb report`` can draw it over the device population (docs/physics.md, "The strain's
order spectrum: the paper's Fig. 2").

The measurement uses what a lab records, the strain and the encoder count, nothing of the
simulator's truth: the strain is re-sampled where the count first reaches each new position
(order tracking, as the paper does), cut into windows of whole wave-generator revolutions
in one direction of motion, and in each window the amplitude of every order is a least-
squares fit of ``cos(k theta)``, ``sin(k theta)`` beside a quadratic in the angle, which
takes up the torque's slow change within the window (gravity over 0.13 rad of the joint).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: Orders of the wave-generator angle measured: 1 to 10.
ORDERS = tuple(range(1, 11))
#: Bands of wave-generator speed [rev/s], from creep to the built-ins' top (19 rev/s on
#: ``speed-sweep``; ``paper-quintic`` peaks at 10.7 rev/s).
SPEED_BANDS = ((1.0, 3.0), (3.0, 6.0), (6.0, 10.0), (10.0, 15.0), (15.0, 20.0))
#: Wave-generator revolutions per window: orders are integers, so one revolution resolves
#: them; two halve the leak of what is not periodic per turn (output-locked ripple, noise).
REVOLUTIONS = 2
#: The direction of motion is the sign of the count's change over this time [s]: long
#: enough that the loop's count jitter at a stop does not split a run.
DIRECTION_S = 0.02
#: The scenarios of the population test and figure: a speed sweep and the paper's own move.
SCENARIOS = ("speed-sweep", "paper-quintic")


@dataclass(frozen=True)
class OrderWindows:
    """The order amplitudes of one log, window by window.

    Attributes
    ----------
    speed
        Mean wave-generator speed of each window [rev/s].
    amplitude
        ``(windows, len(orders))``: the strain's amplitude at each order [V].
    orders
        The orders of the columns.
    """

    speed: np.ndarray
    amplitude: np.ndarray
    orders: tuple[int, ...] = ORDERS

    def bands(self, bands=SPEED_BANDS) -> np.ndarray:
        """``(len(bands), len(orders))``: the mean amplitude of each order over the windows
        whose speed lies in each band ``[lo, hi)`` (NaN for a band without a window)."""
        out = np.full((len(bands), len(self.orders)), np.nan)
        for i, (lo, hi) in enumerate(bands):
            inside = (self.speed >= lo) & (self.speed < hi)
            if inside.any():
                out[i] = self.amplitude[inside].mean(axis=0)
        return out


def order_windows(log, orders=ORDERS, revolutions: int = REVOLUTIONS) -> OrderWindows:
    """The strain's order amplitudes of ``log`` (a :class:`~rippleb.data.SensorLog`) in
    windows of ``revolutions`` wave-generator turns, from its strain and encoder alone."""
    cpr = log.spec.counts_per_rev
    counts = np.asarray(log.encoder, float)
    lag = max(1, int(round(DIRECTION_S * log.spec.fs)))
    direction = np.zeros(len(counts))
    direction[lag:] = np.sign(counts[lag:] - counts[:-lag])
    changes = np.flatnonzero(np.diff(direction)) + 1
    speeds, amplitudes = [], []
    for lo, hi in zip(np.r_[0, changes], np.r_[changes, len(counts)]):
        if direction[lo] == 0:
            continue
        sign = direction[lo]
        reached = np.maximum.accumulate(sign * counts[lo:hi])    # counts in the run's direction
        first = np.flatnonzero(np.diff(reached) > 0) + 1          # where each new count is reached
        if len(first) < 2:
            continue
        # every count of the run once, at the sample that first reached it (order tracking);
        # a count the DAQ skipped is interpolated
        grid = np.arange(reached[first[0]], reached[first[-1]] + 1)
        strain = np.interp(grid, reached[first], log.strain[lo:hi][first])
        times = np.interp(grid, reached[first], log.t[lo:hi][first])
        size = revolutions * cpr
        for start in range(0, len(grid) - size + 1, size):
            window = slice(start, start + size)
            theta = sign * 2.0 * np.pi * grid[window] / cpr
            speeds.append(revolutions / (times[window][-1] - times[window][0]))
            amplitudes.append(_amplitudes(strain[window], theta, orders))
    return OrderWindows(np.array(speeds), np.array(amplitudes).reshape(-1, len(orders)), tuple(orders))


def _amplitudes(values: np.ndarray, theta: np.ndarray, orders) -> np.ndarray:
    """Least-squares amplitude of each order in ``values`` over the angles ``theta``, beside
    a quadratic in the angle (the torque's slow change)."""
    x = (theta - theta.mean()) / np.ptp(theta)
    columns = [np.ones_like(x), x, x * x]
    for k in orders:
        columns += [np.cos(k * theta), np.sin(k * theta)]
    coef = np.linalg.lstsq(np.column_stack(columns), values, rcond=None)[0]
    return np.hypot(coef[3::2], coef[4::2])


def case_bands(seed: int, scenario, condition: str = "same-session", bands=SPEED_BANDS) -> np.ndarray:
    """``(len(bands), len(ORDERS))``: the band amplitudes [V] of the device of ``seed`` on
    ``scenario`` (a name or a :class:`~rippleb.simulator.scenario.Scenario`) under ``condition``."""
    from rippleb.simulator.simulation import simulate

    return order_windows(simulate(scenario, seed, condition).log).bands(bands)


def largest_order(band_amplitudes: np.ndarray) -> np.ndarray:
    """The order of the largest line per band (0 where the band has no window)."""
    out = np.zeros(len(band_amplitudes), int)
    seen = ~np.isnan(band_amplitudes).all(axis=1)
    out[seen] = np.array(ORDERS)[np.nanargmax(band_amplitudes[seen], axis=1)]
    return out


def order4_fraction(cases: np.ndarray) -> np.ndarray:
    """Per band, the fraction of the cases (``(cases, bands, orders)`` amplitudes, a case a
    device on one scenario) whose largest line is order 4, among those with a window in the
    band (NaN if none has)."""
    tops = np.array([largest_order(bands) for bands in cases])
    seen = (tops > 0).sum(axis=0)
    with np.errstate(invalid="ignore"):
        return np.where(seen > 0, (tops == 4).sum(axis=0) / np.maximum(seen, 1), np.nan)

"""``order-tracking``: the paper's method (Jung et al., TMECH 2017, Sec. III and IV-A).

The strain is re-sampled at the fixed encoder positions (``counts_per_rev`` per motor
revolution), where the torque ripple sits at fixed orders 2, 4 and 8 whatever the
speed; fixed notch filters remove those orders; the latest filtered value is held
back onto the DAQ grid and scaled by the gain and offset fitted on the calibration log.

Two mechanisms handle the stops the paper calls the *dead zone*:

- **dead-zone switching**: when no encoder position has been crossed for
  ``stop_after_s``, the output switches to the raw strain plus the offset
  ``filtered - raw`` measured at the last crossing (the ripple frozen at the stop);
  it switches back at the next crossing;
- **back propagation**: the last revolution of order samples is kept in a table
  indexed by position, frozen during the stop; at the first crossing after a stop the
  filter state is rebuilt from that revolution, so the notches know the ripple phase
  and amplitude at once instead of learning them again over several revolutions.

``order-tracking-no-deadzone`` holds the last filtered value during stops;
``order-tracking-no-backprop`` restarts the filter after each stop in steady state on
the first new sample (the best naive state, docs/design.md). Everything else is shared.

See ``docs/methods/order-tracking.md`` for every parameter and how it was chosen.
"""

from __future__ import annotations

import numpy as np
from numba import types
from scipy.signal import iirnotch

from rippleb.dsp import F8, IN_F8, IN_F8_2D, IN_I8, biquad_ss, compiled, fit_gain_offset, series_ss
from rippleb.method import Method

# Absolute sample index meaning "no crossing yet": far enough back to count as a stop.
_NEVER = -(1 << 62)


def design_notches(orders, q: float, counts_per_rev: int) -> list[tuple[np.ndarray, np.ndarray]]:
    """One second-order notch ``(b, a)`` per ripple order, in the angle domain.

    Parameters
    ----------
    orders
        Ripple orders (cycles per motor revolution) to remove.
    q
        Quality factor ``order / (-3 dB width in orders)`` of every notch.
    counts_per_rev
        Order samples per motor revolution: the "sample rate" of the angle domain.
    """
    return [iirnotch(order, q, fs=counts_per_rev) for order in orders]


def crossings(encoder: np.ndarray, strain: np.ndarray, prev_encoder: int, prev_strain: float):
    """Encoder position crossings between consecutive DAQ samples, with the strain there.

    The definition the streaming loop (:func:`track`) follows crossing by crossing, as
    a whole-array function for analysing logs.

    Between sample ``i - 1`` and sample ``i`` the count changes by ``m``; the ``m``
    crossed position boundaries are placed at the fractions ``(j + 1/2) / m``,
    ``j = 0 .. m-1`` of the interval, i.e. the shaft is assumed to move uniformly from the
    centre of the first count to the centre of the last. The strain is interpolated
    linearly in time there. The boundary between counts ``c - 1`` and ``c`` is labelled
    ``c`` in both directions, so a reversal re-visits the same label.

    Parameters
    ----------
    encoder, strain
        The samples of one block.
    prev_encoder, prev_strain
        The sample just before the block.

    Returns
    -------
    sample
        Index in the block of the sample at which each crossing becomes known.
    label
        Position boundary crossed (integer count).
    direction
        +1 or -1.
    value
        Interpolated strain at the crossing.
    """
    e = np.concatenate(([prev_encoder], encoder)).astype(np.int64)
    s = np.concatenate(([prev_strain], strain)).astype(float)
    return _crossings(e, s, np.diff(e))


def _crossings(e, s, de):
    """:func:`crossings` on the arrays extended by the previous sample, ``de = diff(e)``."""
    moved = np.flatnonzero(de)
    m = np.abs(de[moved])
    sample = np.repeat(moved, m)
    j = np.arange(len(sample)) - np.repeat(np.cumsum(m) - m, m)
    frac = (j + 0.5) / np.repeat(m, m)
    value = s[sample] + frac * (s[sample + 1] - s[sample])
    direction = np.repeat(np.sign(de[moved]), m)
    # Forward from count c the boundaries c+1, c+2, ...; backward c, c-1, ...
    label = np.repeat(e[moved], m) + np.where(direction > 0, j + 1, -j)
    return sample, label, direction, value


@compiled(types.float64(IN_F8_2D, F8, types.float64))
def notch(sections, state, x):
    """One order sample through the second-order ``sections`` in series; the output.

    Transposed direct form II, ``state`` (2 per section) updated in place in
    ``lfilter``'s ``zi`` convention.
    """
    for j in range(sections.shape[0]):
        b0, b1, b2, a1, a2 = (sections[j, 0], sections[j, 1], sections[j, 2], sections[j, 4],
                              sections[j, 5])
        y = b0 * x + state[2 * j]
        state[2 * j] = b1 * x - a1 * y + state[2 * j + 1]
        state[2 * j + 1] = b2 * x - a2 * y
        x = y
    return x


@compiled(types.void(IN_F8_2D, IN_F8, IN_F8, types.float64, types.int64, types.int64, F8))
def periodic_state(periodic, unit_state, table, x_new, label, direction, state):
    """Into ``state``: the filter having seen the saved revolution infinitely often.

    ``periodic.T @ history`` with ``history`` the table rotated to lead up to ``label``
    in ``direction`` (:meth:`OrderTracking.history`), indexed in place instead of built,
    plus the steady state of the level change ``x_new - table[label]``.
    """
    n = len(table)
    here = label % n
    level = x_new - table[here]
    for r in range(len(state)):
        state[r] = unit_state[r] * level
    position = here
    for c in range(n):
        value = table[position]
        for r in range(len(state)):
            state[r] += periodic[c, r] * value
        position += direction
        if position == n:
            position = 0
        elif position < 0:
            position = n - 1


@compiled(types.void(IN_I8, IN_F8, IN_F8_2D, IN_F8, IN_F8_2D, types.int64, types.boolean,
                     types.boolean, F8, F8, types.boolean[:], types.int64[:], F8, F8))
def track(encoder, strain, sections, unit_state, periodic, stop_samples, dead_zone,
          back_propagation, state, table, seen, counters, levels, out):
    """The ripple-free strain per sample of one block: re-sample, notch, hold, switch.

    Sample by sample: each encoder boundary crossed since the previous sample (placed as
    in :func:`crossings`) gives one order sample, the strain interpolated there; a
    crossing more than ``stop_samples`` after the previous one is a restart and first
    rebuilds the filter ``state`` (:func:`periodic_state` once ``table`` holds a whole
    revolution and ``back_propagation`` is on, else the steady state); the order sample
    goes through the notches and what they removed is kept in ``table``. The output is
    the latest filtered value, or with ``dead_zone`` after ``stop_samples`` without a
    crossing the raw strain plus the offset ``filtered - raw`` of the last crossing;
    before the first crossing, the raw strain.

    Parameters
    ----------
    counters
        ``previous count, absolute index of the block's first sample, absolute index of
        the last crossing sample, positions seen``; updated in place.
    levels
        ``previous strain, filtered strain and filtered - raw at the last crossing``;
        updated in place.
    state, table, seen
        Notch state, ripple removed at each position, positions seen; updated in place.
    out
        The filtered strain [V] per sample.
    """
    n = len(table)
    prev_count, start, last_cross, n_seen = counters[0], counters[1], counters[2], counters[3]
    prev_strain, y_last, offset_last = levels[0], levels[1], levels[2]
    for i in range(len(encoder)):
        count, value = encoder[i], strain[i]
        step = count - prev_count
        if step != 0:
            m, direction = abs(step), (1 if step > 0 else -1)
            restart = start + i - last_cross > stop_samples
            for j in range(m):
                # forward from count c the boundaries c+1, c+2, ...; backward c, c-1, ...
                label = prev_count + (j + 1 if direction > 0 else -j)
                x = prev_strain + (j + 0.5) / m * (value - prev_strain)
                if j == 0 and restart:
                    if back_propagation and n_seen == n:
                        periodic_state(periodic, unit_state, table, x, label, direction, state)
                    else:
                        for r in range(len(state)):
                            state[r] = unit_state[r] * x
                y = notch(sections, state, x)
                here = label % n
                table[here] = x - y
                if not seen[here]:
                    seen[here] = True
                    n_seen += 1
            last_cross = start + i
            y_last, offset_last = y, y - x
        if last_cross == _NEVER:
            out[i] = value
        elif dead_zone and start + i - last_cross >= stop_samples:
            out[i] = value + offset_last
        else:
            out[i] = y_last
        prev_count, prev_strain = count, value
    counters[0], counters[1], counters[2], counters[3] = prev_count, start + len(encoder), \
        last_cross, n_seen
    levels[0], levels[1], levels[2] = prev_strain, y_last, offset_last


class OrderTracking(Method):
    """Order tracking with dead-zone switching and back propagation.

    Parameters
    ----------
    q
        Quality factor of the three notches (centre order over -3 dB width). Chosen on the
        ``calibration`` scenario only (docs/methods/order-tracking.md).
    orders
        Ripple orders removed in the angle domain; the paper's Sec. III-A: 2, 4, 8.
    stop_after_s
        Time without any position crossing after which the joint counts as stopped [s]:
        the dead-zone switch, and the restart that triggers back propagation at the next
        crossing. The paper's FPGA uses a trigger timeout (Sec. IV-A); here it is chosen
        on the ``calibration`` scenario.
    dead_zone
        Switch to the offset-compensated raw strain during stops.
    back_propagation
        Rebuild the filter state from the saved revolution at each restart; otherwise
        restart in steady state on the first new order sample.
    """

    name = "order-tracking"
    description = ("the paper: strain re-sampled at encoder positions, notches at orders 2, 4, 8 "
                   "(q=30.5), dead zone, back propagation")
    #: ranges of the tuning protocol (rippleb/tuning.py)
    tunable = {"q": (5.0, 50.0, "log"), "stop_after_s": (0.0005, 0.005, "log")}

    def __init__(self, q: float = 30.5, orders: tuple = (2, 4, 8), stop_after_s: float = 0.00394,
                 dead_zone: bool = True, back_propagation: bool = True):
        self.q = q
        self.orders = orders
        self.stop_after_s = stop_after_s
        self.dead_zone = dead_zone
        self.back_propagation = back_propagation

    # -- API ---------------------------------------------------------------------------

    def fit(self, calibration):
        """Fit gain and offset of ``torque_ref`` on the order-filtered strain.

        The fit is on what the method outputs before scaling (not on the raw strain): the
        ripple is already gone there, so the least-squares residual is smaller, and any
        level the filter chain introduces is absorbed.
        """
        self.reset(calibration.spec)
        volts = self.filter_strain(calibration.block(0, len(calibration)))
        self.gain_, self.offset_ = fit_gain_offset(volts, calibration.torque_ref)

    def reset(self, spec):
        """Design the notches for ``spec`` and clear the streaming state."""
        super().reset(spec)
        n = int(spec.counts_per_rev)
        self.sections_ = np.array([np.concatenate([b, a]) for b, a in
                                   design_notches(self.orders, self.q, n)])
        self.stop_samples_ = max(1, int(round(self.stop_after_s * spec.fs)))
        self._design_state_space(n)
        self.zi_ = np.zeros(2 * len(self.sections_))
        self.table_ = np.zeros(n)            # ripple removed at each position (one revolution)
        self.seen_ = np.zeros(n, dtype=bool)
        self.started_ = False
        # previous count, absolute index of the next sample, of the last crossing, positions seen
        self.counters_ = np.array([0, 0, _NEVER, 0], dtype=np.int64)
        # previous strain, filtered strain and filtered - raw at the last crossing
        self.levels_ = np.zeros(3)

    @property
    def full_(self) -> bool:
        """Every position of the revolution seen: back propagation has a whole revolution."""
        return bool(self.counters_[3] == len(self.table_))

    def step(self, block):
        """Torque estimate [Nm] per sample: gain times the filtered strain plus offset.

        Without :meth:`fit` the gain is 1 and the offset 0: the filtered strain in volts.
        """
        gain, offset = getattr(self, "gain_", 1.0), getattr(self, "offset_", 0.0)
        return gain * self.filter_strain(block) + offset

    # -- the strain-domain pipeline ------------------------------------------------------

    def filter_strain(self, block) -> np.ndarray:
        """The ripple-free strain [V] per sample of ``block`` (before gain and offset)."""
        strain = np.asarray(block.strain, dtype=float)
        out = np.empty(len(strain))
        if len(strain) == 0:
            return out
        encoder = np.asarray(block.encoder, dtype=np.int64)
        if not self.started_:          # the first sample: no crossing before it
            self.counters_[0], self.levels_[0] = encoder[0], strain[0]
            self.started_ = True
        track(encoder, strain, self.sections_, self.unit_state_, self.periodic_,
              self.stop_samples_, self.dead_zone, self.back_propagation, self.zi_, self.table_,
              self.seen_, self.counters_, self.levels_, out)
        return out

    def _design_state_space(self, n):
        """The steady state of the notch cascade, and its periodic steady state over one
        revolution, in the cascade's state (``lfilter``'s ``zi`` of each section in turn)."""
        A, B, _, _ = series_ss(*(biquad_ss(s[:3], s[3:]) for s in self.sections_))
        self.unit_state_ = np.linalg.solve(np.eye(len(B)) - A, B)   # steady state, input 1
        # Periodic steady state over one revolution: s = (I - A^n)^-1 sum_k A^(n-1-k) B h_k.
        reach = np.empty((len(B), n))
        column = B.copy()
        for k in range(n - 1, -1, -1):
            reach[:, k] = column
            column = A @ column
        # stored one row per history sample, so a restart reads it in memory order
        self.periodic_ = np.ascontiguousarray(
            np.linalg.solve(np.eye(len(B)) - np.linalg.matrix_power(A, n), reach).T)

    # -- back propagation ---------------------------------------------------------------

    def history(self, x_new, label, direction) -> np.ndarray:
        """The saved revolution, ordered to lead up to the new crossing, at today's level.

        Positions ``label - direction * N .. label - direction``: the revolution behind the
        joint in its new direction of motion (in reverse order after a reversal). The table
        holds the ripple the notches removed there, so adding one level, the torque strain
        of ``x_new`` without its ripple, gives the history of a joint that turned at
        today's torque: the torque may have changed during the stop, the ripple has not.
        """
        n = len(self.table_)
        ripple = self.table_[(label - direction * np.arange(n, 0, -1)) % n]
        return ripple + (x_new - self.table_[label % n])

    def _periodic_state(self, x_new, label, direction):
        """State after running the filter over :meth:`history` repeated for ever
        (:func:`periodic_state`)."""
        state = np.empty(len(self.unit_state_))
        periodic_state(self.periodic_, self.unit_state_, self.table_, float(x_new), int(label),
                       int(direction), state)
        return state


class OrderTrackingNoDeadzone(OrderTracking):
    """Ablation: hold the last filtered value during stops instead of switching to raw."""

    name = "order-tracking-no-deadzone"
    description = ("order-tracking without its dead zone: holds the last filtered value during stops"
                   " (dead_zone=false)")

    def __init__(self, q: float = 30.5, orders: tuple = (2, 4, 8), stop_after_s: float = 0.00394,
                 dead_zone: bool = False, back_propagation: bool = True):
        super().__init__(q=q, orders=orders, stop_after_s=stop_after_s, dead_zone=dead_zone,
                         back_propagation=back_propagation)


class OrderTrackingNoBackprop(OrderTracking):
    """Ablation: restart the filter after a stop in steady state on the first new sample."""

    name = "order-tracking-no-backprop"
    description = ("order-tracking without back propagation: restarts its notches in steady state "
                   "(back_propagation=false)")

    def __init__(self, q: float = 9.77, orders: tuple = (2, 4, 8), stop_after_s: float = 0.00321,
                 dead_zone: bool = True, back_propagation: bool = False):
        super().__init__(q=q, orders=orders, stop_after_s=stop_after_s, dead_zone=dead_zone,
                         back_propagation=back_propagation)

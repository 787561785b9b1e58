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
the first new sample (the best naive state, DESIGN.md). Everything else is shared.

See ``docs/methods/order-tracking.md`` for every parameter and how it was chosen.
"""

from __future__ import annotations

import numpy as np
from scipy.signal import iirnotch, lfilter, lfilter_zi

from rippleb.dsp import fit_gain_offset
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


def cascade(sections, x: np.ndarray, zi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Run ``x`` through the second-order ``sections`` in series, carrying the state.

    One ``lfilter`` call per section is the same transposed direct form II recursion as
    ``sosfilt`` (so just as sound numerically) at about a sixth of its per-call cost.

    Returns
    -------
    y, zf
        The output and the final state, ``zf`` shaped like ``zi`` (sections, 2).
    """
    zf = np.empty_like(zi)
    for k, (b, a) in enumerate(sections):
        x, zf[k] = lfilter(b, a, x, zi=zi[k])
    return x, zf


def steady_state(sections, level: float) -> np.ndarray:
    """Cascade state after the constant input ``level`` for ever (DC gain of a notch is 1)."""
    return np.array([lfilter_zi(b, a) for b, a in sections]) * level


def crossings(encoder: np.ndarray, strain: np.ndarray, prev_encoder: int, prev_strain: float):
    """Encoder position crossings between consecutive DAQ samples, with the strain there.

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
    e = np.concatenate(([prev_encoder], encoder))
    s = np.concatenate(([prev_strain], strain))
    de = np.diff(e)
    m = np.abs(de)
    sample = np.repeat(np.arange(len(de)), m)
    j = np.arange(len(sample)) - np.repeat(np.cumsum(m) - m, m)
    frac = (j + 0.5) / m[sample]
    value = s[sample] + frac * (s[sample + 1] - s[sample])
    direction = np.sign(de)[sample]
    label = e[sample] + np.where(direction > 0, j + 1, -j)
    return sample, label, direction, value


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
        the dead-zone switch and the moment the back-propagation table freezes. The
        paper's FPGA uses a trigger timeout (Sec. IV-A); here it is chosen on the
        ``calibration`` scenario.
    dead_zone
        Switch to the offset-compensated raw strain during stops.
    back_propagation
        Rebuild the filter state from the saved revolution at each restart; otherwise
        restart in steady state on the first new order sample.
    """

    name = "order-tracking"

    def __init__(self, q: float = 10.0, orders: tuple = (2, 4, 8), stop_after_s: float = 0.005,
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
        self.sections_ = design_notches(self.orders, self.q, n)
        self.stop_samples_ = max(1, int(round(self.stop_after_s * spec.fs)))
        self.periodic_solver_ = self._periodic_solver(n)
        self.zi_ = np.zeros((len(self.sections_), 2))
        self.table_ = np.zeros(n)            # ripple removed at each position (one revolution)
        self.seen_ = np.zeros(n, dtype=bool)
        self.prev_encoder_ = None
        self.prev_strain_ = 0.0
        self.samples_ = 0                    # absolute index of the next sample
        self.last_cross_ = _NEVER            # absolute index of the last crossing sample
        self.y_last_ = 0.0                   # filtered strain at the last crossing
        self.offset_last_ = 0.0              # filtered - raw at the last crossing

    def step(self, block):
        """Torque estimate [Nm] per sample: gain times the filtered strain plus offset."""
        gain, offset = getattr(self, "gain_", 1.0), getattr(self, "offset_", 0.0)
        return gain * self.filter_strain(block) + offset

    # -- the strain-domain pipeline ------------------------------------------------------

    def filter_strain(self, block) -> np.ndarray:
        """The ripple-free strain [V] per sample of ``block`` (before gain and offset)."""
        strain = np.asarray(block.strain, dtype=float)
        encoder = np.asarray(block.encoder, dtype=np.int64)
        n = len(strain)
        if n == 0:
            return np.empty(0)
        if self.prev_encoder_ is None:
            self.prev_encoder_, self.prev_strain_ = int(encoder[0]), float(strain[0])
        here = self.samples_ + np.arange(n)
        if encoder[-1] == self.prev_encoder_ and not np.any(np.diff(encoder)):
            out = self._hold(strain, here, np.full(n, self.last_cross_), None, None, None)
        else:
            out = self._track(strain, encoder, here)
        self.prev_encoder_, self.prev_strain_ = int(encoder[-1]), float(strain[-1])
        self.samples_ += n
        return out

    def _track(self, strain, encoder, here):
        """The general path: re-sample, filter, hold, switch."""
        sample, label, direction, x = crossings(encoder, strain, self.prev_encoder_, self.prev_strain_)
        first = np.flatnonzero(np.diff(sample, prepend=-1))      # first crossing of each sample
        moved = here[sample[first]]
        gaps = np.diff(moved, prepend=self.last_cross_)
        restarts = first[gaps - 1 >= self.stop_samples_]
        y = self._filter(x, label, direction, restarts)
        last_cross = np.full(len(strain), self.last_cross_)
        last_cross[sample[first]] = moved
        last_cross = np.maximum.accumulate(last_cross)
        count = np.searchsorted(sample, np.arange(len(strain)), side="right")  # crossings so far
        out = self._hold(strain, here, last_cross, y, x, count)
        self.last_cross_ = int(moved[-1])
        self.y_last_, self.offset_last_ = float(y[-1]), float(y[-1] - x[-1])
        return out

    def _hold(self, strain, here, last_cross, y, x, count):
        """Latest filtered value per DAQ sample, or raw plus the stop offset in the dead zone."""
        if y is None:
            held = np.full(len(strain), self.y_last_)
            offset = self.offset_last_
        else:
            held = np.concatenate(([self.y_last_], y))[count]
            offset = np.concatenate(([self.offset_last_], y - x))[count]
        never = last_cross == _NEVER
        stopped = (here - last_cross >= self.stop_samples_) if self.dead_zone else never
        # Before the first crossing there is no filtered value: the raw strain is all we have.
        return np.where(stopped, strain + np.where(never, 0.0, offset), held)

    def _filter(self, x, label, direction, restarts):
        """Notch the order samples ``x``, rebuilding the state at each restart index."""
        y = np.empty_like(x)
        start = 0
        for r in list(restarts) + [len(x)]:
            if r > start:
                y[start:r], self.zi_ = cascade(self.sections_, x[start:r], self.zi_)
                self._remember(label[start:r], x[start:r] - y[start:r], direction[start:r])
            if r < len(x):
                self.zi_ = self._restart_state(x[r], int(label[r]), int(direction[r]))
            start = r
        return y

    # -- back propagation ---------------------------------------------------------------

    def _remember(self, label, ripple, direction):
        """Keep the latest ripple estimate (what the notches removed) at each position."""
        n = len(self.table_)
        pos = label % n
        if len(pos) > n or np.any(direction != direction[0]):
            # A reversal revisits positions: keep the last visit (fancy assignment order
            # with repeated indices is not guaranteed by numpy).
            pos, last = np.unique(pos[::-1], return_index=True)
            ripple = ripple[::-1][last]
        self.table_[pos] = ripple
        self.seen_[pos] = True

    def _restart_state(self, x_new, label, direction):
        """Filter state for the first order sample after a stop."""
        if not (self.back_propagation and self.seen_.all()):
            return steady_state(self.sections_, x_new)
        return self._periodic_state(self._history(x_new, label, direction))

    def _history(self, x_new, label, direction):
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

    def _periodic_solver(self, n):
        """Matrix ``(I - Phi)^-1`` where ``Phi`` maps the cascade state over ``n`` zero inputs."""
        size = 2 * len(self.sections_)
        phi = np.empty((size, size))
        zeros = np.zeros(n)
        for k in range(size):
            unit = np.zeros(size)
            unit[k] = 1.0
            _, zf = cascade(self.sections_, zeros, unit.reshape(-1, 2))
            phi[:, k] = zf.ravel()
        return np.linalg.inv(np.eye(size) - phi)

    def _periodic_state(self, history):
        """State after running the filter over ``history`` repeated for ever.

        The ripple is periodic over one revolution, so this is the filter having seen the
        saved revolution infinitely often: ``s = Phi s + g`` with ``g`` the state reached
        from rest over one pass, solved in closed form.
        """
        _, g = cascade(self.sections_, history, np.zeros_like(self.zi_))
        return (self.periodic_solver_ @ g.ravel()).reshape(self.zi_.shape)


class OrderTrackingNoDeadzone(OrderTracking):
    """Ablation: hold the last filtered value during stops instead of switching to raw."""

    name = "order-tracking-no-deadzone"

    def __init__(self, q: float = 10.0, orders: tuple = (2, 4, 8), stop_after_s: float = 0.005,
                 dead_zone: bool = False, back_propagation: bool = True):
        super().__init__(q=q, orders=orders, stop_after_s=stop_after_s, dead_zone=dead_zone,
                         back_propagation=back_propagation)


class OrderTrackingNoBackprop(OrderTracking):
    """Ablation: restart the filter after a stop in steady state on the first new sample."""

    name = "order-tracking-no-backprop"

    def __init__(self, q: float = 10.0, orders: tuple = (2, 4, 8), stop_after_s: float = 0.005,
                 dead_zone: bool = True, back_propagation: bool = False):
        super().__init__(q=q, orders=orders, stop_after_s=stop_after_s, dead_zone=dead_zone,
                         back_propagation=back_propagation)

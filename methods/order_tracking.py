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
from scipy.signal import iirnotch, lfilter

from rippleb.dsp import biquad_ss, fit_gain_offset, lift, series_ss
from rippleb.method import Method

# Absolute sample index meaning "no crossing yet": far enough back to count as a stop.
_NEVER = -(1 << 62)
# Order samples up to which one tick is filtered by two small matrix products (lifted
# state space) instead of one lfilter call per section; longer runs use lfilter.
_LIFT = 128


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

    def __init__(self, q: float = 30.0, orders: tuple = (2, 4, 8), stop_after_s: float = 0.0015,
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
        self._design_state_space(n)
        self.zi_ = np.zeros(2 * len(self.sections_))
        self.table_ = np.zeros(n)            # ripple removed at each position (one revolution)
        self.seen_ = np.zeros(n, dtype=bool)
        self.full_ = False                   # every position of the revolution seen
        self.prev_encoder_ = None
        self.prev_strain_ = 0.0
        self.samples_ = 0                    # absolute index of the next sample
        self.last_cross_ = _NEVER            # absolute index of the last crossing sample
        self.y_last_ = 0.0                   # filtered strain at the last crossing
        self.offset_last_ = 0.0              # filtered - raw at the last crossing

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
        n = len(strain)
        if n == 0:
            return np.empty(0)
        if self.prev_encoder_ is None:
            self.prev_encoder_, self.prev_strain_ = int(block.encoder[0]), float(strain[0])
        e = np.empty(n + 1, dtype=np.int64)
        e[0] = self.prev_encoder_
        e[1:] = block.encoder
        de = e[1:] - e[:-1]
        moved = np.flatnonzero(de)
        out = self._track(strain, e, de, moved) if len(moved) else self._hold(strain)
        self.prev_encoder_, self.prev_strain_ = int(e[-1]), float(strain[-1])
        self.samples_ += n
        return out

    def _hold(self, strain):
        """A block without crossings: hold the last filtered value, or the dead-zone output."""
        n = len(strain)
        out = np.empty(n)
        stop = 0 if self.last_cross_ == _NEVER else (
            self.last_cross_ + self.stop_samples_ - self.samples_ if self.dead_zone else n)
        stop = min(max(stop, 0), n)
        out[:stop] = self.y_last_
        out[stop:] = strain[stop:] + self.offset_last_
        return out

    def _track(self, strain, e, de, moved):
        """A block with crossings: re-sample, filter, hold, switch."""
        s = np.empty(len(strain) + 1)
        s[0] = self.prev_strain_
        s[1:] = strain
        steps = de[moved]
        moving = np.cumsum(de != 0)              # moving samples up to each sample
        # A restart is a crossing after more than stop_samples samples without one.
        restarts = np.flatnonzero(moved[1:] - moved[:-1] > self.stop_samples_) + 1
        if self.samples_ + moved[0] - self.last_cross_ > self.stop_samples_:
            restarts = np.concatenate(([0], restarts))
        if steps.max() <= 1 and steps.min() >= -1:
            # One crossing per moving sample (below fs counts/s): the same formulas as
            # crossings() with m = 1, without its bookkeeping.
            direction, crossed = steps, moving
            label = e[moved] + (steps > 0)
            x = s[moved] + 0.5 * (s[moved + 1] - s[moved])
        else:
            _, label, direction, x = _crossings(e, s, de)
            m = np.abs(steps)
            restarts = (np.cumsum(m) - m)[restarts]       # first crossing of each sample
            crossed = np.cumsum(np.abs(de))
        y = self._filter(x, label, direction, restarts)
        out = self._output(strain, moved, moving, crossed, x, y)
        self.last_cross_ = self.samples_ + int(moved[-1])
        self.y_last_, self.offset_last_ = float(y[-1]), float(y[-1] - x[-1])
        return out

    def _output(self, strain, moved, moving, crossed, x, y):
        """Latest filtered value per DAQ sample, or raw plus the stop offset in the dead zone.

        ``moving`` and ``crossed`` count the moving samples and the crossings up to and
        including each sample.
        """
        held = np.concatenate(([self.y_last_], y))[crossed]
        first_ever = self.last_cross_ == _NEVER
        if not self.dead_zone:
            if first_ever:   # no filtered value yet: the raw strain is all there is
                held[:moved[0]] = strain[:moved[0]]
            return held
        since = np.arange(len(strain)) - np.concatenate(
            ([self.last_cross_ - self.samples_], moved))[moving]
        offset = np.concatenate(([0.0 if first_ever else self.offset_last_], y - x))[crossed]
        return np.where(since >= self.stop_samples_, strain + offset, held)

    def _filter(self, x, label, direction, restarts):
        """Notch the order samples ``x``, rebuilding the state at each restart index."""
        if len(restarts) == 0:   # the usual tick: one run, no restart
            y, self.zi_ = self._run(x, self.zi_)
            self._remember(label, x - y, direction)
            return y
        y = np.empty_like(x)
        start = 0
        for r in list(restarts) + [len(x)]:
            if r > start:
                y[start:r], self.zi_ = self._run(x[start:r], self.zi_)
                self._remember(label[start:r], x[start:r] - y[start:r], direction[start:r])
            if r < len(x):
                self.zi_ = self._restart_state(x[r], int(label[r]), int(direction[r]))
            start = r
        return y

    def _run(self, x, state):
        """Filter ``x`` from ``state``: one lifted matrix product for a tick, ``lfilter`` for
        long runs."""
        m = len(x)
        if m <= _LIFT:
            out = self.lifted_[m] @ np.concatenate((x, state))
            return out[:m], out[m:]
        y, zf = cascade(self.sections_, x, state.reshape(-1, 2))
        return y, zf.ravel()

    def _design_state_space(self, n):
        """State-space forms of the notch cascade: per tick (lifted), and over one revolution.

        The state is the transposed-direct-form-II state of each section in turn, exactly
        ``lfilter``'s ``zi``, so both paths share it.
        """
        A, B, C, D = series_ss(*(biquad_ss(b, a) for b, a in self.sections_))
        O, T, _, R = lift(A, B, C, D, _LIFT)
        # lifted_[m] maps [x (m samples), state] to [y (m samples), next state].
        self.lifted_ = [None]
        power = np.eye(len(B))
        for m in range(1, _LIFT + 1):
            power = A @ power
            self.lifted_.append(np.block([[T[:m, :m], O[:m]], [R[:, _LIFT - m:], power]]))
        self.unit_state_ = np.linalg.solve(np.eye(len(B)) - A, B)   # steady state, input 1
        # Periodic steady state over one revolution: s = (I - A^n)^-1 sum_k A^(n-1-k) B h_k.
        reach = np.empty((len(B), n))
        column = B.copy()
        for k in range(n - 1, -1, -1):
            reach[:, k] = column
            column = A @ column
        self.periodic_ = np.linalg.solve(np.eye(len(B)) - np.linalg.matrix_power(A, n), reach)
        self.periodic_reversed_ = np.ascontiguousarray(self.periodic_[:, ::-1])

    # -- back propagation ---------------------------------------------------------------

    def _remember(self, label, ripple, direction):
        """Keep the latest ripple estimate (what the notches removed) at each position."""
        n = len(self.table_)
        pos = label % n
        # Without a reversal the labels run one by one, all distinct within a revolution.
        if len(pos) > n or abs(int(label[-1]) - int(label[0])) != len(pos) - 1:
            # A reversal revisits positions: keep the last visit (fancy assignment order
            # with repeated indices is not guaranteed by numpy).
            pos, last = np.unique(pos[::-1], return_index=True)
            ripple = ripple[::-1][last]
        self.table_[pos] = ripple
        if not self.full_:
            self.seen_[pos] = True
            self.full_ = bool(self.seen_.all())

    def _restart_state(self, x_new, label, direction):
        """Filter state for the first order sample after a stop."""
        if not (self.back_propagation and self.full_):
            return self.unit_state_ * x_new
        return self._periodic_state(x_new, label, direction)

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
        """State after running the filter over :meth:`history` repeated for ever.

        The ripple is periodic over one revolution, so this is the filter having seen the
        saved revolution infinitely often, in closed form: ``periodic_ @ history``, with the
        rotation of the table to the restart position done by splitting the product instead
        of building the history.
        """
        n, t, L = len(self.table_), self.table_, label % len(self.table_)
        if direction > 0:
            g = self.periodic_
            state = g[:, :n - L] @ t[L:] + g[:, n - L:] @ t[:L]
        else:
            g = self.periodic_reversed_
            state = g[:, n - 1 - L:] @ t[:L + 1] + g[:, :n - 1 - L] @ t[L + 1:]
        return state + self.unit_state_ * (x_new - t[L])


class OrderTrackingNoDeadzone(OrderTracking):
    """Ablation: hold the last filtered value during stops instead of switching to raw."""

    name = "order-tracking-no-deadzone"

    def __init__(self, q: float = 30.0, orders: tuple = (2, 4, 8), stop_after_s: float = 0.0015,
                 dead_zone: bool = False, back_propagation: bool = True):
        super().__init__(q=q, orders=orders, stop_after_s=stop_after_s, dead_zone=dead_zone,
                         back_propagation=back_propagation)


class OrderTrackingNoBackprop(OrderTracking):
    """Ablation: restart the filter after a stop in steady state on the first new sample."""

    name = "order-tracking-no-backprop"

    def __init__(self, q: float = 30.0, orders: tuple = (2, 4, 8), stop_after_s: float = 0.0015,
                 dead_zone: bool = True, back_propagation: bool = False):
        super().__init__(q=q, orders=orders, stop_after_s=stop_after_s, dead_zone=dead_zone,
                         back_propagation=back_propagation)

"""``switched-notch``: a bank of time-domain notch filters switched by encoder speed.

After Godler et al., whose ripple compensation uses "a set of multiple notch filters that
have partially separated cutoff frequencies" (reference [17] of the paper). The ripple of
order ``k`` sits at ``k`` times the wave-generator rotation frequency ``f``, so it moves
with speed. The bank holds ``n_bands`` bands whose centre speeds ``c_j`` are spaced
geometrically from ``min_speed`` to ``max_speed`` [wave-generator rev/s]; band ``j``
is one filter, the series of second-order notches at ``k * c_j`` for every ``k`` in
``orders``, each of quality factor ``q``. Because all orders scale with the same speed
and the notches have constant Q, the relative mistuning ``f / c_j`` is the same for every
order, so one band index picks the active notch of every order at once.

The encoder speed, measured once per control tick over ``speed_window`` ticks, picks the
band nearest in log-speed; a band is left only when the speed is ``hysteresis`` of a band
spacing beyond the half-way point to its neighbour, so a speed sitting on a band edge
does not chatter. Below the lowest band (half a spacing under ``min_speed``) the strain
passes through unfiltered: there the ripple lies inside the torque band, and a notch
would remove torque as much as ripple. Above the highest band the highest band stays on.

Every band runs all the time (kept warm), so a switch never starts a cold filter: the
whole bank is one block-diagonal linear system advanced once per tick with precomputed
lifted matrices (``x_L = A^L x_0 + R u``, one batched matrix product), and the active
band's output is one more product (``y = O x_0 + T u``). Gain and offset come from a
least-squares fit of the calibration strain to the known torque.

Examples
--------
>>> bank_size(min_speed=1.0, max_speed=50.0, q=4.0, hysteresis=0.2)
221
"""

from __future__ import annotations

import math

import numpy as np
from scipy import signal

from rippleb.data import JointSpec, SensorBlock, SensorLog
from rippleb.dsp import biquad_ss, fit_gain_offset, lift, series_ss, steady_state
from rippleb.method import Method

OFF = -1  # band index of the pass-through state below the lowest band
RESIDUAL = 0.1  # ripple fraction a notch may pass at a switching point (-20 dB)


def band_centres(min_speed: float, max_speed: float, n_bands: int) -> np.ndarray:
    """Geometrically spaced centre speeds [rev/s] of the bank, lowest first."""
    return np.geomspace(min_speed, max_speed, n_bands)


def band_filter(centre: float, orders, q: float, fs: float):
    """State space (A, B, C, D) of one band: notches at ``k * centre`` in series.

    Orders whose notch would reach Nyquist are left out (the ripple there is aliased
    by the DAQ anyway).
    """
    stages = [biquad_ss(*signal.iirnotch(k * centre, q, fs=fs))
              for k in orders if k * centre < 0.45 * fs]
    if not stages:
        return np.zeros((0, 0)), np.zeros(0), np.zeros((1, 0)), np.ones(1)
    return series_ss(*stages)


def bank_size(min_speed: float, max_speed: float, q: float, hysteresis: float,
              residual: float = RESIDUAL) -> int:
    """Fewest bands for which the ripple left at a switching point is at most ``residual``.

    A band is left ``0.5 + hysteresis`` spacings away from its centre, a relative
    mistuning ``delta = (0.5 + hysteresis) * log(spacing)``; a notch of quality ``q``
    passes about ``2 q delta`` of a sinusoid mistuned by ``delta``. Solving
    ``2 q delta <= residual`` for the spacing gives the count.
    """
    delta = residual / (2.0 * q)
    spacing = delta / (0.5 + hysteresis)
    return max(2, int(np.ceil(np.log(max_speed / min_speed) / spacing)) + 1)


def select_band(speed: float, current: int, centres: np.ndarray, hysteresis: float) -> int:
    """The band for ``speed`` [rev/s] given the ``current`` one, with hysteresis.

    In the coordinate ``p = log(speed / c_0) / log(spacing)`` band ``j`` owns
    ``|p - j| <= 0.5``; the current band is kept while ``|p - j| <= 0.5 + hysteresis``.
    ``OFF`` (pass-through) sits at ``p = -1``.
    """
    # scalar math, not numpy: this runs once per control tick
    spacing = math.log(centres[1] / centres[0]) if len(centres) > 1 else math.log(2.0)
    p = math.log(max(speed, 1e-12) / centres[0]) / spacing
    if abs(p - current) <= 0.5 + hysteresis:
        return current
    if current == len(centres) - 1 and p > current:
        return current
    return min(max(round(p), OFF), len(centres) - 1)


class SwitchedNotch(Method):
    """Switched bank of time-domain notch filters (Godler et al.).

    Parameters
    ----------
    orders
        Ripple orders notched, in cycles per wave-generator revolution. The paper's
        dominant orders 2, 4 and 8.
    n_bands
        Number of bands in the bank; None for the fewest that leave at most 10 % of
        the ripple at a switching point (:func:`bank_size`).
    min_speed, max_speed
        Centre speeds of the lowest and highest band [wave-generator rev/s].
    q
        Quality factor of every notch (centre frequency over -3 dB width).
    hysteresis
        Extra band coordinate, as a fraction of the band spacing, the speed must pass
        beyond a band edge before the band switches.
    speed_window
        Control ticks over which the encoder speed is measured (a count difference).

    Where the defaults come from is in ``docs/methods/switched-notch.md``.
    """

    name = "switched-notch"

    def __init__(self, orders=(2, 4, 8), n_bands=None, min_speed=2.0, max_speed=50.0, q=8.0,
                 hysteresis=0.3, speed_window=80):
        self.orders = orders
        self.n_bands = n_bands
        self.min_speed = min_speed
        self.max_speed = max_speed
        self.q = q
        self.hysteresis = hysteresis
        self.speed_window = speed_window

    # -- identification --------------------------------------------------------------
    def fit(self, calibration: SensorLog) -> None:
        """Least-squares gain and offset of the strain against the known torque, and the
        bank designed for the calibration's rate and tick (a device streams at the rate it
        was calibrated at, so ``reset`` then reuses it instead of designing it per run)."""
        self.gain_, self.offset_ = fit_gain_offset(calibration.strain, calibration.torque_ref)
        self.design_ = self._design(calibration.spec)

    # -- streaming -------------------------------------------------------------------
    def reset(self, spec: JointSpec) -> None:
        """Design the bank for ``spec.fs`` (unless ``fit`` did) and clear the streaming state."""
        super().reset(spec)
        if not hasattr(self, "gain_"):
            self.gain_, self.offset_ = 1.0, 0.0
        design = getattr(self, "design_", None)
        if design is None or design["key"] != self._design_key(spec):
            design = self._design(spec)
        for name, value in design.items():
            if name != "key":
                setattr(self, name, value)
        self.lifted_ = dict(self.lifted_)  # lengths met while streaming are this run's own
        self.x0_ = self.x1_ = None    # modal bank state, set by the first sample
        self.band_ = OFF
        self.phase_ = 0               # samples since the last tick boundary
        self.marks_ = []              # encoder counts at the last tick boundaries

    def _design_key(self, spec: JointSpec) -> tuple:
        return (spec.fs, spec.block_size, tuple(sorted(self.get_params().items(), key=str)))

    def _design(self, spec: JointSpec) -> dict:
        """The bank for ``spec``: centres, padded band filters, their modal bases, and the
        lifted matrices of the runner's block length (built before the first tick)."""
        n_bands = self.n_bands or bank_size(self.min_speed, self.max_speed, self.q, self.hysteresis)
        centres = band_centres(self.min_speed, self.max_speed, n_bands)
        bands = [band_filter(c, self.orders, self.q, spec.fs) for c in centres]
        n_states = max(b[0].shape[0] for b in bands)
        self.bands_ = [_pad(b, n_states) for b in bands]
        self.from_modal_ = [modal_basis(b[0]) for b in self.bands_]
        self.to_modal_ = [np.linalg.inv(v) for v in self.from_modal_]
        self.tick_ = spec.block_size
        self.lifted_ = {}
        self._lifted(self.tick_)
        return {"key": self._design_key(spec), "centres_": centres, "n_states_": n_states,
                "bands_": self.bands_, "modes_": n_states // 2, "from_modal_": self.from_modal_,
                "to_modal_": self.to_modal_, "tick_": self.tick_, "lifted_": self.lifted_}

    def step(self, block: SensorBlock) -> np.ndarray:
        """Notch the strain with the active band, segment by segment of the tick grid."""
        u = np.asarray(block.strain, dtype=float)
        if self.x0_ is None and len(u):
            self._start(u[0], int(block.encoder[0]))
        if len(u) == self.tick_ and self.phase_ == 0:     # the runner's case: one segment
            y = self._segment(u)
            self._tick_boundary(int(block.encoder[-1]))
        else:
            y = np.empty_like(u)
            pos = 0
            while pos < len(u):
                m = min(self.tick_ - self.phase_, len(u) - pos)
                y[pos:pos + m] = self._segment(u[pos:pos + m])
                pos += m
                self.phase_ = (self.phase_ + m) % self.tick_
                if self.phase_ == 0:
                    self._tick_boundary(int(block.encoder[pos - 1]))
        return self.gain_ * y + self.offset_

    def _start(self, u0: float, count0: int) -> None:
        """Every band at rest on the first sample, so no filter starts from zero."""
        xi = np.array([ti @ steady_state(A, B, u0)
                       for (A, B, _, _), ti in zip(self.bands_, self.to_modal_)])
        self.x0_ = np.ascontiguousarray(xi[:, 0::2]).ravel()   # first state of each mode
        self.x1_ = np.ascontiguousarray(xi[:, 1::2]).ravel()   # second state of each mode
        self.marks_ = [count0]

    def _segment(self, u: np.ndarray) -> np.ndarray:
        """Output of the active band over ``u`` and the whole bank's state update.

        In modal coordinates every band is three independent 2-state modes, so the
        update of the whole bank is four elementwise products and two matrix-vector
        products, about half the cost of a batched product of the 6x6 blocks.
        """
        a00, a01, a10, a11, R0, R1, OT = self._lifted(len(u))
        x0, x1 = self.x0_, self.x1_
        band = self.band_
        if band == OFF:
            y = u.copy()
        else:
            k = self.modes_
            sel = slice(band * k, (band + 1) * k)
            y = OT[band] @ np.concatenate([x0[sel], x1[sel], u])
        n0 = a00 * x0
        n0 += a01 * x1
        n0 += R0 @ u
        n1 = a10 * x0
        n1 += a11 * x1
        n1 += R1 @ u
        self.x0_, self.x1_ = n0, n1
        return y

    def _tick_boundary(self, count: int) -> None:
        """Measure the speed over the last ticks and pick the band."""
        marks = self.marks_
        marks.append(count)
        if len(marks) > self.speed_window + 1:
            del marks[0]
        span = (len(marks) - 1) * self.tick_ / self.spec_.fs
        speed = abs(marks[-1] - marks[0]) / self.spec_.counts_per_rev / span
        self.band_ = select_band(speed, self.band_, self.centres_, self.hysteresis)

    def _lifted(self, m: int):
        """Lifted matrices of every band for a segment of ``m`` samples, in modal
        coordinates, cached: the 2x2 mode blocks of ``A^m`` as four vectors, the input
        maps of the first and second state of each mode, and ``[O | T]`` per band."""
        if m not in self.lifted_:
            blocks, inputs, outputs = [], [], []
            for band, ti, v in zip(self.bands_, self.to_modal_, self.from_modal_):
                O, T, Am, R = lift(*band, m)
                blocks.append(ti @ Am @ v)
                inputs.append(ti @ R)
                Ov = O @ v
                outputs.append(np.hstack([Ov[:, 0::2], Ov[:, 1::2], T]))
            blocks = np.array(blocks)
            idx = np.arange(0, blocks.shape[1], 2)
            a00, a01 = blocks[:, idx, idx].ravel(), blocks[:, idx, idx + 1].ravel()
            a10, a11 = blocks[:, idx + 1, idx].ravel(), blocks[:, idx + 1, idx + 1].ravel()
            R = np.array(inputs)
            R0 = np.ascontiguousarray(R[:, 0::2, :]).reshape(-1, m)
            R1 = np.ascontiguousarray(R[:, 1::2, :]).reshape(-1, m)
            self.lifted_[m] = (a00, a01, a10, a11, R0, R1, np.array(outputs))
        return self.lifted_[m]


def modal_basis(A: np.ndarray) -> np.ndarray:
    """Real basis ``V`` in which ``V^-1 A V`` is block diagonal with 2x2 blocks.

    A cascade of notches has distinct complex pole pairs, one 2x2 rotation-scaling
    block each (``scipy.linalg.cdf2rdf``); padding states (all zero) keep the identity.
    """
    from scipy.linalg import cdf2rdf

    n = A.shape[0]
    k = int(np.count_nonzero(np.abs(A).sum(axis=0) + np.abs(A).sum(axis=1)))
    V = np.eye(n)
    if k:
        w, v = np.linalg.eig(A[:k, :k])
        if np.any(np.abs(w.imag) == 0):
            raise ValueError("a band filter has a real pole; the modal form needs pole pairs")
        _, V[:k, :k] = cdf2rdf(w, v)       # numpy returns conjugate pairs adjacent
        blocks = np.linalg.solve(V, A @ V)
        mask = np.kron(np.eye(n // 2), np.ones((2, 2))) == 0
        if np.abs(blocks[mask]).max() > 1e-9 * max(1.0, np.abs(A).max()):
            raise ValueError("a band filter did not split into 2x2 modes")
    return V


def _pad(system, n: int):
    """Embed a band's state space in ``n`` states (bands may drop orders near Nyquist)."""
    A, B, C, D = system
    k = A.shape[0]
    Ap = np.zeros((n, n))
    Ap[:k, :k] = A
    Bp = np.zeros(n)
    Bp[:k] = B
    Cp = np.zeros((1, n))
    Cp[:, :k] = C
    return Ap, Bp, Cp, D

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

Every band runs all the time (kept warm), so a switch never starts a cold filter: each
band is kept as independent 2-state modes (its notches' pole pairs), and one compiled
loop advances every mode of the bank sample by sample; the active band's output is the
sum over its modes. Gain and offset come from a least-squares fit of the calibration
strain to the known torque.

Examples
--------
>>> bank_size(min_speed=1.0, max_speed=50.0, q=4.0, hysteresis=0.2)
221
"""

from __future__ import annotations

import math

import numpy as np
from scipy import signal

from numba import types

from rippleb.data import JointSpec, SensorBlock, SensorLog
from rippleb.dsp import (F8, F8_C, IN_F8, IN_I8, biquad_ss, compiled, fit_gain_offset,
                         series_ss, steady_state)
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


@compiled(types.int64(types.float64, types.int64, IN_F8, types.float64))
def select_band(speed, current, centres, hysteresis):
    """The band for ``speed`` [rev/s] given the ``current`` one, with hysteresis.

    In the coordinate ``p = log(speed / c_0) / log(spacing)`` band ``j`` owns
    ``|p - j| <= 0.5``; the current band is kept while ``|p - j| <= 0.5 + hysteresis``.
    ``OFF`` (pass-through) sits at ``p = -1``.
    """
    spacing = math.log(centres[1] / centres[0]) if len(centres) > 1 else math.log(2.0)
    p = math.log(max(speed, 1e-12) / centres[0]) / spacing
    if abs(p - current) <= 0.5 + hysteresis:
        return current
    if current == len(centres) - 1 and p > current:
        return current
    return min(max(round(p), OFF), len(centres) - 1)


I8_C = types.int64[::1]
#: C-contiguous read-only coefficients: contiguity lets the compiler vectorise the mode loop
IN_F8_C = types.Array(types.float64, 1, "C", readonly=True)
#: streaming counters of :func:`notch_stream`, kept in one int64 array between calls
BAND, PHASE, N_MARKS, OLDEST = range(4)


@compiled(types.float64(I8_C, I8_C, types.int64, types.int64, types.float64, types.float64))
def tick_speed(marks, at, count, tick, fs, counts_per_rev):
    """Record ``count`` in the ring ``marks`` of the last tick ends; the speed over it [rev/s]."""
    size = len(marks)
    if at[N_MARKS] < size:
        marks[(at[OLDEST] + at[N_MARKS]) % size] = count
        at[N_MARKS] += 1
    else:
        marks[at[OLDEST]] = count
        at[OLDEST] = (at[OLDEST] + 1) % size
    span = (at[N_MARKS] - 1) * tick / fs
    return abs(count - marks[at[OLDEST]]) / counts_per_rev / span


@compiled(types.void(IN_F8, IN_I8, F8, F8_C, F8_C, IN_F8_C, IN_F8_C, IN_F8_C, IN_F8_C, IN_F8,
                     IN_F8, I8_C, I8_C, types.float64, types.int64, types.float64, types.float64))
def notch_stream(u, counts, y, x0, x1, decay, turn, c0, c1, d, centres, marks, at, hysteresis,
                 tick, fs, counts_per_rev):
    """Filter ``u`` into ``y`` with the active band while the whole bank runs, in place.

    The bank is kept as independent 2-state modes (one per notch pole pair), the same
    number per band, band after band. Mode ``m`` is the pole pair ``decay +- i turn`` in
    coordinates where the input enters its first state with unit weight:
    ``[x0, x1]' = [[decay, turn], [-turn, decay]] [x0, x1] + [u, 0]``; the active band's
    output is the sum of ``c0 x0 + c1 x1`` over its modes plus ``d u``. One flat loop over
    every mode of every band per sample, which the compiler vectorises. At the end of
    every ``tick`` samples the encoder speed picks the band (:func:`select_band`).
    """
    modes = len(x0) // len(centres)
    band, phase = at[BAND], at[PHASE]     # locals in the loop: no stores through ``at``
    for i in range(len(u)):
        ui = u[i]
        if band == OFF:
            y[i] = ui
        else:
            acc = d[band] * ui
            for m in range(band * modes, (band + 1) * modes):
                acc += c0[m] * x0[m] + c1[m] * x1[m]
            y[i] = acc
        for m in range(len(x0)):
            p, q = x0[m], x1[m]
            x0[m] = decay[m] * p + turn[m] * q + ui
            x1[m] = decay[m] * q - turn[m] * p
        phase += 1
        if phase == tick:
            phase = 0
            speed = tick_speed(marks, at, counts[i], tick, fs, counts_per_rev)
            band = select_band(speed, band, centres, hysteresis)
    at[BAND], at[PHASE] = band, phase


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
        bank designed for the calibration's rate (a device streams at the rate it was
        calibrated at, so ``reset`` then reuses it instead of designing it per run)."""
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
        self.x0_ = self.x1_ = None    # modal bank state, set by the first sample
        self.marks_ = np.zeros(self.speed_window + 1, dtype=np.int64)  # counts at tick ends
        self.at_ = np.array([OFF, 0, 0, 0], dtype=np.int64)             # BAND, PHASE, ...

    @property
    def band_(self) -> int:
        """Index of the active band (``OFF`` for pass-through)."""
        return int(self.at_[BAND])

    def _design_key(self, spec: JointSpec) -> tuple:
        return (spec.fs, tuple(sorted(self.get_params().items(), key=str)))

    def _design(self, spec: JointSpec) -> dict:
        """The bank for ``spec``: centres, band filters padded to one state count, and
        their modes (:func:`normal_modes`), band after band in flat arrays."""
        n_bands = self.n_bands or bank_size(self.min_speed, self.max_speed, self.q, self.hysteresis)
        centres = band_centres(self.min_speed, self.max_speed, n_bands)
        bands = [band_filter(c, self.orders, self.q, spec.fs) for c in centres]
        n_states = max(b[0].shape[0] for b in bands)
        bands = [_pad(b, n_states) for b in bands]
        parts = [normal_modes(*band) for band in bands]
        design = {name: np.concatenate([p[k] for p in parts])
                  for k, name in enumerate(["decay_", "turn_", "c0_", "c1_"])}
        design.update(key=self._design_key(spec), centres_=centres, bands_=bands,
                      d_=np.array([D[0] for _, _, _, D in bands]),
                      to_modal_=[p[4] for p in parts])
        return design

    def step(self, block: SensorBlock) -> np.ndarray:
        """Notch the strain with the active band; the band is picked on the tick grid."""
        u = np.asarray(block.strain, dtype=float)
        counts = np.asarray(block.encoder, dtype=np.int64)
        if self.x0_ is None and len(u):
            self._start(u[0], int(counts[0]))
        y = np.empty_like(u)
        notch_stream(u, counts, y, self.x0_, self.x1_, self.decay_, self.turn_, self.c0_,
                     self.c1_, self.d_, self.centres_, self.marks_, self.at_,
                     float(self.hysteresis), int(self.spec_.block_size), float(self.spec_.fs),
                     float(self.spec_.counts_per_rev))
        return self.gain_ * y + self.offset_

    def _start(self, u0: float, count0: int) -> None:
        """Every band at rest on the first sample, so no filter starts from zero."""
        xi = np.array([ti @ steady_state(A, B, u0)
                       for (A, B, _, _), ti in zip(self.bands_, self.to_modal_)])
        self.x0_ = np.ascontiguousarray(xi[:, 0::2]).ravel()   # first state of each mode
        self.x1_ = np.ascontiguousarray(xi[:, 1::2]).ravel()   # second state of each mode
        self.marks_[0] = count0
        self.at_[N_MARKS] = 1


def normal_modes(A, B, C, D):
    """One band as independent modes whose input enters the first state with weight 1.

    In the real modal basis (:func:`modal_basis`) each pole pair ``s +- i w`` is the block
    ``[[s, w], [-w, s]]``, which commutes with rotations and scalings; rotating and scaling
    each mode so that its input vector becomes ``(1, 0)`` leaves the block unchanged and
    takes two multiplications per mode and sample off the update.

    Returns
    -------
    decay, turn, c0, c1
        Per mode: ``s``, ``w`` and the two output weights.
    to_modal
        The map from the band's own state to these coordinates.
    """
    v = modal_basis(A)
    to_modal = np.linalg.inv(v)
    b, c = to_modal @ B, C[0] @ v
    n = A.shape[0]
    for k in range(0, n, 2):
        bk = np.hypot(b[k], b[k + 1])
        if bk == 0.0:                        # a padding mode: no input, no output
            continue
        # rotation R with R b = (|b|, 0), then 1/|b|: T = R / |b|
        cos, sin = b[k] / bk, b[k + 1] / bk
        T = np.array([[cos, sin], [-sin, cos]]) / bk
        to_modal[k:k + 2] = T @ to_modal[k:k + 2]
        c[k:k + 2] = c[k:k + 2] @ np.linalg.inv(T)
    blocks = to_modal @ A @ np.linalg.inv(to_modal)
    decay, turn = blocks.diagonal()[0::2].copy(), blocks.diagonal(1)[0::2].copy()
    off = blocks - np.kron(np.eye(n // 2), np.ones((2, 2))) * blocks
    rotation = np.abs(blocks.diagonal(-1)[0::2] + turn).max(initial=0.0)
    if np.abs(off).max(initial=0.0) > 1e-9 or rotation > 1e-9:
        raise ValueError("a band filter did not split into rotation-scaling modes")
    return decay, turn, c[0::2].copy(), c[1::2].copy(), to_modal


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

"""``switched-notch``: a bank of time-domain notch filters switched by encoder speed.

After Godler et al., whose ripple compensation uses "a set of multiple notch filters that
have partially separated cutoff frequencies" (reference [17] of the paper). The ripple of
order ``k`` sits at ``k`` times the wave-generator rotation frequency ``f``, so it moves
with speed. The bank holds bands whose centre speeds ``c_j`` are spaced geometrically
from ``min_speed`` to ``max_speed`` [wave-generator rev/s], a whole number per octave;
band ``j`` is one filter, the series of second-order notches at ``k * c_j`` for every ``k`` in
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
bank is kept as independent 2-state modes, one per distinct notch pole pair (a band's
order-4 notch is the order-2 notch of the band an octave up), and one compiled loop
advances every mode, two samples a step; the active band's output is a weighted sum of
its modes (partial fractions of its notches in series). Gain and offset come from a
least-squares fit of the calibration strain to the known torque.

Examples
--------
>>> bank_size(min_speed=1.0, max_speed=50.0, q=4.0, hysteresis=0.2)
222
"""

from __future__ import annotations

import math

import numpy as np
from scipy import signal

from rippleb.data import JointSpec, SensorBlock, SensorLog
from rippleb.dsp import fit_gain_offset
from rippleb.method import Method
from rippleb.methods._notch_stream import (BAND, N_MARKS, OFF, ROWS, notch_stream,  # noqa: F401
                                           select_band)

RESIDUAL = 0.1  # ripple fraction a notch may pass at a switching point (-20 dB)


def bank_spacing(q: float, hysteresis: float, residual: float = RESIDUAL) -> float:
    """Ratio of neighbouring centre speeds: the coarsest that leaves at most ``residual``
    of the ripple at a switching point, with a whole number of bands per octave.

    A band is left ``0.5 + hysteresis`` spacings away from its centre, a relative
    mistuning ``delta = (0.5 + hysteresis) * log(spacing)``; a notch of quality ``q``
    passes about ``2 q delta`` of a sinusoid mistuned by ``delta``. Solving
    ``2 q delta <= residual`` bounds the spacing; it is then rounded down to
    ``2 ** (1 / n)``, so that the notch of order ``2 k`` of a band is the notch of order
    ``k`` of the band an octave up, and the bank runs each such pole pair once
    (:func:`notch_modes`).
    """
    delta = residual / (2.0 * q)
    per_octave = math.ceil(math.log(2.0) * (0.5 + hysteresis) / delta - 1e-9)
    return 2.0 ** (1.0 / per_octave)


def band_centres(min_speed: float, max_speed: float, spacing: float) -> np.ndarray:
    """Centre speeds [rev/s] ``min_speed * spacing ** j``, lowest first, up to the first
    at or above ``max_speed``."""
    n = math.ceil(math.log(max_speed / min_speed) / math.log(spacing) - 1e-9) + 1
    return min_speed * spacing ** np.arange(max(n, 2))


def bank_size(min_speed: float, max_speed: float, q: float, hysteresis: float,
              residual: float = RESIDUAL) -> int:
    """Number of bands from ``min_speed`` to ``max_speed`` at :func:`bank_spacing`."""
    return len(band_centres(min_speed, max_speed, bank_spacing(q, hysteresis, residual)))


def notch_modes(centres, orders, q: float, fs: float):
    """The bank's distinct notch pole pairs, and how each band's output is made of them.

    Band ``j`` is the series of ``scipy.signal.iirnotch`` notches at ``k * centres[j]``
    for ``k`` in ``orders`` (orders at or above 0.45 fs are left out: the ripple there is
    aliased by the DAQ anyway). A series of notches with distinct poles is, by partial
    fractions, ``d + sum_i 2 Re(r_i xi_i)`` with one complex state per pole ``p_i`` (upper
    half plane), ``xi_i' = p_i xi_i + u``: the state depends on the pole alone, so bands
    whose notches sit at the same frequency share it. On geometric centres an order ``k``
    notch of band ``j`` is the order ``k0 = min(orders)`` notch of band ``j + s`` when
    ``k / k0 = spacing ** s`` for a whole ``s`` (octaves, with :func:`bank_spacing`);
    other orders get modes of their own.

    Returns
    -------
    poles
        One complex pole per mode (upper half plane).
    band_modes
        ``(n_bands, len(orders))`` mode of each band's notch; 0 where an order is left out.
    weights
        ``(n_bands, len(orders))`` complex ``2 r`` of each band's notch; 0 where left out.
    direct
        ``(n_bands,)`` each band's direct feed-through ``d``.
    """
    spacing = centres[1] / centres[0]
    base = min(orders)
    grid: dict = {}                                  # (family, index) -> mode
    poles, sections = [], []
    band_modes = np.zeros((len(centres), len(orders)), dtype=np.int64)
    for o, k in enumerate(orders):
        steps = math.log(k / base) / math.log(spacing)
        family, offset = (base, round(steps)) if abs(steps - round(steps)) < 1e-6 else (k, 0)
        for j in range(len(centres)):
            key = (family, j + offset)
            freq = family * centres[0] * spacing ** key[1]
            if freq >= 0.45 * fs:
                band_modes[j, o] = -1
                continue
            if key not in grid:
                b, a = signal.iirnotch(freq, q, fs=fs)
                if a[1] ** 2 >= 4.0 * a[2]:
                    raise ValueError(f"switched-notch: the notch at {freq:.4g} Hz with q={q} has "
                                     f"real poles; raise q or lower max_speed")
                grid[key] = len(poles)
                poles.append((-a[1] + 1j * math.sqrt(4.0 * a[2] - a[1] ** 2)) / 2.0)
                sections.append((b, a))
            band_modes[j, o] = grid[key]
    poles = np.array(poles)
    weights = np.zeros(band_modes.shape, dtype=complex)
    direct = np.ones(len(centres))
    for j, modes in enumerate(band_modes):
        used = modes[modes >= 0]
        weights[j, modes >= 0] = 2.0 * _residues(poles[used], [sections[m] for m in used])
        direct[j] = np.prod([sections[m][0][0] for m in used])
    band_modes[band_modes < 0] = 0
    return poles, band_modes, weights, direct


def _residues(poles: np.ndarray, sections: list) -> np.ndarray:
    """``r_i`` of ``prod_k b_k(w) / a_k(w) = d + sum r_i w / (1 - p_i w)`` (``w = 1/z``,
    ``a_k(w) = (1 - p_k w)(1 - conj(p_k) w)``, the sum over every pole and its conjugate),
    at the upper poles ``p_i = poles[i]`` of the sections ``(b_k, a_k)``.

    Evaluated section by section, ``r_i = p_i b_i(1/p_i) / (1 - conj(p_i)/p_i) *
    prod_{k != i} b_k(1/p_i) / a_k(1/p_i)``: expanding the series into one polynomial
    first loses the notches' precision (their poles sit within 1e-4 of ``z = 1``).
    """
    out = np.empty(len(poles), dtype=complex)
    for i, (p, (b, _)) in enumerate(zip(poles, sections)):
        w = 1.0 / p
        r = p * np.polyval(b[::-1], w) / (1.0 - p.conjugate() * w)
        for k, (bk, ak) in enumerate(sections):
            if k != i:
                r *= np.polyval(bk[::-1], w) / np.polyval(ak[::-1], w)
        out[i] = r
    return out


def mode_rows(values: np.ndarray) -> np.ndarray:
    """The bank's per-mode ``values`` as the ``(ROWS, columns)`` array the compiled loop
    advances (``methods/_notch_stream.py``): mode ``m`` at flat index ``m``, the last row
    padded with zeros (idle modes no band reads)."""
    columns = -(-len(values) // ROWS)
    rows = np.zeros(ROWS * columns)
    rows[:len(values)] = values
    return rows.reshape(ROWS, columns)


class SwitchedNotch(Method):
    """Switched bank of time-domain notch filters (Godler et al.).

    Parameters
    ----------
    orders
        Ripple orders notched, in cycles per wave-generator revolution. The paper's
        dominant orders 2, 4 and 8.
    n_bands
        Number of bands in the bank, spaced geometrically from ``min_speed`` to
        ``max_speed``; None for the coarsest whole number per octave that leaves at most
        10 % of the ripple at a switching point (:func:`bank_spacing`).
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
    description = "time-domain notches at orders 2, 4, 8 (q=8.0), switched by encoder speed (Godler et al.)"
    #: ranges of the tuning protocol (rippleb/tuning.py)
    tunable = {"min_speed": (0.5, 5.0, "log"), "q": (2.0, 32.0, "log"), "speed_window": (20, 320, "int")}

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
        """The bank for ``spec``: centres and the modes of :func:`notch_modes` in flat arrays."""
        if not self.max_speed > self.min_speed > 0:
            raise ValueError(f"switched-notch: needs 0 < min_speed < max_speed, got "
                             f"min_speed={self.min_speed}, max_speed={self.max_speed}")
        if self.n_bands is None:
            spacing = bank_spacing(self.q, self.hysteresis)
        elif self.n_bands < 2:
            raise ValueError(f"switched-notch: n_bands={self.n_bands}; a bank needs at least 2 bands")
        else:
            spacing = (self.max_speed / self.min_speed) ** (1.0 / (self.n_bands - 1))
        centres = band_centres(self.min_speed, self.max_speed, spacing)
        poles, band_modes, weights, direct = notch_modes(centres, self.orders, self.q, spec.fs)
        return dict(key=self._design_key(spec), centres_=centres, poles_=poles,
                    decay_=mode_rows(poles.real), turn_=mode_rows(poles.imag),
                    decay2_=mode_rows((poles ** 2).real), turn2_=mode_rows((poles ** 2).imag),
                    band_modes_=band_modes, c0_=weights.real.copy(), c1_=weights.imag.copy(),
                    d_=direct)

    def step(self, block: SensorBlock) -> np.ndarray:
        """Notch the strain with the active band; the band is picked on the tick grid."""
        u = np.asarray(block.strain, dtype=float)
        counts = np.asarray(block.encoder, dtype=np.int64)
        if self.x0_ is None and len(u):
            self._start(u[0], int(counts[0]))
        y = np.empty_like(u)
        notch_stream(u, counts, y, self.x0_, self.x1_, self.decay_, self.turn_, self.decay2_,
                     self.turn2_, self.band_modes_, self.c0_, self.c1_, self.d_, self.centres_,
                     self.marks_, self.at_, float(self.hysteresis), int(self.spec_.block_size),
                     float(self.spec_.fs), float(self.spec_.counts_per_rev))
        return self.gain_ * y + self.offset_

    def _start(self, u0: float, count0: int) -> None:
        """Every mode at rest on the first sample (``xi = u0 / (1 - p)``), so no filter
        starts from zero."""
        rest = u0 / (1.0 - self.poles_)
        self.x0_, self.x1_ = mode_rows(rest.real), mode_rows(-rest.imag)
        self.marks_[0] = count0
        self.at_[N_MARKS] = 1

"""switched-notch's compiled streaming loop against the plain form of the same arithmetic.

The compiled loop (``methods/_notch_stream.py``) orders its work for speed: modes in two
rows, two sample pairs per pass over the bank with the state held in registers between
them. None of that may change a number. The oracle here steps the bank the plain way, one
sample pair at a time with numpy over every mode (the form the loop had before it was
reordered), the active band's output sample by sample in Python floats, the speed and band
switch at every tick end: each operation the one the method's definition gives, in the
order it rounds. Contract: **bit for bit** (no FMA contraction, no fast-math in numba, and
numpy's elementwise ``*`` ``+`` ``-`` round each operation alike on every CPU).
"""

import dataclasses

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from rippleb import JointSpec, SensorLog
from rippleb.methods.switched_notch import OFF, SwitchedNotch, select_band


def oracle(method, log, size=None):
    """``method``'s estimate of ``log`` in blocks of ``size`` samples, computed plainly."""
    spec = log.spec
    method.reset(spec)                               # the bank designed for the stream's rate
    tick, window = spec.block_size, method.speed_window + 1
    flat = dict(decay=method.decay_.ravel(), turn=method.turn_.ravel(),
                decay2=method.decay2_.ravel(), turn2=method.turn2_.ravel())
    m = len(method.poles_)
    s, w, s2, w2 = (flat[k][:m] for k in ("decay", "turn", "decay2", "turn2"))
    rest = log.strain[0] / (1.0 - method.poles_)
    x0, x1 = rest.real.copy(), -rest.imag
    marks, band, phase = [int(log.encoder[0])], OFF, 0
    out = []
    for block in log.blocks(size):
        u, y = block.strain, np.empty(len(block.strain))
        i = 0
        while i < len(u):
            end = min(len(u), i + tick - phase)
            seg = u[i:end].tolist()
            if band == OFF:
                y[i:end] = u[i:end]
            else:
                y[i:end] = _band_output(seg, x0, x1, s, w, method, band)
            for a in range(0, len(seg) - 1, 2):
                ua, ub = seg[a], seg[a + 1]
                x0, x1 = s2 * x0 + w2 * x1 + s * ua + ub, s2 * x1 - w2 * x0 - w * ua
            if len(seg) % 2:
                x0, x1 = s * x0 + w * x1 + seg[-1], s * x1 - w * x0
            phase += end - i
            if phase == tick:
                phase = 0
                marks = (marks + [int(block.encoder[end - 1])])[-window:]
                span = (len(marks) - 1) * tick / spec.fs
                speed = abs(marks[-1] - marks[0]) / spec.counts_per_rev / span
                band = select_band(speed, band, method.centres_, float(method.hysteresis))
            i = end
        out.append(method.gain_ * y + method.offset_)
    return np.concatenate(out)


def _band_output(seg, x0, x1, s, w, method, band):
    """The active band over one tick's samples: feed-through plus its modes, each stepped
    sample by sample from the bank's state."""
    y = [method.d_[band] * v for v in seg]
    for k, mode in enumerate(method.band_modes_[band]):
        p, q, sk, wk = float(x0[mode]), float(x1[mode]), float(s[mode]), float(w[mode])
        c0, c1 = float(method.c0_[band, k]), float(method.c1_[band, k])
        for i, v in enumerate(seg):
            y[i] += c0 * p + c1 * q
            p, q = sk * p + wk * q + v, sk * q - wk * p
    return y


def stream(method, log, size=None):
    method.reset(log.spec)
    return np.concatenate([method.step(b) for b in log.blocks(size)])


def _log(strain, counts, spec):
    t = np.arange(len(strain)) / spec.fs
    return SensorLog(spec=spec, t=t, strain=strain, encoder=counts, current=np.zeros_like(t))


def test_the_mode_arrays_hold_every_mode_at_its_flat_index():
    method = SwitchedNotch()
    method.reset(JointSpec())
    n = len(method.poles_)
    np.testing.assert_array_equal(method.decay_.ravel()[:n], method.poles_.real)
    np.testing.assert_array_equal(method.turn2_.ravel()[:n], (method.poles_ ** 2).imag)
    assert not method.decay_.ravel()[n:].any()      # idle padding
    assert method.band_modes_.max() < n             # which no band reads


@settings(max_examples=10, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), control_rate=st.sampled_from([1000.0, 800.0, 2500.0]),
       size=st.one_of(st.none(), st.integers(1, 97)))
def test_matches_the_plain_arithmetic_bit_for_bit(seed, control_rate, size):
    """Random speed profiles through the bank (pass-through, switches, the top band), ticks
    of 20, 25 and 8 samples (odd ticks end on a single step), any block size."""
    spec = JointSpec(control_rate=control_rate)
    rng = np.random.default_rng(seed)
    n = int(rng.integers(100, 2000))
    speed = np.interp(np.arange(n), np.sort(rng.integers(0, n, 6)), rng.uniform(-60, 60, 6))
    angle = 2 * np.pi * np.cumsum(speed) / spec.fs
    strain = np.sin(4 * angle) + rng.normal(0, 0.1, n) + rng.uniform(-2, 2)
    counts = np.floor(angle / (2 * np.pi) * spec.counts_per_rev).astype(np.int64)
    log = _log(strain, counts, spec)
    method = SwitchedNotch(speed_window=int(rng.integers(1, 40)))
    method.fit(dataclasses.replace(log, torque_ref=3.0 * strain + rng.normal(0, 0.1, n)))
    np.testing.assert_array_equal(stream(method, log, size), oracle(method, log, size))


@pytest.mark.slow
@pytest.mark.parametrize("scenario, seed, condition", [
    ("paper-quintic", 901, "same-session"), ("speed-sweep", 2003, "aged"),
    ("stop-restart", 2011, "re-assembled"), ("reversal", 7, "power-cycled")])
def test_simulated_joints_bit_for_bit(scenario, seed, condition):
    """Simulated devices through whole scenarios: the 20-sample ticks, 1-second blocks, and
    7- and 53-sample blocks that end inside ticks (a block's end cuts a tick's pairs, so
    each block size has its own bits, ``test_block_size_does_not_change_the_estimate``)."""
    from rippleb.simulator import simulate

    method = SwitchedNotch()
    method.fit(simulate("calibration", seed).log.for_method(keep_ref=True))
    log = simulate(scenario, seed, condition).log.for_method(keep_ref=False)
    for size in (None, 7, 53, int(log.spec.fs)):
        np.testing.assert_array_equal(stream(method, log, size), oracle(method, log, size),
                                      err_msg=f"blocks of {size}")

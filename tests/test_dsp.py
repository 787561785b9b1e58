"""The compiled biquad recursion against scipy's lfilter, and its state across block cuts."""

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy import signal

from rippleb.dsp import biquad


@settings(max_examples=30, deadline=None)
@given(cutoff=st.floats(1.0, 9000.0), n=st.integers(1, 300), cut=st.integers(0, 300),
       seed=st.integers(0, 2**32 - 1))
def test_biquad_is_lfilter_and_carries_its_state_across_a_cut(cutoff, n, cut, seed):
    rng = np.random.default_rng(seed)
    b, a = signal.butter(2, cutoff, fs=20_000.0)
    x, zi = rng.normal(size=n), rng.normal(size=2)
    expected, zf = signal.lfilter(b, a, x, zi=zi)
    state, out = zi.copy(), np.empty(n)
    cut = min(cut, n)
    biquad(b, a, x[:cut], state, out[:cut])      # two blocks, one state
    biquad(b, a, x[cut:], state, out[cut:])
    np.testing.assert_allclose(out, expected, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(state, zf, rtol=1e-12, atol=1e-12)


def test_biquad_accepts_read_only_input_and_filters_in_place():
    b, a = signal.butter(2, 130.0, fs=20_000.0)
    x = np.linspace(-1.0, 1.0, 50)
    expected, _ = signal.lfilter(b, a, x, zi=np.zeros(2))
    frozen = x.copy()
    frozen.flags.writeable = False
    out = np.empty(50)
    biquad(b, a, frozen, np.zeros(2), out)
    in_place = x.copy()
    biquad(b, a, in_place, np.zeros(2), in_place)
    np.testing.assert_allclose(out, expected, atol=1e-14)
    np.testing.assert_allclose(in_place, expected, atol=1e-14)

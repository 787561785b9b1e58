import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from rippleb.methods.lowpass import Lowpass
from rippleb.methods.raw import Raw
from rippleb.registry import Registry
from rippleb.harness import run_method
from rippleb.testing import check_method, default_logs


@pytest.mark.parametrize("cls", [Raw, Lowpass])
def test_baselines_conform(cls):
    check_method(cls)


@pytest.mark.slow
@pytest.mark.parametrize("name", Registry.discover().names("builtin"))
def test_every_builtin_method_conforms(name):
    """The conformance checks on every method in rippleb.methods (the authors add stricter ones)."""
    check_method(Registry.discover().get(name).load())


def test_raw_recovers_gain_and_offset():
    cal, _ = default_logs()
    raw = Raw()
    raw.fit(cal.for_method(keep_ref=True))
    # the strain is g*tau + ripple + offset: the fit inverts g within a few percent
    assert np.corrcoef(cal.strain, cal.torque_ref)[0, 1] > 0.99
    est = raw.gain_ * cal.strain + raw.offset_
    assert np.sqrt(np.mean((est - cal.torque_ref) ** 2)) < 0.1 * np.std(cal.torque_ref)


def test_lowpass_removes_ripple_that_raw_keeps():
    cal, log = default_logs()
    raw, _ = run_method(Raw(), cal, log)
    # at 30 Hz, the cutoff before the tuning protocol opened it to 190 Hz (methods/lowpass.py)
    low, _ = run_method(Lowpass(cutoff_hz=30.0), cal, log)
    from scipy.signal import welch

    # error power above 100 Hz (ripple and noise) drops by more than 10x, beyond the true
    # torque's own power there, which a low-pass removes with the ripple (the gear's real
    # torque and the joint's count edges: measured 91 % of lowpass's error power above
    # 100 Hz on this log, 9.3 % of raw's)
    f, p_raw = welch(raw - log.torque_true, log.spec.fs, nperseg=4096)
    _, p_low = welch(low - log.torque_true, log.spec.fs, nperseg=4096)
    _, p_true = welch(log.torque_true - log.torque_true.mean(), log.spec.fs, nperseg=4096)
    high = f > 100
    assert p_low[high].sum() - p_true[high].sum() < 0.1 * p_raw[high].sum()
    assert p_true[high].sum() < p_low[high].sum()   # what it removed of the real torque is its error


@settings(max_examples=15, deadline=None)
@given(st.lists(st.integers(1, 400), min_size=1, max_size=30), st.floats(5, 500))
def test_lowpass_is_block_size_independent(sizes, cutoff):
    cal, log = default_logs()
    base, _ = run_method(Lowpass(cutoff_hz=cutoff), cal, log)
    method = Lowpass(cutoff_hz=cutoff)
    method.fit(cal.for_method(keep_ref=True))
    method.reset(log.spec)
    out, start, i = [], 0, 0
    while start < len(log):   # irregular block sizes, cycling through the drawn list
        stop = min(len(log), start + sizes[i % len(sizes)])
        out.append(method.step(log.block(start, stop)))
        start, i = stop, i + 1
    np.testing.assert_allclose(np.concatenate(out), base, atol=1e-9)


class _Future(Raw):
    name = "future"

    def step(self, block):   # peeks at the end of its own block: not causal per sample
        return np.full(len(block), block.strain[-1] * self.gain_ + self.offset_)


class _Stateful(Raw):
    name = "stateful"

    def reset(self, spec):
        pass   # forgets to clear its state

    def step(self, block):
        self.count_ = getattr(self, "count_", 0) + 1
        return block.strain * self.gain_ + self.offset_ + 1e-3 * self.count_


class _Nan(Raw):
    name = "nan"

    def step(self, block):
        return np.full(len(block), np.nan)


@pytest.mark.parametrize("cls, message", [(_Future, "blocks of 1 samples differ"),
                                          (_Stateful, "reset must clear"),
                                          (_Nan, "NaN")])
def test_check_method_catches_broken_methods(cls, message):
    with pytest.raises(AssertionError, match=message):
        check_method(cls)

"""The plugin's own tests: rippleb's conformance kit on the default and a short window."""
from rippleb.testing import check_method
from rippleb_median import Median


def test_median_behaves_as_the_runner_expects():
    check_method(Median)                # length, finiteness, determinism, causality, block sizes


def test_a_one_sample_window_behaves_too():
    check_method(Median, window=1)

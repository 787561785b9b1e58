"""The one tuning protocol (rippleb/tuning.py): declared ranges, one sampler, one budget."""

import inspect

import pytest
from hypothesis import given, strategies as st

from rippleb.registry import Registry
from rippleb.tuning import candidates, check_tunable

RANGES = {"a": (1e-3, 10.0, "log"), "b": (-1.0, 1.0, "linear"), "n": (2, 9, "int")}


@given(st.integers(1, 64))
def test_every_budget_gives_that_many_points_in_range_default_first(budget):
    points = candidates(RANGES, {"a": 0.5, "b": 0.0, "n": 4}, budget)
    assert len(points) == budget and points[0] == {"a": 0.5, "b": 0.0, "n": 4}
    for p in points[1:]:
        assert 1e-3 <= p["a"] <= 10.0 and -1.0 <= p["b"] <= 1.0
        assert isinstance(p["n"], int) and 2 <= p["n"] <= 9


def test_the_points_re_run_and_spread_over_a_log_range():
    first = candidates(RANGES, {"a": 0.5, "b": 0.0, "n": 4}, 33)
    assert first == candidates(RANGES, {"a": 0.5, "b": 0.0, "n": 4}, 33)
    a = sorted(p["a"] for p in first[1:])
    assert a[0] < 1e-2 and a[-1] > 1.0            # decades below and above the middle
    assert {p["n"] for p in first[1:]} == set(range(2, 10))


def test_nothing_to_tune_is_one_evaluation_whatever_the_budget():
    assert candidates({}, {"x": 1}, 16) == [{}]


@pytest.mark.parametrize("bad", [(1.0, 1.0, "log"), (0.0, 1.0, "log"), (1, 2, "cubic"), (1, 2)])
def test_a_malformed_declaration_is_one_line_naming_the_method(bad):
    with pytest.raises(ValueError, match=r"my-method\.tunable\['x'\]"):
        check_tunable("my-method", {"x": bad})


def test_every_builtin_declares_ranges_of_its_own_constructor_parameters():
    registry = Registry.discover()
    for name in registry.names("builtin"):
        cls = registry.get(name).load()
        assert hasattr(cls, "tunable"), name
        check_tunable(name, cls.tunable)
        parameters = inspect.signature(cls.__init__).parameters
        defaults = cls().get_params()
        for param, (low, high, _) in cls.tunable.items():
            assert param in parameters, (name, param)
            assert low <= defaults[param] <= high, (name, param, defaults[param])

"""Sweep parameters: parsing, ranges, the grid, and scenarios built with a swept value."""

import pytest

from rippleb.errors import InputError
from rippleb.engine.sweep import PARAMS, apply, grid, parse_params, swept_scenario


def test_parse_and_grid_cover_every_combination_in_order():
    sweeps = parse_params(["joint.counts_per_rev=500,2500", "temperature_c=25,40,60"])
    points = grid(sweeps)
    assert len(points) == 6
    assert points[0] == {"joint.counts_per_rev": 500, "temperature_c": 25.0}
    assert points[-1] == {"joint.counts_per_rev": 2500, "temperature_c": 60.0}
    assert isinstance(points[0]["joint.counts_per_rev"], int)


@pytest.mark.parametrize("spec, words", [
    (["joint.counts_per_rv=500"], ["unknown sweep parameter", "did you mean 'joint.counts_per_rev'"]),
    (["joint.counts_per_rev=2.5"], ["not an integer"]),
    (["joint.counts_per_rev=10"], ["outside the valid range"]),
    (["temperature_c=hot"], ["not a number"]),
    (["temperature_c"], ["expected NAME=v1,v2"]),
    (["temperature_c=20,20"], ["repeated"]),
    (["temperature_c=20", "temperature_c=30"], ["given twice"]),
    ([], ["at least one"]),
])
def test_bad_parameters_are_one_clear_line(spec, words):
    with pytest.raises(InputError) as info:
        parse_params(spec)
    message = str(info.value)
    assert "\n" not in message
    for word in words:
        assert word in message


def test_apply_sets_nested_keys_without_touching_the_original():
    raw = {"joint": {"fs": 20000.0}, "duration": 1.0}
    out = apply(raw, {"joint.counts_per_rev": 1000, "temperature_c": 30.0})
    assert out == {"joint": {"fs": 20000.0, "counts_per_rev": 1000}, "duration": 1.0,
                   "temperature_c": 30.0}
    assert raw == {"joint": {"fs": 20000.0}, "duration": 1.0}


def test_swept_scenario_carries_the_value_and_keeps_its_name():
    sc = swept_scenario("paper-quintic", {"joint.counts_per_rev": 1000, "temperature_c": 30.0})
    assert sc.name == "paper-quintic"
    assert sc.spec.counts_per_rev == 1000 and sc.temperature_c == 30.0


def test_an_impossible_combination_names_the_swept_values():
    with pytest.raises(InputError, match=r"control_rate.*with joint.fs=2000.0, joint.control_rate=5000.0"):
        swept_scenario("paper-quintic", {"joint.fs": 2000.0, "joint.control_rate": 5000.0})


def test_every_parameter_has_a_range_and_a_description():
    for param in PARAMS.values():
        assert param.low < param.high and param.doc


def test_ripple_drift_is_swept_into_the_ripple_table():
    sc = swept_scenario("paper-quintic", {"ripple.drift": 2.5})
    assert sc.ripple.drift == 2.5 and not PARAMS["ripple.drift"].device
    with pytest.raises(InputError, match=r"ripple\.drift.*in \[0, 5\]"):
        swept_scenario("paper-quintic", {"ripple.drift": 6.0})


def test_ripple_drift_without_the_aged_condition_is_refused():
    from rippleb.engine.sweep import run_sweep

    with pytest.raises(InputError, match=r"ripple\.drift: acts only under the 'aged' condition"):
        run_sweep(["ripple.drift=0,1"], methods="raw", scenarios="paper-quintic", seeds=1,
                  conditions="same-session")

"""The one tuning protocol (rippleb/tuning.py): declared ranges, one sampler, one budget."""

import inspect
import json
import subprocess
import sys

import numpy as np
import pytest
from hypothesis import given, strategies as st

from rippleb.engine.tuner import entry, plan
from rippleb.errors import PluginError
from rippleb.registry import Registry
from rippleb.report.tuning_table import tuning_markdown
from rippleb.tuning import BUDGET, SEEDS, candidates, check_tunable, read_record, replaces_default, summary

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


def test_sobol_points_hold_three_significant_digits():
    for p in candidates(RANGES, {"a": 0.5, "b": 0.0, "n": 4}, 64)[1:]:
        for value in (p["a"], p["b"]):
            assert value == float(f"{value:.3g}")


@given(st.lists(st.tuples(st.floats(0.1, 10), st.floats(0.1, 10)), min_size=1, max_size=8))
def test_the_rule_replaces_only_a_default_beaten_on_every_device(pairs):
    default, best = [d for d, _ in pairs], [b for _, b in pairs]
    assert replaces_default(default, best) == all(b < d for d, b in pairs)


def test_a_method_entry_keeps_the_default_unless_the_rule_says_otherwise():
    tried = [({"q": 30}, [1.0, 1.0], ""), ({"q": 10}, [0.5, 1.2], ""), ({"q": 20}, [0.9, 0.95], "")]
    kept = entry({"q": (5, 50, "int")}, tried, "", 1.0)
    assert kept["best"] == {"q": 10} and not kept["replaced"] and kept["adopted"] == {"q": 30}
    tried[1] = ({"q": 10}, [0.5, 0.99], "")
    won = entry({"q": (5, 50, "int")}, tried, "", 1.0)
    assert won["replaced"] and won["adopted"] == {"q": 10} and won["evaluations"] == 3


def test_a_failing_point_cannot_be_the_best_and_is_named():
    tried = [({"q": 30}, [1.0], ""), ({"q": 5}, [float("inf")], "ValueError: q too small")]
    record = entry({"q": (5, 50, "int")}, tried, "", 0.0)
    assert record["adopted"] == {"q": 30} and record["errors"] == ["ValueError: q too small"]


# ------------------------------------------------------------------ the built-ins' record
RECORD = read_record()


def test_the_record_is_one_protocol_with_one_budget_on_unpublished_devices():
    protocol = RECORD["protocol"]
    assert protocol["budget"] == BUDGET and protocol["seeds"] == list(SEEDS)
    assert not set(protocol["seeds"]) & set(range(20))           # the published devices are 0-19
    for name, method in RECORD["methods"].items():
        expected = BUDGET if method["tunable"] else 1
        assert method["evaluations"] == expected == len(method["points"]), name
        assert len(method["default_scores"]) == len(SEEDS) and not method["errors"], name


def test_every_builtin_runs_with_the_values_its_tuning_adopted():
    """The built-ins' defaults are the record's adopted points: a changed default without a
    new tuning record, or a record without the defaults it adopted, fails here."""
    registry = Registry.discover()
    assert sorted(RECORD["methods"]) == sorted(registry.names("builtin"))
    for name in registry.names("builtin"):
        cls = registry.get(name).load()
        method = RECORD["methods"][name]
        assert {k: list(v) for k, v in cls.tunable.items()} == method["tunable"], name
        defaults = cls().get_params()
        assert {p: defaults[p] for p in cls.tunable} == method["adopted"], name
        if method["replaced"]:
            assert np.all(np.array(method["best_scores"]) < np.array(method["default_scores"])), name


def test_a_run_records_the_tuning_and_its_report_prints_it():
    recorded = summary()
    assert recorded["protocol"] == RECORD["protocol"] and len(recorded["sha256"]) == 64
    text = tuning_markdown(recorded, ["order-tracking", "raw", "order-tracking[q=20]", "my-plugin"])
    assert f"budget of {BUDGET} calibration evaluations" in text
    adopted = RECORD["methods"]["order-tracking"]["adopted"]
    assert f"`q` = {adopted['q']:g}" in text
    assert "a variant" in text and "not in the built-ins' record" in text
    assert tuning_markdown(None, ["raw"]).startswith("Not recorded")


def _tune(*args):
    return subprocess.run([sys.executable, "-m", "rippleb", "tune", "--no-progress", *map(str, args)],
                          capture_output=True, text=True, timeout=600)


def test_tune_through_the_cli_writes_a_record_and_says_its_verdict(tmp_path):
    out = tmp_path / "tuning.json"
    proc = _tune("--methods", "lowpass,raw", "--budget", 3, "--seeds", "100", "--jobs", 1, "--out", out)
    assert proc.returncode == 0, proc.stderr
    record = json.loads(out.read_text())
    assert record["protocol"]["budget"] == 3 and record["protocol"]["seeds"] == [100]
    lowpass = record["methods"]["lowpass"]
    assert lowpass["evaluations"] == 3 and lowpass["default"] == {"cutoff_hz": 190.0}
    assert record["methods"]["raw"]["evaluations"] == 1
    assert "lowpass: default" in proc.stdout and "raw:" in proc.stdout


@pytest.mark.parametrize("args, message", [
    (("--methods", "no-such-method"), "no-such-method"),
    (("--seeds", "1-x"), "--seeds"),
    (("--budget", 0), "--budget"),
])
def test_bad_tune_options_are_one_line_exit_2(args, message):
    proc = _tune(*args)
    assert proc.returncode == 2 and message in proc.stderr
    assert len(proc.stderr.strip().splitlines()) == 1, proc.stderr


class _Entry:
    def __init__(self, cls, name):
        self.cls = cls
        self.name = name

    def load(self):
        return self.cls

    @property
    def module(self):
        return self.cls.__module__


class _Registry:
    def __init__(self, **classes):
        self.classes = classes

    def get(self, name):
        return _Entry(self.classes[name], name)


@pytest.mark.parametrize("tunable, message", [
    ({"q": (1, 2)}, r"cannot tune 'bad': ValueError: bad\.tunable\['q'\]"),
    ({"nope": (1.0, 2.0, "log")}, "get_params"),
])
def test_a_plugin_that_cannot_be_tuned_is_one_line_naming_it(tunable, message):
    from rippleb.methods.raw import Raw

    bad = type("Bad", (Raw,), {"tunable": tunable})
    with pytest.raises(PluginError, match=message):
        plan(["bad"], _Registry(bad=bad), 4)


def test_a_plugin_without_ranges_is_scored_at_its_defaults_once():
    from rippleb.methods.raw import Raw

    plain = type("Plain", (Raw,), {})                                    # raw's tunable = {}
    undeclared = type("Undeclared", (), {"get_params": lambda self: {}})  # no tunable at all
    planned = plan(["plain", "undeclared"], _Registry(plain=plain, undeclared=undeclared), 16)
    assert planned["plain"][1] == [{}] and "nothing to tune" in planned["plain"][2]
    assert planned["undeclared"][1] == [{}] and "no tunable ranges" in planned["undeclared"][2]

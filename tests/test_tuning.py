"""The one tuning protocol (rippleb/tuning.py): declared ranges, one sampler, one budget."""

import inspect
import json
from pathlib import Path
import subprocess
import sys

import numpy as np
import pytest
from hypothesis import given, strategies as st

from rippleb.engine.tuner import entry, plan
from rippleb.errors import PluginError
from rippleb.registry import Registry
from rippleb.report.tuning_table import tuning_markdown
from rippleb.tuning import (BUDGET, EVERY_DEVICE, PAIRED_SEEDS, PROTOCOL_RULE, RULE_ID, SEEDS, adopted, candidates, check_tunable, pvalues,
                            read_record, replaces_default, rule_of, summary)

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
def test_the_former_rule_replaced_only_a_default_beaten_on_every_device(pairs):
    default, best = [d for d, _ in pairs], [b for _, b in pairs]
    assert replaces_default(default, best) == all(b < d for d, b in pairs)


DEVICES = 20
DEFAULT = [1.0 + 0.02 * k for k in range(DEVICES)]    # devices differ far more than the points


def _point(shift, wobble=0.0):
    return [d + shift + wobble * ((-1) ** k) * (k + 1) / DEVICES for k, d in enumerate(DEFAULT)]


def test_a_point_lower_on_the_devices_by_the_paired_test_replaces_the_default():
    scores = [DEFAULT, _point(+0.03), _point(-0.02, 0.004), _point(-0.01, 0.002)]
    assert adopted(scores) == 2                                    # the lowest mean of those that pass
    p = pvalues(scores)
    assert np.isnan(p[0]) and p[1] > 0.5 and p[2] < 0.05 and p[3] < 0.05


def test_a_mean_won_on_a_few_devices_does_not_move_a_method():
    """The former rule's worry, under heavy tails: a point better by the mean because three
    devices gain a lot, while seventeen lose a little, is not adopted; nor is one that ties
    the default on every device."""
    tail = [d - (0.5 if k < 3 else -0.01 * (1 + k / 100)) for k, d in enumerate(DEFAULT)]
    assert np.mean(tail) < np.mean(DEFAULT)
    assert adopted([DEFAULT, tail, list(DEFAULT)]) == 0


@given(st.lists(st.integers(0, 64), min_size=DEVICES, max_size=DEVICES), st.integers(1, 40))
def test_the_rule_reads_per_device_differences_only(difficulty, gain):
    """Adding any per-device difficulty to every point changes nothing; a point never lower
    than the default on any device is never adopted."""
    base = [DEFAULT, _point(-gain / 1000, 0.001), _point(+gain / 1000)]
    moved = [[s + h / 64 for s, h in zip(point, difficulty)] for point in base]
    assert adopted(moved) == adopted(base)
    assert adopted([DEFAULT, _point(+gain / 1000), _point(0.0)]) == 0


def test_a_method_entry_keeps_the_default_unless_the_rule_says_otherwise():
    tried = [({"q": 30}, DEFAULT, ""), ({"q": 10}, _point(-0.5, 0.0)[:3] + _point(+0.01)[3:], ""),
             ({"q": 20}, _point(+0.001), "")]
    kept = entry({"q": (5, 50, "int")}, tried, "", 1.0, RULE_ID)
    assert kept["best"] == {"q": 10} and not kept["replaced"] and kept["adopted"] == {"q": 30}
    tried[2] = ({"q": 20}, _point(-0.02, 0.004), "")
    won = entry({"q": (5, 50, "int")}, tried, "", 1.0, RULE_ID)
    assert won["replaced"] and won["adopted"] == {"q": 20} and won["best"] == {"q": 10} and won["evaluations"] == 3
    assert won["points"][0]["p_holm"] is None and won["points"][2]["p_holm"] < 0.05


def test_a_failing_point_cannot_be_the_best_and_is_named():
    tried = [({"q": 30}, [1.0], ""), ({"q": 5}, [float("inf")], "ValueError: q too small")]
    record = entry({"q": (5, 50, "int")}, tried, "", 0.0)
    assert record["adopted"] == {"q": 30} and record["errors"] == ["ValueError: q too small"]


# ------------------------------------------------------------------ the built-ins' record
RECORD = read_record()


def test_the_tuning_devices_are_neither_development_nor_published_devices():
    for seeds in (SEEDS, PAIRED_SEEDS):   # development: the public seeds 0-99
        assert not set(seeds) & set(range(100))
    assert len(PAIRED_SEEDS) >= 10 and set(SEEDS) <= set(PAIRED_SEEDS)


def test_the_record_follows_its_own_rule_on_every_method():
    """Each verdict of the record is its rule applied to its own scores, and each method
    it records ran every point of the budget on every device without error."""
    rule = rule_of(RECORD)
    for name, method in RECORD["methods"].items():
        scores = [p["scores"] for p in method["points"]]
        assert method["adopted"] == method["points"][adopted(scores, rule)]["params"], name
        assert method["replaced"] == (method["adopted"] != method["default"]), name
        expected = RECORD["protocol"]["budget"] if method["tunable"] else 1
        assert method["evaluations"] == expected == len(method["points"]), name
        assert len(method["default_scores"]) == len(RECORD["protocol"]["seeds"]) and not method["errors"], name


def test_the_record_is_made_by_the_current_protocol():
    """Fails after a change of the protocol (its devices, budget or rule) until the built-ins
    are tuned again: ``rippleb tune --out methods/tuning.json`` (docs/tuning.md), then the
    defaults this file's next test names."""
    protocol = RECORD["protocol"]
    assert (protocol["budget"], protocol["seeds"], rule_of(RECORD)) == (BUDGET, list(SEEDS), PROTOCOL_RULE), \
        ("methods/tuning.json was made by another protocol (seeds "
         f"{protocol['seeds'][0]}-{protocol['seeds'][-1]}, rule {rule_of(RECORD)}): re-tune with "
         "'rippleb tune --out methods/tuning.json' and set the defaults it adopts (docs/tuning.md)")


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
        assert {p: defaults[p] for p in cls.tunable} == method["adopted"], \
            f"{name}: set its defaults to the adopted point {method['adopted']} of methods/tuning.json"


STABILITY = Path(__file__).resolve().parent.parent / "docs" / "tuning-stability"
TUNING_DOC = STABILITY.parent / "tuning.md"


def test_the_stability_table_is_what_compare_prints():
    """docs/tuning.md's stability table is what ``rippleb tune --compare`` prints for the two
    records of docs/tuning-stability/, and the built-ins' record is the first of them
    (docs/tuning.md, "Re-tuning after a change of the physics")."""
    from rippleb.report.tuning_stability import read, stability_markdown

    first, second = (read(STABILITY / name) for name in ("100-119.json", "5000-5019.json"))
    assert first == RECORD, "methods/tuning.json is not docs/tuning-stability/100-119.json"
    assert second["protocol"] == {**first["protocol"], "seeds": list(range(5000, 5020))}
    assert stability_markdown(first, second) in TUNING_DOC.read_text(), \
        "docs/tuning.md's stability table is stale: paste what 'rippleb tune --compare' prints"


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
    proc = _tune("--methods", "lowpass,raw", "--budget", 3, "--seeds", "100", "--jobs", 1, "--out", out,
                 "--rule", RULE_ID)
    assert proc.returncode == 0, proc.stderr
    record = json.loads(out.read_text())
    assert record["protocol"]["budget"] == 3 and record["protocol"]["seeds"] == [100]
    assert record["protocol"]["rule_id"] == RULE_ID
    lowpass = record["methods"]["lowpass"]
    assert lowpass["evaluations"] == 3 and lowpass["default"] == {"cutoff_hz": 190.0}
    assert not lowpass["replaced"]                       # one device: no paired test can pass
    assert record["methods"]["raw"]["evaluations"] == 1
    assert "lowpass: default" in proc.stdout and "raw:" in proc.stdout
    # the stability table of two disjoint sets; the same set twice is refused
    other = tmp_path / "other.json"
    assert _tune("--methods", "lowpass", "--budget", 3, "--seeds", "101", "--jobs", 1, "--out", other).returncode == 0
    table = _tune("--compare", out, other)
    assert table.returncode == 0, table.stderr
    assert "| `lowpass` " in table.stdout and "adopted on devices 100 " in table.stdout
    assert "methods with something to tune adopt the same point on both sets" in table.stdout
    same = _tune("--compare", out, out)
    assert same.returncode == 2 and "share devices [100]" in same.stderr
    # a run cut short goes on: the methods the record holds are kept, not tuned again
    again = _tune("--methods", "lowpass,raw,current-based", "--budget", 3, "--seeds", "100", "--jobs", 1, "--out", out,
                  "--rule", RULE_ID)
    assert again.returncode == 0, again.stderr
    assert "1 method(s)" in again.stderr and "2 already in" in again.stderr
    grown = json.loads(out.read_text())
    assert grown["methods"]["lowpass"] == lowpass and set(grown["methods"]) == {"lowpass", "raw", "current-based"}
    # ... and a record of another protocol is never mixed into this one
    other_rule = _tune("--methods", "current-based", "--budget", 3, "--seeds", "100", "--jobs", 1, "--out", out,
                       "--rule", EVERY_DEVICE)
    assert other_rule.returncode == 2 and "another protocol" in other_rule.stderr


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


def test_the_tuning_plan_runs_method_by_method_so_a_cut_short_tuning_keeps_whole_methods():
    """The scheduler starts rows in the plan's order: each method's points on every device
    come before the next method's, so its entry is recorded (and kept by ``--out``) early."""
    from rippleb.engine.tuner import tuning_plan

    labels = ["a[x=1]", "a[x=2]", "b[y=1]"]
    order = [key.method for key in tuning_plan(labels, [100, 101, 102]).rows]
    assert order == ["a[x=1]"] * 3 + ["a[x=2]"] * 3 + ["b[y=1]"] * 3

"""Method variants (``--methods 'order-tracking[q=20,30]'``): parsing, labels, checks, and the CLI."""

import json
import subprocess
import sys

import numpy as np
import pandas as pd
import pytest
from hypothesis import given
from hypothesis import strategies as st

from rippleb.errors import InputError
from rippleb.report.stats import method_order
from rippleb.variants import Variant, check_params, label, parse_label, parse_methods, signature_of

ORDER_TRACKING = {"params": {"q": "float", "orders": "tuple", "stop_after_s": "float", "dead_zone": "bool",
                             "back_propagation": "bool"}, "kwargs": False}


def labels(text):
    return [v.label for v in parse_methods(text)]


def test_a_list_of_values_gives_one_variant_per_value_in_the_order_written():
    assert labels("raw,order-tracking[q=30,20]") == ["raw", "order-tracking[q=30]", "order-tracking[q=20]"]


def test_benchopts_list_form_is_the_same_selection():
    assert labels("order-tracking[q=[20,30]]") == labels("order-tracking[q=20,30]")


def test_several_parameters_give_every_combination_the_first_varying_slowest():
    assert labels("m[a=1,2,b=x,y]") == ["m[a=1,b=x]", "m[a=1,b=y]", "m[a=2,b=x]", "m[a=2,b=y]"]


def test_values_are_toml_or_python_literals_or_bare_words():
    variant = parse_label("m[i=3,f=1e-3,t=true,T=False,s='a b',w=cd,q=\"x,y\"]")
    assert variant.params == {"i": 3, "f": 0.001, "t": True, "T": False, "s": "a b", "w": "cd", "q": "x,y"}
    assert [type(v) for v in variant.params.values()] == [int, float, bool, bool, str, str, str]


def test_a_variant_given_twice_runs_once():
    assert labels("raw,m[a=1],m[a=1]") == ["raw", "m[a=1]"]


@pytest.mark.parametrize("text, words", [
    ("m[q=20", ["'m[q=20'", "end the item"]),
    ("m[20]", ["'m'", "'20' has no parameter name"]),
    ("m[q=1,q=2]", ["'m'", "'q' is given twice"]),
    ("m[q=@]", ["'m'", "parameter 'q'", "'@' is not a value"]),
    ("m[q={a=1}]", ["'m'", "parameter 'q'", "is a dict"]),
    ("m[q=[]]", ["'m'", "parameter 'q' has no value"]),
])
def test_a_malformed_item_is_one_line_naming_the_method_and_the_parameter(text, words):
    with pytest.raises(InputError) as info:
        parse_methods(text)
    message = str(info.value)
    assert "\n" not in message and all(word in message for word in words), message


def test_a_label_names_one_variant():
    with pytest.raises(InputError, match="names 2 variants"):
        parse_label("m[q=1,2]")


scalars = st.one_of(st.booleans(), st.integers(-10**6, 10**6),
                    st.floats(allow_nan=False, allow_infinity=False, width=64),
                    st.text(st.characters(blacklist_categories=("Cs", "Cc")), max_size=12))
parameter_names = st.from_regex(r"[a-z_][a-z0-9_]{0,8}", fullmatch=True)


@given(st.dictionaries(parameter_names, scalars, max_size=4))
def test_a_label_reads_back_as_the_same_variant(params):
    variant = parse_label(label("m", params))
    assert variant.name == "m" and variant.params == params
    assert [type(v) for v in variant.params.values()] == [type(v) for v in params.values()]
    assert variant.label == label("m", params)


@given(st.dictionaries(parameter_names, st.lists(st.integers(-99, 99), min_size=1, max_size=3, unique=True),
                       min_size=1, max_size=3))
def test_an_item_names_one_variant_per_combination_of_its_values(grid):
    item = "m[" + ",".join(f"{k}={','.join(map(str, v))}" for k, v in grid.items()) + "]"
    variants = parse_methods(item)
    assert len(variants) == np.prod([len(v) for v in grid.values()])
    assert len({v.label for v in variants}) == len(variants)
    assert variants[0].params == {k: v[0] for k, v in grid.items()}
    assert variants[-1].params == {k: v[-1] for k, v in grid.items()}


def test_the_signature_of_a_method_names_each_parameter_with_its_defaults_type():
    from rippleb.methods.order_tracking import OrderTracking

    assert signature_of(OrderTracking) == ORDER_TRACKING


@pytest.mark.parametrize("params, words", [
    ({"qq": 20}, ["'order-tracking'", "unknown parameter 'qq'", "did you mean 'q'"]),
    ({"q": "abc"}, ["'order-tracking'", "parameter 'q'", "expected a float", "got a str"]),
    ({"q": True}, ["parameter 'q'", "got a bool"]),
    ({"orders": 2}, ["parameter 'orders'", "expected a tuple"]),
    ({"dead_zone": 1}, ["parameter 'dead_zone'", "expected a bool", "got an int"]),
])
def test_a_parameter_the_constructor_refuses_is_one_line(params, words):
    with pytest.raises(InputError) as info:
        check_params(Variant("order-tracking", params), ORDER_TRACKING)
    assert all(word in str(info.value) for word in words), str(info.value)


def test_a_method_without_a_constructor_takes_no_parameter():
    from rippleb.methods.raw import Raw

    assert signature_of(Raw) == {"params": {}, "kwargs": False}
    with pytest.raises(InputError, match="method 'raw': unknown parameter 'window'"):
        check_params(Variant("raw", {"window": 3}), signature_of(Raw))


def test_an_integer_is_a_float_value_and_kwargs_take_any_name():
    check_params(Variant("order-tracking", {"q": 20, "dead_zone": False}), ORDER_TRACKING)
    check_params(Variant("m", {"anything": 1}), {"params": {}, "kwargs": True})


def test_the_report_lists_variants_right_after_their_method_numbers_as_numbers():
    names = ["zed", "order-tracking[q=100]", "raw", "order-tracking", "order-tracking[q=30]", "lowpass"]
    assert method_order(names) == ["raw", "lowpass", "order-tracking", "order-tracking[q=30]",
                                   "order-tracking[q=100]", "zed"]


def rippleb(*args, cwd):
    return subprocess.run([sys.executable, "-m", "rippleb", *map(str, args)], capture_output=True,
                          text=True, cwd=cwd, timeout=900)


@pytest.mark.slow
@pytest.mark.parametrize("methods, words", [
    ("order-tracking[qq=20]", ["method 'order-tracking'", "unknown parameter 'qq'"]),
    ("order-tracking[q=fast]", ["method 'order-tracking'", "parameter 'q'", "expected a float"]),
    ("order-tracking[q=20", ["the parameters in brackets must end the item"]),
])
def test_the_cli_refuses_a_bad_parameter_in_one_line_before_the_run(tmp_path, methods, words):
    proc = rippleb("run", "--methods", methods, "--scenarios", "paper-quintic", "--seeds", "1",
                   "--out", tmp_path / "run", "--no-progress", cwd=tmp_path)
    assert proc.returncode == 2, proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and all(word in lines[0] for word in words), proc.stderr
    assert not (tmp_path / "run").exists()


@pytest.mark.slow
@pytest.mark.heavy
def test_two_variants_run_resume_and_are_named_in_the_report(tmp_path):
    out = tmp_path / "run"
    proc = rippleb("run", "--methods", "order-tracking[q=20,30]", "--scenarios", "paper-quintic",
                   "--seeds", "1", "--jobs", "2", "--out", out, "--no-progress", cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    rows = pd.read_csv(out / "results.csv").set_index("method")
    assert list(rows.index) == ["order-tracking[q=20]", "order-tracking[q=30]"]
    assert (rows["status"] == "ok").all()
    assert [json.loads(p)["q"] for p in rows["params"]] == [20, 30]
    assert rows.loc["order-tracking[q=20]", "rms_error_nm"] != rows.loc["order-tracking[q=30]", "rms_error_nm"]
    assert json.loads((out / "run.json").read_text())["methods"] == list(rows.index)

    # the labels in run.json select the same variants again: nothing is left to run
    again = rippleb("run", "--resume", out, "--no-progress", cwd=tmp_path)
    assert again.returncode == 0, again.stderr
    kept = ["status", "params", "rms_error_nm", "us_per_tick_p50"]  # timings too: the rows did not run again
    pd.testing.assert_frame_equal(pd.read_csv(out / "results.csv").set_index("method")[kept], rows[kept])

    report = rippleb("report", out, "--out", tmp_path / "report", cwd=tmp_path)
    assert report.returncode == 0, report.stderr
    text = (tmp_path / "report" / "README.md").read_text()
    assert "order-tracking[q=20]" in text and "order-tracking[q=30]" in text

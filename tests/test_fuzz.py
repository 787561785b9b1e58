"""Property tests (hypothesis) of issue 7's acceptance: random scenario files and logs never
give a traceback through the CLI; either a valid result or one ``rippleb: error:`` line.

The CLI is called in this process (``rippleb.cli.main``): an exception other than the
errors it turns into one line would escape and fail the test, exactly where the command
would print a traceback. Numeric durations are kept short so valid files simulate quickly.
"""

from __future__ import annotations

import contextlib
import io
import json
import math
import os
import string
import tempfile
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from rippleb.cli import main

# Derandomized, so the suite is reproducible; RIPPLEB_FUZZ_EXAMPLES=500 RIPPLEB_FUZZ_RANDOM=1 hunts longer.
SETTINGS = dict(deadline=None, suppress_health_check=[HealthCheck.too_slow, HealthCheck.filter_too_much],
                derandomize=not os.environ.get("RIPPLEB_FUZZ_RANDOM"))
SCALE = int(os.environ.get("RIPPLEB_FUZZ_EXAMPLES", "0")) or None

_text = st.text(alphabet=string.ascii_letters + string.digits + " _-./'\"\\", max_size=12)
_any = st.one_of(st.floats(allow_nan=True, allow_infinity=True), st.integers(-10**12, 10**12),
                 st.booleans(), _text)
_short = st.one_of(st.floats(-0.2, 0.4), st.integers(-1, 0), st.booleans(), _text)  # durations
_small = st.one_of(st.floats(-3.0, 3.0), st.integers(-3, 3), _any)


def _mostly(valid, bad=_any) -> st.SearchStrategy:
    """``valid`` three times in four, else ``bad``: most files are valid or nearly so."""
    return st.sampled_from(range(4)).flatmap(lambda i: bad if i == 3 else valid)


def _rarely(valid, bad) -> st.SearchStrategy:
    """``bad`` once in eight: for mistakes that every table could have."""
    return st.sampled_from(range(8)).flatmap(lambda i: bad if i == 7 else valid)


def _maybe_extra(d: dict) -> st.SearchStrategy:
    """The dict, sometimes with an unknown key added."""
    return _rarely(st.just(d), st.builds(lambda k, v: {**d, k: v},
                                         st.text(alphabet=string.ascii_lowercase + "_", min_size=1,
                                                 max_size=8), _any))


def _table(required: dict, optional: dict) -> st.SearchStrategy:
    return st.fixed_dictionaries(required, optional=optional).flatmap(_maybe_extra)


_duration = _mostly(st.floats(0.05, 0.3), _short)
_hold = _table({"kind": st.just("hold"), "duration": _duration}, {})
_move = _rarely(st.one_of(_table({"kind": st.just("move"), "duration": _duration,
                                  "by": _mostly(st.floats(-0.5, 0.5), _small)}, {}),
                           _table({"kind": st.just("move"), "duration": _duration,
                                   "to": _mostly(st.floats(-2.5, -1.0), _small)}, {})),
                 _table({"kind": st.just("move"), "duration": _duration},
                        {"by": _small, "to": _small}))
_ramp = _table({"kind": st.sampled_from(["ramp", "cruise", "jump", 3]), "duration": _duration},
               {"velocity": _mostly(st.floats(-0.5, 0.5), _small), "shape": st.sampled_from(["smooth", "linear", "wavy"])})
_ramp_up_down = st.builds(lambda v, d1, d2, d3, shape: [
    {"kind": "ramp", "velocity": v, "duration": d1, "shape": shape},
    {"kind": "cruise", "duration": d2}, {"kind": "ramp", "velocity": 0.0, "duration": d3}],
    st.floats(-0.5, 0.5), st.floats(0.05, 0.2), st.floats(0.0, 0.2).filter(lambda d: d != 0) | st.just(0.1),
    st.floats(0.05, 0.2), st.sampled_from(["smooth", "linear"]))
_segments = st.lists(st.one_of(_hold.map(lambda s: [s]), _move.map(lambda s: [s]), _ramp_up_down,
                               _ramp.map(lambda s: [s])), min_size=1, max_size=3).map(
    lambda parts: [seg for part in parts for seg in part])
_fault_values = {"encoder_missed": _mostly(st.floats(0, 0.05), st.floats(-0.5, 1.5) | _any),
                 "encoder_spurious_rate": _mostly(st.floats(0, 500)),
                 "strain_full_scale": _mostly(st.floats(0.5, 20)),
                 "dropout_rate": _mostly(st.floats(0, 50)),
                 "dropout_length": _mostly(st.floats(0, 0.01)),
                 "bridge_drift": _mostly(st.floats(-1, 1), _small),
                 "current_offset": _mostly(st.floats(-1, 1), _small)}
_faults = _table({}, _fault_values)
_scenario = _table({"trajectory": _table({"segment": _rarely(_segments, st.just([]))},
                                         {"start": _mostly(st.floats(-2.5, -1.0), _small)})},
                   {"description": _text, "scored": _mostly(st.booleans()),
                    "duration": _duration, "temperature_c": _mostly(st.floats(-60, 200)),
                    "joint": _table({}, {"fs": st.sampled_from([20000.0, 5000, 0.0, -1.0, 1e9, "fast"]),
                                         "control_rate": st.sampled_from([1000.0, 500, 4e4, 0]),
                                         "gear_ratio": _mostly(st.floats(-10, 200)),
                                         "counts_per_rev": _mostly(st.integers(-5, 5000))}),
                    "robot": _table({}, {"name": st.sampled_from(["ur5", "ur5", "panda", "ur55", ""]),
                                         "joint": st.sampled_from(["shoulder_lift_joint", "elbow_joint",
                                                                   "panda_joint2", "knee"]),
                                         "posture": st.dictionaries(
                                             st.sampled_from(["elbow_joint", "wrist_1_joint", "knee"]),
                                             _mostly(st.floats(-3, 3), _small), max_size=2)}),
                    "evaluation": _table({}, {"start": _mostly(st.floats(0, 0.2), _small),
                                              "stop": _mostly(st.floats(0.1, 0.6), _small)}),
                    "load": st.lists(_table({"torque": _mostly(st.floats(-60, 60), _small),
                                             "start": _mostly(st.floats(0, 0.3), _small)},
                                            {"stop": _mostly(st.floats(0.3, 1), _small),
                                             "rise": _mostly(st.floats(0.001, 0.05), _small),
                                             "known": _mostly(st.booleans())}), max_size=2),
                    "faults": _faults})


def _toml_value(v) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, float):
        return "nan" if math.isnan(v) else ("inf" if v > 0 else "-inf") if math.isinf(v) else repr(v)
    if isinstance(v, int):
        return str(v)
    if isinstance(v, str):
        return json.dumps(v)
    if isinstance(v, dict):
        return "{ " + ", ".join(f"{json.dumps(k)} = {_toml_value(x)}" for k, x in v.items()) + " }"
    if isinstance(v, list):
        return "[ " + ", ".join(_toml_value(x) for x in v) + " ]"
    raise TypeError(v)


def to_toml(doc: dict) -> str:
    """A TOML document of ``doc``; top-level tables and arrays as inline values (valid TOML)."""
    return "".join(f"{json.dumps(k)} = {_toml_value(v)}\n" for k, v in doc.items())


def _cli(*argv) -> tuple[int, str]:
    err = io.StringIO()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
        code = main([str(a) for a in argv])
    return code, err.getvalue()


def _assert_one_line(code: int, err: str, name: str):
    assert code == 2, (code, err)
    assert err.startswith("rippleb: error: ") and err.count("\n") == 1, err
    assert name in err, err


@pytest.mark.slow
@settings(max_examples=SCALE or 60, **SETTINGS)
@given(doc=_scenario, garbage=_rarely(st.none(), st.text(max_size=40)))
def test_random_scenario_files_give_a_log_or_one_line(doc, garbage):
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "fuzz.toml"
        path.write_text(garbage if garbage is not None else to_toml(doc), encoding="utf-8",
                        errors="replace")
        out = Path(tmp) / "log.csv"
        code, err = _cli("simulate", path, "--out", out)
        if code == 0:
            frame = pd.read_csv(out)
            assert list(frame.columns) == ["t", "strain", "encoder", "current", "index", "torque_true",
                                           "torque_ref"]
            assert len(frame) >= 2 and np.isfinite(frame.to_numpy()).all()
        else:
            _assert_one_line(code, err, str(path))
            assert not out.exists()


def _column(kind: str, n: int, rng: np.random.Generator):
    if kind == "float":
        return rng.normal(size=n)
    if kind == "int":
        return rng.integers(-100, 100, size=n)
    if kind == "nan":
        values = rng.normal(size=n)
        values[rng.integers(0, n)] = rng.choice([np.nan, np.inf, -np.inf])
        return values
    if kind == "bool":
        return rng.normal(size=n) > 0
    if kind == "scaled":  # overflows the scores, or underflows to subnormal values
        return rng.normal(size=n) * rng.choice([1e306, 1e-310])
    return np.array(["x" + str(i) for i in range(n)], dtype=object)


_GOOD_COLUMNS = {"strain": "float", "encoder": "float", "current": "float", "torque_ref": "float"}
_log = st.fixed_dictionaries({
    # mostly shorter than the 0.2 s a log needs to be scored, sometimes long enough
    "n": st.one_of(st.integers(0, 120), st.just(4000)),
    "seed": st.integers(0, 2**16),
    "t": _mostly(st.just("grid"), st.sampled_from(["repeat", "back", "gap", "random", "text", "missing"])),
    "fs": st.sampled_from([20_000.0, 1_000.0, 3.0]),
    # start from a good log; spoil, drop or add up to two columns
    "changes": st.dictionaries(st.sampled_from(["strain", "encoder", "current", "torque_ref", "torque_true",
                                                "extra"]),
                               st.sampled_from(["float", "int", "nan", "text", "drop", "bool", "scaled"]),
                               max_size=2),
    "suffix": st.sampled_from([".csv", ".parquet"]),
})


@pytest.mark.slow
@settings(max_examples=SCALE or 40, **SETTINGS)
@given(spec=_log)
def test_random_logs_give_rows_or_one_line(spec):
    n, rng = spec["n"], np.random.default_rng(spec["seed"])
    frame = {}
    t = np.arange(n) / spec["fs"]
    if n > 3 and spec["t"] == "repeat":
        t[n // 2] = t[n // 2 - 1]
    elif n > 3 and spec["t"] == "back":
        t[n // 2] = t[n // 2 - 2]
    elif n > 3 and spec["t"] == "gap":
        t[n // 2:] += 0.5
    elif spec["t"] == "random":
        t = rng.normal(size=n)
    if spec["t"] == "text":
        frame["t"] = _column("text", n, rng)
    elif spec["t"] != "missing":
        frame["t"] = t
    columns = {**_GOOD_COLUMNS, **spec["changes"]}
    for name, kind in columns.items():
        if kind != "drop":
            frame[name] = _column(kind, n, rng) if n else np.array([], dtype=float)
    if columns.get("encoder") == "float" and n:
        frame["encoder"] = np.round(frame["encoder"] * 100)   # integer counts stored as floats
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / f"rec{spec['suffix']}"
        data = pd.DataFrame(frame)
        if spec["suffix"] == ".csv":
            data.to_csv(path, index=False)
        else:
            data.to_parquet(path, index=False)
        out = Path(tmp) / "out"
        code, err = _cli("run", "--log", path, "--methods", "raw", "--jobs", "1", "--out", out,
                         "--no-progress", "--timeout", "60")
        if code == 0:
            rows = pd.read_csv(out / "results.csv")
            assert len(rows) == 1 and rows.loc[0, "status"] in ("ok", "invalid", "error"), rows
            assert rows.loc[0, "scenario"] == f"log:{path.name}"
        else:
            _assert_one_line(code, err, path.name)
            assert not (out / "results.csv").exists()

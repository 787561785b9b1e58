"""Faulty sensors as scenario options (issue 7, item 2).

Unit checks of each fault on the simulated log, validation of the ``[faults]`` table, and
every built-in method run under every fault: each row is ``ok`` with finite metrics or
``invalid``, never a crash. A fault changes only the channels of its own sensor.
"""

from __future__ import annotations

import importlib.util
from pathlib import Path

import numpy as np
import pytest

import rippleb
from rippleb import InputError, make_log
from rippleb.simulator.scenario import Faults, scenario_from_dict
from rippleb.simulator import simulate
from rippleb.simulator.sensors import STRAIN_RANGE

ROOT = Path(__file__).resolve().parents[1]
_spec = importlib.util.spec_from_file_location("fault_table", ROOT / "docs" / "tables" / "fault_table.py")
fault_table = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(fault_table)

BASE = {"robot": {"posture": {"elbow_joint": 1.5}},
        "trajectory": {"start": -1.8, "segment": [{"kind": "hold", "duration": 0.1},
                                                  {"kind": "move", "by": 0.3, "duration": 0.4},
                                                  {"kind": "hold", "duration": 0.3}]}}


def sim(faults=None, seed=0):
    raw = dict(BASE, **({"faults": faults} if faults is not None else {}))
    return simulate(scenario_from_dict(raw, name="faulty"), seed)


@pytest.fixture(scope="module")
def healthy():
    return sim()


def test_no_fault_and_zero_faults_are_the_same_log(healthy):
    zeros = sim({"encoder_missed": 0.0, "encoder_spurious_rate": 0.0, "dropout_rate": 0.0,
                 "bridge_drift": 0.0, "current_offset": 0.0})
    for name, values in healthy.log.columns().items():
        np.testing.assert_array_equal(getattr(zeros.log, name), values)
    assert not Faults().active and "faults" not in healthy.log.meta


@pytest.mark.parametrize("faults, touched", [
    ({"encoder_missed": 0.01}, {"encoder"}),
    ({"encoder_spurious_rate": 100.0}, {"encoder"}),
    ({"strain_full_scale": 1.0}, {"strain"}),
    ({"dropout_rate": 20.0, "dropout_length": 0.002}, {"strain", "encoder", "current"}),
    ({"bridge_drift": 0.2}, {"strain"}),
    ({"current_offset": 0.5}, {"current"}),
])
def test_each_fault_touches_only_its_own_sensors(healthy, faults, touched):
    faulty = sim(faults)
    for name, values in healthy.log.columns().items():
        if name in touched:
            assert not np.array_equal(getattr(faulty.log, name), values), name
        elif name == "index" and "dropout_rate" in faults:
            # a pulse inside a lost frame is lost with it (never invented)
            assert np.all(faulty.log.index <= values)
        else:
            np.testing.assert_array_equal(getattr(faulty.log, name), values, err_msg=name)
    assert faulty.log.meta["faults"] == faults


def test_current_offset_shifts_the_current(healthy):
    faulty = sim({"current_offset": 0.5})
    # +0.5 A, up to one 12-bit step of 40 A / 4096 either way, except where the ADC clips
    inside = np.abs(healthy.log.current) < 19.0
    shift = (faulty.log.current - healthy.log.current)[inside]
    assert inside.mean() > 0.99
    assert abs(np.median(shift) - 0.5) < 0.01 and np.abs(shift - 0.5).max() <= 40 / 4096 + 1e-12


def test_missed_counts_make_the_counter_fall_behind(healthy):
    faulty = sim({"encoder_missed": 0.02})
    travel = healthy.log.encoder[-1] - healthy.log.encoder[0]
    lost = travel - (faulty.log.encoder[-1] - faulty.log.encoder[0])
    assert travel > 5000
    assert 0.015 * travel < lost < 0.025 * travel          # binomial: 2 % +- many sigma
    # monotonic move: the faulty counter never runs ahead, and never moves where the true one rests
    assert np.all(np.diff(faulty.log.encoder) * np.sign(travel) >= 0)
    still = np.diff(healthy.log.encoder) == 0
    assert np.all(np.diff(faulty.log.encoder)[still] == 0)


def test_spurious_counts_appear_at_rest(healthy):
    faulty = sim({"encoder_spurious_rate": 500.0})
    still = np.diff(healthy.log.encoder) == 0
    glitches = np.count_nonzero(np.diff(faulty.log.encoder)[still])
    expected = 500.0 * still.sum() / healthy.log.spec.fs
    assert 0.6 * expected < glitches < 1.4 * expected
    assert set(np.unique(np.diff(faulty.log.encoder)[still])) <= {-2, -1, 0, 1, 2}


def test_a_lower_full_scale_clips_the_strain(healthy):
    faulty = sim({"strain_full_scale": 1.0})
    assert np.abs(healthy.log.strain).max() > 1.5           # the healthy peaks exceed 1 V
    assert np.abs(faulty.log.strain).max() <= 1.0
    inside = np.abs(healthy.log.strain) < 0.9
    # the same 16-bit ADC on a tenth of the range: finer steps inside, clipped outside
    assert np.abs(faulty.log.strain[inside] - healthy.log.strain[inside]).max() <= 2 * STRAIN_RANGE / 2**16
    assert np.mean(np.abs(faulty.log.strain) >= 0.999) > 0.1


def test_dropouts_hold_the_last_sample_on_an_unbroken_grid(healthy):
    faulty = sim({"dropout_rate": 20.0, "dropout_length": 0.005})
    np.testing.assert_array_equal(faulty.log.t, healthy.log.t)
    changed = ((faulty.log.strain != healthy.log.strain) | (faulty.log.current != healthy.log.current)
               | (faulty.log.encoder != healthy.log.encoder))
    # about 20/s x 5 ms = 10 % of the samples are replaced...
    assert 0.03 < changed.mean() < 0.2 and not changed[0]
    # ...each by the sample before it, on every channel at once
    for name in ("strain", "current", "encoder"):
        values = getattr(faulty.log, name)
        np.testing.assert_array_equal(values[1:][changed[1:]], values[:-1][changed[1:]])
    # the log passes the schema check
    make_log(faulty.log.spec, faulty.log.columns(), source="dropouts")


def test_bridge_drift_adds_a_ramp(healthy):
    faulty = sim({"bridge_drift": 0.2})
    extra = faulty.log.strain - healthy.log.strain
    step = 2 * STRAIN_RANGE / 2**16
    assert np.abs(extra - 0.2 * healthy.log.t).max() <= step


@pytest.mark.parametrize("faults, key, words", [
    ({"encoder_missed": -0.1}, "faults.encoder_missed", "probability"),
    ({"encoder_missed": 2}, "faults.encoder_missed", "probability"),
    ({"encoder_spurious_rate": 1e9}, "faults.encoder_spurious_rate", "fs"),
    ({"strain_full_scale": 0.0}, "faults.strain_full_scale", "0.001"),
    ({"dropout_rate": 5.0}, "faults.dropout_length", "positive"),
    ({"bridge_drift": "fast"}, "faults.bridge_drift", "number"),
    ({"current_offset": True}, "faults.current_offset", "number"),
    ({"gremlins": 1.0}, "faults.gremlins", "unknown key"),
])
def test_bad_fault_values_are_refused(faults, key, words):
    with pytest.raises(InputError) as err:
        scenario_from_dict(dict(BASE, faults=faults), name="f")
    assert f"<f>: {key}:" in str(err.value) and words in str(err.value)


@pytest.fixture(scope="module")
def fault_rows(tmp_path_factory):
    paths = fault_table.write_scenarios(tmp_path_factory.mktemp("faults"))
    return rippleb.run(methods=None, scenarios=[str(p) for p in paths], seeds=[0], jobs=2)


@pytest.mark.slow
def test_every_builtin_method_survives_every_fault(fault_rows):
    from rippleb.registry import Registry

    methods = set(Registry.discover().names("builtin"))
    assert set(fault_rows.method) == methods and set(fault_rows.scenario) == set(fault_table.FAULTS)
    assert len(fault_rows) == len(methods) * len(fault_table.FAULTS)
    bad = fault_rows[~fault_rows.status.isin(["ok", "invalid"])]
    assert bad.empty, bad[["method", "scenario", "status", "message"]].to_string()
    ok = fault_rows[fault_rows.status == "ok"]
    assert np.isfinite(ok[["rms_error_nm", "max_error_nm", "rms_error_ref_nm"]].to_numpy()).all()


@pytest.mark.slow
def test_the_results_show_the_faults(fault_rows):
    # (each fault file has its own name, hence its own noise: only large effects compare)
    rms = fault_rows.pivot(index="method", columns="scenario", values="rms_error_nm")
    # clipping at 1 V (about 10 Nm) wrecks every strain-based estimate
    for method in ("raw", "lowpass", "order-tracking", "switched-notch", "kalman-ripple"):
        assert rms.loc[method, "strain-clipping"] > rms.loc[method, "no-fault"] + 5.0, method
    # the current-based estimate does not read strain
    assert abs(rms.loc["current-based", "strain-clipping"] - rms.loc["current-based", "no-fault"]) < 1.0

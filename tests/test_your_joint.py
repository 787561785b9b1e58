"""Issue 32: each row of its first table, through the real command.

The fast cases run ``rippleb.cli.main`` in this process on a small synthetic recording; the
worked example of docs/your-joint.md runs as ``python -m rippleb`` subprocesses (slow).
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from rippleb.cli import main

ROOT = Path(__file__).resolve().parents[1]

FS = 20_000.0
METHODS = "raw,lowpass"


def _frame(n: int = 8000, seed: int = 0) -> pd.DataFrame:
    """A plausible recording: a 3 Hz torque, strain at 0.1 V/Nm, an encoder turning."""
    t = np.arange(n) / FS
    torque = 5.0 * np.sin(2 * np.pi * 3 * t) + 2.0 + np.random.default_rng(seed).normal(0, 0.05, n)
    return pd.DataFrame({"t": t, "strain": 0.1 * torque, "encoder": np.arange(n) // 4,
                         "current": 0.01 * torque, "torque_ref": torque})


def _run(tmp_path, monkeypatch, capsys, *args):
    monkeypatch.chdir(tmp_path)
    code = main(["run", *args, "--methods", METHODS, "--jobs", "1", "--no-progress", "--out", "out"])
    captured = capsys.readouterr()
    rows = pd.read_csv(tmp_path / "out" / "results.csv") if (tmp_path / "out" / "results.csv").is_file() else None
    return code, captured.err, rows


def test_a_run_says_what_it_assumed_before_it_starts(tmp_path, monkeypatch, capsys):
    _frame().to_csv(tmp_path / "rec.csv", index=False)
    code, err, rows = _run(tmp_path, monkeypatch, capsys, "--log", "rec.csv")
    assert code == 0, err
    assert "counts_per_rev = 2500 (ASSUMED (rippleb's default);" in err
    assert "column strain = 'strain' in V (ASSUMED" in err
    assert err.index("counts_per_rev") < err.index("no --calibration")   # before the run, not after


def test_daq_names_and_units_are_read_through_the_joint_file(tmp_path, monkeypatch, capsys):
    frame = _frame()
    daq = pd.DataFrame({"t": frame.t * 1e3, "enc_counts": frame.encoder, "strain_mV": frame.strain * 1e3,
                        "i_motor_A": frame.current, "tau_ref": frame.torque_ref})
    daq.to_csv(tmp_path / "daq.csv", index=False)
    frame.to_csv(tmp_path / "rec.csv", index=False)
    (tmp_path / "joint.toml").write_text(
        '[joint.columns]\nt = {column = "t", unit = "ms"}\nstrain = {column = "strain_mV", unit = "mV"}\n'
        'encoder = "enc_counts"\ncurrent = "i_motor_A"\ntorque_ref = "tau_ref"\n')
    code, err, plain = _run(tmp_path, monkeypatch, capsys, "--log", "rec.csv")
    assert code == 0, err
    os.rename(tmp_path / "out", tmp_path / "plain")
    code, err, mapped = _run(tmp_path, monkeypatch, capsys, "--log", "daq.csv", "--joint", "joint.toml")
    assert code == 0, err
    assert (mapped.status == "ok").all()
    np.testing.assert_allclose(mapped.sort_values("method").rms_error_ref_nm,
                               plain.sort_values("method").rms_error_ref_nm, rtol=1e-6, atol=1e-9)


def test_mv_against_v_is_one_line_naming_the_strain_not_a_ranking(tmp_path, monkeypatch, capsys):
    """Issue 39: strain in V labelled mV ran every method, 13 of 14 rows invalid, exit 0 and
    current-based printed 'rank 1'; now the log is refused before any row runs."""
    frame = _frame()
    frame.assign(strain=frame.strain * 1e3).to_csv(tmp_path / "rec.csv", index=False)   # mV, unsaid
    _frame(int(1.2 * FS), seed=1).to_csv(tmp_path / "cal.csv", index=False)                # V
    code, err, rows = _run(tmp_path, monkeypatch, capsys, "--log", "rec.csv", "--calibration", "cal.csv")
    assert code == 2 and err.count("\n") == 1 and rows is None, err
    assert err.startswith("rippleb: error: rec.csv: column strain ('strain' in V): calibrated as the calibration "
                          "log's strain, it reads up to "), err
    assert "the two logs' strain units differ (strain in V labelled mV reads 1000 times too large)" in err
    (tmp_path / "rec.toml").write_text('[joint.columns]\nstrain = {column = "strain", unit = "mV"}\n')
    code, err, rows = _run(tmp_path, monkeypatch, capsys, "--log", "rec.csv", "--calibration", "cal.csv")
    assert code == 0 and (rows.status == "ok").all() and (rows.rms_error_ref_nm < 1.0).all(), rows   # its sidecar says mV


def test_a_log_without_reference_says_what_can_and_cannot_be_scored(tmp_path, monkeypatch, capsys):
    _frame().drop(columns="torque_ref").to_csv(tmp_path / "rec.csv", index=False)
    _frame(int(1.2 * FS), seed=1).to_csv(tmp_path / "cal.csv", index=False)
    code, err, rows = _run(tmp_path, monkeypatch, capsys, "--log", "rec.csv", "--calibration", "cal.csv")
    assert code == 0, err
    assert "rec.csv has no reference torque (torque_ref): its rows get status no-reference" in err
    assert (rows.status == "no-reference").all()
    assert rows.message.str.contains("its accuracy cannot be scored").all()
    assert rows.rms_error_ref_nm.isna().all() and (rows.us_per_tick_p50 > 0).all()   # cost is measured


def test_jitter_is_refused_with_the_hint_and_resampled_on_request(tmp_path, monkeypatch, capsys):
    frame = _frame(20_000)
    frame["t"] = frame.t + np.random.default_rng(3).normal(0.0, 5e-6, len(frame))   # 5 us DAQ jitter
    frame.to_csv(tmp_path / "rec.csv", index=False)
    code, err, _ = _run(tmp_path, monkeypatch, capsys, "--log", "rec.csv")
    assert code == 2 and err.count("\n") == 1 and "Traceback" not in err, err
    assert err.startswith("rippleb: error: rec.csv: column t has a step of") and "pass --resample" in err
    assert not (tmp_path / "out").exists()
    code, err, rows = _run(tmp_path, monkeypatch, capsys, "--log", "rec.csv", "--resample")
    assert code == 0, err
    assert (rows.status == "ok").all() and (rows.rms_error_ref_nm < 1.0).all()
    fs = float(re.search(r"fs = ([0-9.]+) Hz \(from column t", err).group(1))
    assert fs == pytest.approx(FS, rel=1e-4)   # the mean rate: the end stamps jitter too


def test_epoch_stamps_in_both_logs_are_one_rate(tmp_path, monkeypatch, capsys):
    for name, n, seed in (("rec.csv", 8000, 0), ("cal.csv", int(1.2 * FS), 1)):
        frame = _frame(n, seed)
        frame.assign(t=1.764e9 + frame.t).to_csv(tmp_path / name, index=False)
    code, err, rows = _run(tmp_path, monkeypatch, capsys, "--log", "rec.csv", "--calibration", "cal.csv")
    assert code == 0, err
    assert "record both at one rate" not in err and "fs = 20000 Hz" in err
    assert (rows.status == "ok").all()


@pytest.mark.parametrize("text, says", [
    ("[joint]\ncountsperrev = 16384\n", "joint.toml: joint.countsperrev: unknown key"),
    ('[joint.columns]\nstrain = {column = "strain", unit = "volts"}\n',
     "joint.toml: joint.columns.strain.unit: 'volts' is not a unit of strain"),
    ('[joint.columns]\ncurrent = "i_motor_A"\n', "joint.toml: joint.columns.current: rec.csv has no column 'i_motor_A'"),
])
def test_a_bad_joint_file_is_one_line_and_exit_2(text, says, tmp_path, monkeypatch, capsys):
    _frame().to_csv(tmp_path / "rec.csv", index=False)
    (tmp_path / "joint.toml").write_text(text)
    code, err, _ = _run(tmp_path, monkeypatch, capsys, "--log", "rec.csv", "--joint", "joint.toml")
    assert code == 2 and err.count("\n") == 1 and err.startswith(f"rippleb: error: {says}"), err
    assert not (tmp_path / "out").exists()


def test_joint_and_resample_need_a_log(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    assert main(["run", "--methods", "raw", "--scenarios", "creep", "--joint", "j.toml", "--out", "o"]) == 2
    assert capsys.readouterr().err == "rippleb: error: --joint only applies with --log\n"


def _cli(*args, cwd: Path) -> subprocess.CompletedProcess:
    # 20 min: each command takes seconds to a minute here; a loaded 2-core machine is slower
    return subprocess.run([sys.executable, "-m", "rippleb", *args], cwd=cwd, capture_output=True,
                          text=True, timeout=1200)


@pytest.mark.slow
@pytest.mark.heavy
def test_the_walk_of_docs_your_joint(tmp_path):
    """docs/your-joint.md's numbers are what its walk prints today: the script runs every command
    of the page (lab logs of both kinds of reference to rankings, the refusals) and compares."""
    done = subprocess.run([sys.executable, str(ROOT / "benchmarks" / "your_joint_walk.py"), "--out",
                           str(tmp_path / "walk"), "--check"], capture_output=True, text=True, timeout=3600)
    assert done.returncode == 0, done.stdout[-4000:] + done.stderr[-2000:]


@pytest.mark.slow
@pytest.mark.heavy
def test_a_lab_log_reads_as_the_same_log_in_rippleb_columns_through_python(tmp_path):
    """The lab log through its joint file, and the same log in rippleb's columns read from Python
    with JointSpec(counts_per_rev=4096), give the same numbers."""
    joint = ("--param", "joint.counts_per_rev=4096", "--param", "joint.gear_ratio=160")
    for scenario, out in (("calibration", "cal.csv"), ("paper-quintic", "rec.csv")):
        done = _cli("simulate", scenario, "--format", "lab", *joint, "--out", out, cwd=tmp_path)
        assert done.returncode == 0, done.stderr
    rec = pd.read_csv(tmp_path / "rec.csv")
    assert list(rec.columns) == ["t", "strain_mV", "enc_counts", "i_motor_A", "idx", "torque_sensor_Nm"]
    pd.DataFrame({"t": rec.t / 1e3, "strain": rec.strain_mV / 1e3, "encoder": rec.enc_counts,
                  "current": rec.i_motor_A, "torque_ref": rec.torque_sensor_Nm}).to_csv(tmp_path / "plain.csv",
                                                                                     index=False)
    (tmp_path / "j4096.toml").write_text('[joint]\ncounts_per_rev = 4096\ngear_ratio = 160.0\n'
                                         '[joint.reference]\nkind = "transducer"\n')
    done = _cli("run", "--log", "plain.csv", "--joint", "j4096.toml", "--methods", "raw,order-tracking",
                "--jobs", "1", "--no-progress", "--out", "cli", cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    script = ("import rippleb, sys; f = rippleb.run_log(rippleb.read_log('plain.csv', "
              "spec=rippleb.JointSpec(counts_per_rev=4096, gear_ratio=160.0)), methods='raw,order-tracking'); "
              "f.to_csv('python.csv', index=False)")
    done = subprocess.run([sys.executable, "-c", script], cwd=tmp_path, capture_output=True, text=True, timeout=1200)
    assert done.returncode == 0, done.stderr
    cli = pd.read_csv(tmp_path / "cli" / "results.csv").set_index("method").rms_error_ref_nm
    python = pd.read_csv(tmp_path / "python.csv").set_index("method").rms_error_ref_nm
    np.testing.assert_allclose(cli.sort_index(), python.sort_index(), rtol=0.02)

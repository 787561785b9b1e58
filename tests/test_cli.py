"""End to end through the real command (``python -m rippleb`` in a subprocess)."""

import argparse
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

ROOT = Path(__file__).resolve().parents[1]


def rippleb(*args, cwd=None, env=None, timeout=300):
    return subprocess.run([sys.executable, "-m", "rippleb", *map(str, args)], capture_output=True,
                          text=True, cwd=cwd, env=env, timeout=timeout)


def test_help_of_every_command():
    from rippleb.cli.program import build_parser

    commands = next(a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction)).choices
    for command in ([], *([name] for name in commands)):
        proc = rippleb(*command, "--help")
        assert proc.returncode == 0 and "usage: rippleb" in proc.stdout, (command, proc.stderr)
        # argparse %-formats help: a bare % once printed an option's whole dictionary
        assert "option_strings" not in proc.stdout and "%%" not in proc.stdout, command


def test_report_help_prints_percent_signs_once():
    proc = rippleb("report", "--help")
    assert "95 % confidence" in proc.stdout and "%%" not in proc.stdout


def test_list_shows_methods_and_scenarios():
    proc = rippleb("list")
    assert proc.returncode == 0
    assert "raw" in proc.stdout and "builtin" in proc.stdout
    assert "paper-quintic" in proc.stdout and "calibration                  not scored" in proc.stdout
    # one description per method (its `description`, tests/test_descriptions.py) and scenario
    # (its TOML description)
    assert "the paper: strain re-sampled at encoder positions" in proc.stdout
    assert "The paper's Fig. 4 experiment: one 5th-order polynomial" in proc.stdout
    assert "re-assembled" in proc.stdout
    assert max(len(line) for line in proc.stdout.splitlines()) <= 100


def test_list_imports_no_builtin_method():
    """Descriptions come from the methods' source: on a fresh install, importing them would
    compile every numba kernel first (about 15 s)."""
    code = ("import sys, contextlib, io\nfrom rippleb.cli import main\n"
            "with contextlib.redirect_stdout(io.StringIO()): main(['list'])\n"
            "print(sorted(m for m in sys.modules if m.startswith('rippleb.methods.')))")
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.strip() == "[]"


@pytest.mark.parametrize("args, message", [
    (["run", "--methods", "rwa"], "unknown method 'rwa' (did you mean 'raw'?)"),
    (["run", "--methods", "raw", "--scenarios", "paper-quintc"], "did you mean paper-quintic"),
    (["simulate", "nope", "--out", "x.csv"], "unknown scenario"),
    (["simulate", "paper-quintic", "--out", "x.txt"], "unsupported log format"),
    (["report", "missing-dir"], "no results.csv"),
    (["run", "--log", "missing.csv"], "no such file"),
    (["run", "--resume", "missing-dir"], "nothing to resume"),
])
def test_errors_are_one_line_exit_2(tmp_path, args, message):
    proc = rippleb(*args, cwd=tmp_path)
    assert proc.returncode == 2
    assert proc.stderr.startswith("rippleb: error: ") and proc.stderr.count("\n") == 1
    assert message in proc.stderr and "Traceback" not in proc.stderr
    assert not (tmp_path / "runs").exists()


def test_debug_shows_the_traceback(tmp_path):
    proc = rippleb("--debug", "run", "--methods", "rwa", cwd=tmp_path)
    assert proc.returncode != 0 and "Traceback" in proc.stderr


@pytest.mark.slow
def test_simulate_run_and_report(tmp_path):
    log = tmp_path / "log.parquet"
    assert rippleb("simulate", "static-contact", "--seed", "1", "--out", log).returncode == 0
    assert set(pd.read_parquet(log).columns) == {"t", "strain", "encoder", "current", "index",
                                                 "torque_true", "torque_ref"}

    out = tmp_path / "run"
    proc = rippleb("run", "--methods", "raw,lowpass", "--scenarios", "static-contact", "--seeds", "1",
                   "--jobs", "2", "--out", out)
    assert proc.returncode == 0, proc.stderr
    assert "total wall time" in proc.stdout
    rows = pd.read_csv(out / "results.csv")
    assert sorted(rows.method) == ["lowpass", "raw"] and (rows.status == "ok").all()

    published = tmp_path / "published"
    proc = rippleb("report", out, "--out", published, "--no-figures")
    assert proc.returncode == 0, proc.stderr
    assert pd.read_csv(published / "results.csv").equals(rows)

    # the simulated log run as a recording: scored against its torque_ref
    proc = rippleb("run", "--log", log, "--methods", "raw", "--out", tmp_path / "rec")
    assert proc.returncode == 0, proc.stderr
    rec = pd.read_csv(tmp_path / "rec" / "results.csv")
    assert rec.loc[0, "scenario"] == "log:log.parquet" and rec.loc[0, "rms_error_ref_nm"] > 0


def test_bad_recorded_log_names_the_column(tmp_path):
    frame = pd.DataFrame({"t": [0.0, 1e-4, 5e-5], "strain": 0.0, "encoder": 0, "current": 0.0})
    frame.to_csv(tmp_path / "rec.csv", index=False)
    proc = rippleb("run", "--log", tmp_path / "rec.csv", cwd=tmp_path)
    assert proc.returncode == 2 and "column t must strictly increase" in proc.stderr


@pytest.mark.slow
@pytest.mark.heavy
def test_sigint_then_resume(tmp_path):
    out = tmp_path / "run"
    args = [sys.executable, "-m", "rippleb", "run", "--methods", "raw,lowpass,current-based,order-tracking",
            "--scenarios", "paper-quintic,creep,reversal", "--seeds", "4", "--jobs", "1", "--out", str(out),
            "--no-progress"]
    # 48 rows of about 0.15 s: enough that the interrupt lands mid-run, not after the last
    # row (a run of 18 rows sometimes finished before the signal came); four methods per
    # case, so the run simulates 16 cases rather than 32.
    # Ctrl-C as in a terminal: a child of a background process (a pytest-xdist worker)
    # inherits SIGINT ignored, and Python keeps it ignored.
    proc = subprocess.Popen(args, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline:   # interrupt once some, not all, rows are done
        if (out / "results.csv").is_file() and len(pd.read_csv(out / "results.csv")) >= 2:
            break
        time.sleep(0.05)
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 130 and "interrupted" in err, (proc.returncode, err)
    kept = pd.read_csv(out / "results.csv")
    assert 2 <= len(kept) < 48 and (kept.status == "ok").all()

    resumed = rippleb("run", "--resume", out, "--jobs", "2", "--no-progress")
    assert resumed.returncode == 0, resumed.stderr
    rows = pd.read_csv(out / "results.csv")
    assert len(rows) == 48 and not rows.duplicated(["method", "scenario", "seed"]).any()
    assert set(kept.run_id) < set(rows.run_id)   # the kept rows were not rerun


@pytest.mark.slow
@pytest.mark.heavy
def test_non_editable_install_lists_builtins(tmp_path):
    target = tmp_path / "site"
    proc = subprocess.run([sys.executable, "-m", "pip", "install", "-q", "--no-deps",
                           "--target", str(target), str(ROOT)], capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr
    env = {**os.environ, "PYTHONPATH": str(target)}
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    proc = rippleb("list", cwd=elsewhere, env=env)
    assert proc.returncode == 0, proc.stderr
    assert str(target) in subprocess.run([sys.executable, "-c", "import rippleb; print(rippleb.__file__)"],
                                         capture_output=True, text=True, cwd=elsewhere, env=env).stdout
    for name in ("raw", "lowpass", "paper-quintic", "calibration"):
        assert name in proc.stdout
    # the installed copy knows the commit it was built from (setuptools-scm), without git
    head = subprocess.run(["git", "-C", str(ROOT), "rev-parse", "HEAD"], capture_output=True, text=True)
    if head.returncode == 0:
        state = subprocess.run([sys.executable, "-c", "from rippleb.report.provenance import git_state; "
                                "s = git_state(); print(s['git_commit'], s.get('git_source'))"],
                               capture_output=True, text=True, cwd=elsewhere, env=env).stdout.split()
        assert state == [head.stdout.strip(), "build"]


@pytest.mark.slow
def test_run_on_a_log_without_calibration_warns_what_is_true(tmp_path):
    n = 4000
    t = np.arange(n) / 20000.0
    torque = 5.0 * np.sin(2 * np.pi * 3 * t)
    pd.DataFrame({"t": t, "strain": 1e-3 * torque, "encoder": np.arange(n) // 4, "current": 0.01 * torque,
                  "torque_ref": torque}).to_csv(tmp_path / "rec.csv", index=False)
    proc = rippleb("run", "--log", tmp_path / "rec.csv", "--methods", "raw", "--jobs", "1", "--no-progress",
                   "--out", tmp_path / "run", cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    assert "not on a calibration recording" in proc.stderr and "flatters" not in proc.stderr
    assert proc.stdout.rstrip().splitlines()[-1].startswith(f"Next: rippleb report {tmp_path / 'run'}")

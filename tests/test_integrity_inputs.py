"""Integrity of what a run reads: row identity, resume input, recorded logs, options, conditions."""

import os
import subprocess
import sys
import time
import warnings

import numpy as np
import pandas as pd
import pytest

from conftest import vouch_for

import rippleb
from rippleb import InputError
from rippleb.engine.results import COLUMNS, RunWarning, read_rows
from support import fake_perfect as fake, fake_simulate  # noqa: F401 - the fixture is used by name
from support import write_move_scenario


def cli(*args, cwd=None, timeout=300):
    return subprocess.run([sys.executable, "-m", "rippleb", *map(str, args)], capture_output=True,
                          text=True, cwd=cwd, timeout=timeout)


# ----------------------------------------------------------------------------- rows mixed


@pytest.mark.slow
def test_different_files_give_distinct_rows(tmp_path):
    write_move_scenario(tmp_path / "a b.toml", by=0.1)
    write_move_scenario(tmp_path / "a_b.toml", by=0.05)
    write_move_scenario(tmp_path / "\N{SLIGHTLY SMILING FACE}.toml", by=0.08)
    write_move_scenario(tmp_path / "\N{UPSIDE-DOWN FACE}.toml", by=0.12)
    files = ["a b.toml", "a_b.toml", "\N{SLIGHTLY SMILING FACE}.toml", "\N{UPSIDE-DOWN FACE}.toml"]
    proc = cli("run", "--methods", "raw", "--scenarios", ",".join(files), "--seeds", "1", "--jobs", "2",
               "--no-progress", "--out", "out", cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    rows = pd.read_csv(tmp_path / "out" / "results.csv", keep_default_na=False)
    assert sorted(rows.scenario) == sorted(f[:-5] for f in files) and (rows.status == "ok").all()
    assert rows.scenario_sha256.nunique() == 4 and rows.rms_error_nm.nunique() == 4


@pytest.mark.parametrize("files, words", [
    (["d1/x.toml", "d2/x.toml"], "two scenarios are named 'x'"),
    (["creep", "./creep.toml"], "named like the built-in scenario 'creep'"),
    (["calibration.toml"], "named like the built-in scenario 'calibration'"),
])
def test_ambiguous_selections_are_refused(tmp_path, files, words):
    for name in files:
        if name.endswith(".toml"):
            write_move_scenario(tmp_path / name, by=0.05 + 0.01 * len(name))
    proc = cli("run", "--methods", "raw", "--scenarios", ",".join(files), "--seeds", "1", "--out", "out",
               cwd=tmp_path)
    assert proc.returncode == 2 and words in proc.stderr and proc.stderr.count("\n") == 1, proc.stderr
    assert not (tmp_path / "out").exists()


def test_one_file_given_twice_is_one_scenario(fake, tmp_path):
    write_move_scenario(tmp_path / "x.toml")
    frame = rippleb.run(methods="raw", scenarios=[str(tmp_path / "x.toml"), str(tmp_path / "." / "x.toml")],
                        seeds=1)
    assert list(frame.scenario) == ["x"]


def test_rows_are_sorted_by_their_key_with_condition_after_scenario(fake):
    frame = rippleb.run(methods="raw,perfect", scenarios="paper-quintic,creep", seeds=[1, 0], jobs=2)
    keys = list(zip(frame.method, frame.scenario, frame.condition, frame.seed))
    assert keys == sorted(keys) and len(keys) == 8
    assert list(frame.columns[:4]) == ["method", "scenario", "condition", "seed"] == list(COLUMNS[:4])


# ----------------------------------------------------------------------------- conditions


def test_conditions_axis_calibration_same_session_but_for_the_joints_own_condition(fake, tmp_path, monkeypatch):
    """The calibration log is the device's first session (same-session) for every deployment
    condition; `realistic` changes the joint itself, so its rows fit on a realistic one."""
    import rippleb.simulator

    calls = tmp_path / "calls"

    def recording(scenario, seed, condition="same-session"):
        with open(calls, "a") as fh:
            fh.write(f"{getattr(scenario, 'name', scenario)} {seed} {condition}\n")
        return fake_simulate(scenario, seed, condition)
    monkeypatch.setattr(rippleb.simulator, "simulate", recording)
    frame = rippleb.run(methods="raw", scenarios="paper-quintic", seeds=1, conditions="all", out=tmp_path / "o")
    assert list(frame.condition) == sorted(rippleb.CONDITIONS) and (frame.status == "ok").all()
    lines = set(calls.read_text().splitlines())
    assert lines == ({"calibration 0 same-session", "calibration 0 realistic"}
                     | {f"paper-quintic 0 {c}" for c in rippleb.CONDITIONS})
    import json
    assert json.loads((tmp_path / "o" / "run.json").read_text())["conditions"] == list(rippleb.CONDITIONS)


def test_default_condition_is_same_session_and_unknown_ones_are_refused(fake):
    assert list(rippleb.run(methods="raw", scenarios="creep", seeds=1).condition) == ["same-session"]
    with pytest.raises(InputError, match="unknown condition 'sunny'"):
        rippleb.run(methods="raw", scenarios="creep", seeds=1, conditions="sunny")


def test_a_condition_the_simulator_lacks_costs_its_rows_only():
    frame = rippleb.run(methods="raw", scenarios="static-contact", seeds=1, conditions="same-session,aged")
    status = dict(zip(frame.condition, frame.status))
    assert status["same-session"] == "ok"
    if status["aged"] != "ok":   # until the simulator implements the condition
        assert "NotImplementedError" in frame.set_index("condition").loc["aged", "message"]


# ----------------------------------------------------------------------------- resume trusts nothing


def _run_two(tmp_path):
    return rippleb.run(methods="raw,perfect", scenarios="paper-quintic", seeds=1, out=tmp_path)


def test_a_truncated_row_is_not_finished(fake, tmp_path):
    _run_two(tmp_path)
    path = tmp_path / "results.csv"
    text = path.read_text().rstrip("\n")
    path.write_text(text[: text.rfind(",", 0, len(text) // 2 + len(text) // 4)] + "\n")   # cut the last row
    with pytest.warns(RunWarning, match="truncated"):
        frame = rippleb.run(methods="raw,perfect", scenarios="paper-quintic", seeds=1, out=tmp_path, resume=True)
    assert sorted(frame.method) == ["perfect", "raw"] and (frame.status == "ok").all()
    assert np.isfinite(frame.rms_error_nm).all()


def test_an_append_cut_short_is_not_a_row(fake, tmp_path):
    """A last line without its end (the runner killed mid-append) is dropped by name, even
    where what is left of it would parse: cut inside a swept value, it would name another row."""
    _run_two(tmp_path)
    path = tmp_path / "results.csv"
    text = path.read_text()
    path.write_text(text[: len(text) - 3])          # the last row loses its line end and two characters
    with pytest.warns(RunWarning, match="unfinished"):
        kept = read_rows(path)
    assert len(kept) == 1


def _row(seed: int) -> dict:
    row = {c: "" for c in COLUMNS}
    row.update(method="raw", scenario="creep", condition="same-session", seed=seed, status="ok",
               rms_error_nm=1.0 + seed)
    return row


def test_rows_are_appended_between_rewrites_and_none_is_lost(tmp_path, monkeypatch):
    """Each finished row is on disk when ``add`` returns, appended without rewriting the file;
    ``flush`` puts the file back in key order, equal to the rows in memory."""
    from rippleb.engine import results

    monkeypatch.setattr(results, "REWRITE_INTERVAL_S", 1e9)
    rewrites = []
    real = results.atomic_path
    monkeypatch.setattr(results, "atomic_path", lambda path: rewrites.append(path) or real(path))
    path = tmp_path / "results.csv"
    store = results.ResultsFile(path)
    for seed in (5, 2, 9, 0, 7):
        store.add(_row(seed))
        assert sorted(r["seed"] for r in read_rows(path)) == sorted(r["seed"] for r in store.rows)
    assert len(rewrites) == 1                       # the first row only: the others were appended
    assert [r["seed"] for r in read_rows(path)] == [5, 2, 9, 0, 7]
    store.flush()
    assert [r["seed"] for r in read_rows(path)] == [0, 2, 5, 7, 9]
    assert len(rewrites) == 2


def test_the_whole_file_is_rewritten_once_the_interval_passes(tmp_path, monkeypatch):
    """An edit of the file by anyone else lasts until the next rewrite from memory."""
    from rippleb.engine import results

    monkeypatch.setattr(results, "REWRITE_INTERVAL_S", 0.0)
    monkeypatch.setattr(results, "REWRITE_SHARE", 0.0)
    path = tmp_path / "results.csv"
    store = results.ResultsFile(path)
    store.add(_row(1))
    path.write_text(path.read_text().replace("2.0", "0.001"))    # a forged error
    store.add(_row(0))
    assert [r["rms_error_nm"] for r in read_rows(path)] == [1.0, 2.0]


def test_scenario_names_like_na_stay_strings(fake, tmp_path):
    for name in ("NA", "null", "nan"):
        write_move_scenario(tmp_path / f"{name}.toml")
    scenarios = [str(tmp_path / f"{n}.toml") for n in ("NA", "null", "nan")]
    rippleb.run(methods="raw", scenarios=scenarios, seeds=1, out=tmp_path / "o")
    again = rippleb.run(methods="raw", scenarios=scenarios, seeds=1, out=tmp_path / "o", resume=True)
    assert sorted(again.scenario) == ["NA", "nan", "null"]
    assert len(pd.read_csv(tmp_path / "o" / "results.csv", keep_default_na=False)) == 3


def test_untrustworthy_rows_are_dropped_with_one_warning(tmp_path):
    good = {c: "" for c in COLUMNS}
    good.update(method="raw", scenario="creep", condition="same-session", seed="0", status="ok",
                rms_error_nm="1.5")
    rows = [good, {**good, "seed": "1", "rms_error_nm": "lots"}, {**good, "seed": "2", "status": "great"},
            {**good}, {**good, "seed": "x"}, {**good, "seed": "3", "rms_error_nm": ""}]
    pd.DataFrame(rows).to_csv(tmp_path / "results.csv", index=False)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        kept = read_rows(tmp_path / "results.csv")
    assert [r["seed"] for r in kept] == [0]
    assert len(caught) == 1 and "ignored 5 row(s)" in str(caught[0].message)
    assert "line 3 holds 'lots' in the numeric column rms_error_nm" in str(caught[0].message)


def test_a_file_without_metric_columns_is_refused(tmp_path):
    pd.DataFrame([{"method": "raw", "scenario": "creep", "seed": 0, "status": "ok"}]).to_csv(
        tmp_path / "results.csv", index=False)
    with pytest.raises(InputError, match="missing column"):
        read_rows(tmp_path / "results.csv")


def test_environmental_failures_are_retried_and_said(fake, tmp_path):
    _run_two(tmp_path)
    path = tmp_path / "results.csv"
    frame = pd.read_csv(path)
    frame["message"] = frame["message"].astype(object)
    frame.loc[frame.method == "raw", ["status", "message"]] = ["error", "environment: process killed by SIGKILL"]
    frame.loc[frame.method == "perfect", ["status", "message"]] = ["error", "ValueError: the method's own bug"]
    frame.to_csv(path, index=False)
    vouch_for(tmp_path)   # rows as rippleb would have written them after those failures
    with pytest.warns(RunWarning, match="running 1 row"):
        again = rippleb.run(methods="raw,perfect", scenarios="paper-quintic", seeds=1, out=tmp_path, resume=True)
    status = dict(zip(again.method, again.status))
    assert status == {"raw": "ok", "perfect": "error"}   # a method's own failure is its result


def test_a_row_killed_from_outside_is_environmental(fake, tmp_path, monkeypatch, register_methods):
    import os
    import signal
    import threading

    from rippleb.method import Method

    import ctypes

    # Its PID is its namespace's 1 and its /proc its own: it names itself instead, and the
    # killer finds that name among the host's processes.
    comm = "victim" + os.urandom(4).hex()

    class Victim(Method):
        name = "victim"

        def step(self, block):
            ctypes.CDLL(None).prctl(15, comm.encode(), 0, 0, 0)   # PR_SET_NAME
            time.sleep(3600)

    def named(name):
        for entry in filter(str.isdigit, os.listdir("/proc")):
            try:
                with open(f"/proc/{entry}/comm") as fh:
                    if fh.read().strip() == name:
                        return int(entry)
            except OSError:
                continue
        return None

    def oom_killer():   # what the kernel's OOM killer, or a user's kill -9, does
        while (pid := named(comm)) is None:
            time.sleep(0.02)
        os.kill(pid, signal.SIGKILL)

    register_methods(Victim)
    killer = threading.Thread(target=oom_killer, daemon=True)
    killer.start()
    frame = rippleb.run(methods="victim", scenarios="creep", seeds=1, timeout=120)
    killer.join(5)
    assert frame.loc[0, "status"] == "error" and frame.loc[0, "message"].startswith("environment: ")


# ----------------------------------------------------------------------------- recorded inputs


def _recording(tmp_path, name, n=40_000, fs=20_000.0, t_scale=1.0):
    sim = fake_simulate("rec", 0)
    columns = {k: v[:n] if len(v) >= n else np.resize(v, n) for k, v in sim.log.columns().items()
               if k != "torque_true"}
    columns["t"] = np.arange(n) / fs * t_scale
    columns["encoder"] = np.floor(np.arange(n) * 0.5)
    frame = pd.DataFrame(columns)
    frame.to_csv(tmp_path / name, index=False)
    return tmp_path / name


@pytest.mark.parametrize("t_scale, words", [(1e6, "(is t in seconds?)"), (1e-5, "outside the plausible")])
def test_implausible_sample_rates_are_refused(tmp_path, t_scale, words):
    path = _recording(tmp_path, "rec.csv", n=2000, t_scale=t_scale)
    with pytest.raises(InputError, match=r"rec.csv: column t gives a sample rate") as info:
        rippleb.run_log(path)
    assert words in str(info.value)


def test_unfit_calibration_logs_are_refused(tmp_path):
    log = _recording(tmp_path, "rec.csv")
    short = _recording(tmp_path, "short.csv", n=2)
    other_rate = _recording(tmp_path, "other.csv", fs=10_000.0)
    with pytest.raises(InputError, match="short.csv: 2 samples .* too short to calibrate on"):
        rippleb.run_log(log, short)
    with pytest.raises(InputError, match="other.csv: recorded at 10000 Hz, the scored log at 20000 Hz"):
        rippleb.run_log(log, other_rate)


# ----------------------------------------------------------------------------- trajectories and options


@pytest.mark.parametrize("kwargs, words", [
    ({"by": 3.0, "duration": 0.002}, "beyond its velocity limit"),
    ({"posture": "nan"}, "posture: elbow_joint = nan is not a finite angle"),
])
def test_absurd_trajectories_are_refused(tmp_path, kwargs, words):
    path = write_move_scenario(tmp_path / "bad.toml", **kwargs)
    with pytest.raises(InputError, match=words):
        rippleb.run(methods="raw", scenarios=str(path), seeds=1)


@pytest.mark.parametrize("kwargs, words", [
    ({"jobs": 0}, "--jobs must be"), ({"timeout": -1.0}, "--timeout must be"),
    ({"timeout": float("nan")}, "--timeout must be"), ({"memory_mb": -1.0}, "--memory-limit must be"),
    ({"methods": ""}, "--methods is empty"), ({"scenarios": " "}, "--scenarios is empty"),
])
def test_nonsense_options_are_refused_in_the_api(kwargs, words):
    with pytest.raises(InputError, match=words):
        rippleb.run(**{"methods": "raw", "scenarios": "creep", "seeds": 1, **kwargs})


def test_a_non_empty_out_is_refused_without_resume(fake, tmp_path):
    first = rippleb.run(methods="raw", scenarios="creep", seeds=1, out=tmp_path)
    before = (tmp_path / "results.csv").read_bytes()
    with pytest.raises(InputError, match="not empty .*--resume"):
        rippleb.run(methods="raw", scenarios="creep", seeds=1, out=tmp_path)
    assert (tmp_path / "results.csv").read_bytes() == before and len(first) == 1


# ----------------------------------------------------------------------------- report trusts nothing


def _results_for_report(tmp_path):
    rippleb.run(methods="raw,perfect", scenarios="paper-quintic", seeds=2, out=tmp_path / "run")
    return tmp_path / "run" / "results.csv"


@pytest.mark.slow
def test_report_ignores_duplicated_and_unreadable_rows_with_one_warning(fake, tmp_path):
    path = _results_for_report(tmp_path)
    frame = pd.read_csv(path)
    duplicated = pd.concat([frame, frame.iloc[[0]]])
    duplicated["rms_error_nm"] = duplicated["rms_error_nm"].astype(object)
    duplicated.iloc[1, duplicated.columns.get_loc("rms_error_nm")] = "oops"
    duplicated.to_csv(path, index=False)
    proc = cli("report", tmp_path / "run", "--no-figures", "--out", tmp_path / "rep")
    assert proc.returncode == 0, proc.stderr
    assert "Traceback" not in proc.stderr
    assert proc.stderr.count("rippleb: warning:") >= 1 and "ignored 2 row(s)" in proc.stderr
    readme = (tmp_path / "rep" / "README.md").read_text()
    assert "2 seeds" in readme and "3 seeds" not in readme   # the duplicate is not an extra seed


def test_report_refuses_a_missing_metric_column(fake, tmp_path):
    path = _results_for_report(tmp_path)
    pd.read_csv(path).drop(columns=["rms_error_nm"]).to_csv(path, index=False)
    proc = cli("report", tmp_path / "run", "--no-figures", "--out", tmp_path / "rep")
    assert proc.returncode == 2 and "missing column(s) rms_error_nm" in proc.stderr


def test_a_full_disk_is_environmental_and_retried(fake, tmp_path, monkeypatch):
    import errno

    import rippleb.engine.jobs

    real_store = rippleb.engine.jobs.store

    def full(path, data):
        raise InputError(f"{path}: cannot write: {os.strerror(errno.ENOSPC)}")
    monkeypatch.setattr(rippleb.engine.jobs, "store", full)
    frame = rippleb.run(methods="raw", scenarios="creep", seeds=1, out=tmp_path)
    assert frame.loc[0, "status"] == "error" and frame.loc[0, "message"].startswith("environment: ")
    assert "No space left on device" in frame.loc[0, "message"]
    monkeypatch.setattr(rippleb.engine.jobs, "store", real_store)   # the disk has room again
    with pytest.warns(RunWarning, match="environmental reason"):
        again = rippleb.run(methods="raw", scenarios="creep", seeds=1, out=tmp_path, resume=True)
    assert list(again.status) == ["ok"]


def test_simulate_passes_the_condition(tmp_path, monkeypatch):
    import rippleb.simulator
    from rippleb.cli import main

    seen = []

    def recording(scenario, seed, condition="same-session"):
        seen.append(condition)
        return fake_simulate(scenario, seed, condition)
    monkeypatch.setattr(rippleb.simulator, "simulate", recording)
    assert main(["simulate", "creep", "--condition", "power-cycled", "--out", str(tmp_path / "x.csv")]) == 0
    assert seen == ["power-cycled"] and (tmp_path / "x.csv").is_file()


def test_resume_may_add_methods_and_says_so(fake, tmp_path):
    import json

    rippleb.run(methods="raw", scenarios="creep", seeds=1, out=tmp_path)
    with pytest.warns(RunWarning, match="adding method"):
        both = rippleb.run(methods="raw,perfect", scenarios="creep", seeds=1, out=tmp_path, resume=True)
    assert sorted(both.method) == ["perfect", "raw"]
    assert json.loads((tmp_path / "run.json").read_text())["methods"] == ["raw", "perfect"]
    with pytest.raises(InputError, match=r"methods \['raw', 'perfect'\], asked \['raw'\]"):
        rippleb.run(methods="raw", scenarios="creep", seeds=1, out=tmp_path, resume=True)

"""Rows and run files that rippleb did not write are found (issue 25, item 2).

Every row gets a keyed hash (``rippleb/integrity.py``) under a key only the user's runs
read; ``--resume`` and ``report`` drop and name the rows whose hash fails, and
``--resume`` refuses a ``run.json`` changed since it was written. Through the real CLI,
with the key in the test's own directory (``RIPPLEB_KEY_FILE``).
"""

import json
import os
import subprocess
import sys

import pandas as pd
import pytest

from support.hostile import csv_rows, write_csv_rows

pytestmark = pytest.mark.slow

RUN = ["run", "--methods", "raw,lowpass", "--scenarios", "static-contact", "--seeds", "2", "--jobs", "2",
       "--no-progress"]


def _cli(tmp_path, *args, key="key"):
    env = {**os.environ, "RIPPLEB_KEY_FILE": str(tmp_path / key)}
    return subprocess.run([sys.executable, "-m", "rippleb", *map(str, args)], capture_output=True, text=True,
                          env=env, cwd=tmp_path, timeout=300)


@pytest.fixture(scope="module")
def finished(tmp_path_factory):
    """One finished run (4 rows) and its key, copied by each test that edits it."""
    where = tmp_path_factory.mktemp("integrity")
    proc = _cli(where, *RUN, "--out", "run")
    assert proc.returncode == 0, proc.stderr
    return where


def _copy(finished, tmp_path):
    import shutil

    shutil.copytree(finished / "run", tmp_path / "run")
    shutil.copy(finished / "key", tmp_path / "key")
    return tmp_path / "run"


def test_an_untouched_run_verifies_with_no_warning(finished, tmp_path):
    run = _copy(finished, tmp_path)
    assert (run / "rows.mac").read_text().count("\n") == 1 + 4     # header and one MAC per row
    report = _cli(tmp_path, "report", run, "--out", "rep")
    assert report.returncode == 0, report.stderr
    assert "warning" not in report.stderr
    resumed = _cli(tmp_path, "run", "--resume", run, "--no-progress")
    assert resumed.returncode == 0 and "warning" not in resumed.stderr, resumed.stderr


def test_an_edited_row_is_named_dropped_and_run_again(finished, tmp_path):
    run = _copy(finished, tmp_path)
    rows = csv_rows(run / "results.csv")
    original = rows[2]["rms_error_nm"]
    rows[2]["rms_error_nm"] = "0.001"                      # a flattering hand edit
    write_csv_rows(run / "results.csv", rows)
    report = _cli(tmp_path, "report", run, "--out", "rep")
    assert report.returncode == 0, report.stderr
    assert "ignored 1 row(s) that rippleb did not write or that were changed since" in report.stderr
    assert "0.001" not in (tmp_path / "rep" / "results.csv").read_text()
    resumed = _cli(tmp_path, "run", "--resume", run, "--no-progress")
    assert resumed.returncode == 0, resumed.stderr
    assert "ignored 1 row(s)" in resumed.stderr
    again = pd.read_csv(run / "results.csv")
    assert len(again) == 4 and (again.status == "ok").all()
    assert again.loc[2, "rms_error_nm"] == pytest.approx(float(original), rel=1e-12)   # recomputed, not kept


def test_a_forged_row_and_a_row_from_another_run_are_dropped(finished, tmp_path):
    run = _copy(finished, tmp_path)
    other = _cli(tmp_path, *RUN[:-1], "--seeds", "3", "--no-progress", "--out", "other")   # a genuine run, same key
    assert other.returncode == 0, other.stderr
    rows = csv_rows(run / "results.csv")
    foreign = [r for r in csv_rows(tmp_path / "other" / "results.csv") if r["seed"] == "2"][0]
    forged = dict(rows[0], method="lowpass", seed="7", rms_error_nm="0.002")
    write_csv_rows(run / "results.csv", rows + [foreign, forged])
    report = _cli(tmp_path, "report", run, "--out", "rep")
    assert report.returncode == 0, report.stderr
    assert "ignored 2 row(s)" in report.stderr
    assert len(pd.read_csv(tmp_path / "rep" / "results.csv")) == 4


def test_a_changed_run_json_is_refused_on_resume(finished, tmp_path):
    run = _copy(finished, tmp_path)
    config = json.loads((run / "run.json").read_text())
    config["seeds"] = [0, 1, 2, 3, 4, 5]                   # the forged seed count of the issue
    (run / "run.json").write_text(json.dumps(config))
    report = _cli(tmp_path, "report", run, "--out", "rep")
    assert report.returncode == 0 and "run.json: changed since rippleb wrote it" in report.stderr, report.stderr
    resumed = _cli(tmp_path, "run", "--resume", run, "--no-progress")
    assert resumed.returncode == 2
    assert resumed.stderr.strip().splitlines()[-1] == (
        f"rippleb: error: {run / 'run.json'}: changed since rippleb wrote it (its keyed hash does not match); "
        "rippleb will not resume a run it cannot vouch for: start it again with another --out")
    assert len(pd.read_csv(run / "results.csv")) == 4     # nothing lost


def test_another_users_key_cannot_verify_and_says_so(finished, tmp_path):
    run = _copy(finished, tmp_path)
    report = _cli(tmp_path, "report", run, "--out", "rep", key="other-key")
    assert report.returncode == 0, report.stderr
    assert "made with another rippleb key" in report.stderr and "cannot be verified here" in report.stderr
    assert len(pd.read_csv(tmp_path / "rep" / "results.csv")) == 4   # kept, as before MACs existed


def test_a_run_that_can_make_no_key_says_so_when_it_starts(tmp_path):
    """A home nobody can write (uid 65534's ``/nonexistent``): the run still runs, and says at
    once that it cannot be resumed and how to give it a key, not first when ``--resume`` refuses."""
    (tmp_path / "file").write_text("")
    proc = _cli(tmp_path, "run", "--methods", "raw", "--scenarios", "static-contact", "--seeds", "1",
                "--no-progress", "--out", "run", key="file/key")      # a key below a file: never writable
    assert proc.returncode == 0, proc.stderr
    assert "rippleb: warning: no key could be read or written at" in proc.stderr
    assert "RIPPLEB_KEY_FILE" in proc.stderr
    resumed = _cli(tmp_path, "run", "--resume", "run", "--no-progress", key="file/key")
    assert resumed.returncode == 2 and "has no integrity field" in resumed.stderr

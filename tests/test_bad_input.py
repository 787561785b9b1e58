"""Bad input through the real command (``python -m rippleb`` in a subprocess), issue 7 items 1 and 5.

Every case must end with a non-zero exit, exactly one line on stderr that names the file,
key, column or plugin at fault, no traceback, and nothing that looks like a valid result
(no ``results.csv``, no log file). One fixture runs every case once (the cases are written
by :func:`support.bad_inputs.bad_inputs`, which ``docs/tables/bad_input_table.py`` shares);
the tests check them.
"""

from __future__ import annotations

import os
import pickle
import subprocess
import sys
import textwrap
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from rippleb import InputError, load_scenario, read_log
from support import GOOD, PLUGIN, install_dist
from support.bad_inputs import PicklePayload, bad_inputs


#: Cases run as ``python -m rippleb`` in a subprocess: one or more of each kind, and all
#: that need an installed plugin. The others call ``rippleb.cli.main`` in this process (the
#: same code after the interpreter starts), which saves ~1.5 s of imports per case.
SUBPROCESS = {"scenario unknown key", "scenario beyond joint limits", "unknown robot", "log holds NaN",
              "log is a pickle (.parquet)", "two plugins, one name", "plugin named like a built-in",
              "output dir under a regular file", "simulate into a regular file's child"}


class _Done:
    def __init__(self, returncode, stderr):
        self.returncode, self.stderr = returncode, stderr


@pytest.fixture(scope="module")
def outcomes(tmp_path_factory):
    import contextlib
    import io

    from rippleb.cli import main

    root = tmp_path_factory.mktemp("bad")
    cases = bad_inputs(root)
    before = {p for p in root.rglob("*")}

    def one(item):
        name, (argv, site, _) = item
        env = dict(os.environ)
        if site:
            env["PYTHONPATH"] = os.pathsep.join([str(root / site), env.get("PYTHONPATH", "")])
        return name, subprocess.run([sys.executable, "-m", "rippleb", *argv], cwd=root, env=env,
                                    capture_output=True, text=True, timeout=120)

    with ThreadPoolExecutor(3) as pool:
        running = pool.map(one, [(k, v) for k, v in cases.items() if k in SUBPROCESS])
        procs = {}
        cwd = os.getcwd()
        try:
            os.chdir(root)
            for name, (argv, site, _) in cases.items():
                if name in SUBPROCESS:
                    continue
                assert site is None
                err = io.StringIO()
                with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
                    code = main(list(argv))   # any other exception fails the test: a traceback
                procs[name] = _Done(code, err.getvalue())
        finally:
            os.chdir(cwd)
        procs.update(dict(running))
    created = sorted(str(p.relative_to(root)) for p in set(root.rglob("*")) - before
                     if "__pycache__" not in p.parts)
    return root, cases, procs, created


def _case_names():
    import tempfile

    with tempfile.TemporaryDirectory() as tmp:
        return list(bad_inputs(Path(tmp)))


@pytest.mark.slow
@pytest.mark.parametrize("case", _case_names())
def test_bad_input_is_one_line_exit_2(outcomes, case):
    _, cases, procs, _ = outcomes
    proc, words = procs[case], cases[case][2]
    assert proc.returncode == 2, (proc.returncode, proc.stderr)
    assert proc.stderr.startswith("rippleb: error: ") and proc.stderr.count("\n") == 1, proc.stderr
    assert "Traceback" not in proc.stderr
    for word in words:
        assert word in proc.stderr, proc.stderr


@pytest.mark.slow
def test_nothing_that_looks_like_a_result_is_written(outcomes):
    root, _, _, created = outcomes
    # no results.csv, no run directory, no log, and no file made by a payload
    assert created == [], created
    assert not (root / "PWNED").exists() and not (root / "out").exists()


def test_debug_shows_the_traceback_of_a_bad_file(tmp_path):
    (tmp_path / "bad.toml").write_text("duraton = 2.0\n" + GOOD)
    proc = subprocess.run([sys.executable, "-m", "rippleb", "--debug", "simulate", "bad.toml", "--out", "x.csv"],
                          cwd=tmp_path, capture_output=True, text=True, timeout=120)
    assert proc.returncode != 0 and "Traceback" in proc.stderr and "InputError" in proc.stderr


# ----------------------------------------------------------------------------- safety (item 5)


def test_strings_that_look_like_code_stay_data(tmp_path):
    marker = tmp_path / "PWNED"
    text = (f'description = "__import__(\'os\').system(\'touch {marker}\')"\n'
            + GOOD.replace('posture = { elbow_joint = 1.5 }',
                           'posture = { elbow_joint = 1.5 }\n# !!python/object/apply:os.system ["touch x"]'))
    (tmp_path / "code.toml").write_text(text)
    sc = load_scenario(tmp_path / "code.toml")
    assert sc.description.startswith("__import__") and not marker.exists()
    # code in a value where a number belongs is a type error, not an evaluation
    (tmp_path / "expr.toml").write_text('duration = "1 + 1"\n' + GOOD)
    with pytest.raises(InputError, match="duration: must be a number, got str"):
        load_scenario(tmp_path / "expr.toml")


def test_a_pickle_disguised_as_a_log_is_not_executed(tmp_path):
    marker = tmp_path / "PWNED"
    for suffix in (".csv", ".parquet"):
        path = tmp_path / f"log{suffix}"
        path.write_bytes(pickle.dumps(PicklePayload(marker)))
        with pytest.raises(InputError, match=str(path.name)):
            read_log(path)
    assert not marker.exists()


def test_the_cache_refuses_pickled_arrays(tmp_path):
    from rippleb.engine.cache import log_from_bytes, unpack

    marker = tmp_path / "PWNED"
    payload = np.empty(1, dtype=object)
    payload[0] = PicklePayload(marker)
    path = tmp_path / "case.npz"
    np.savez(path, t=np.arange(3.0), __info__=np.array("{}"), strain=payload)
    for reader in (unpack, log_from_bytes):
        with pytest.raises(ValueError, match="allow_pickle"):
            reader(path.read_bytes())
    assert not marker.exists()


def test_scenario_and_log_readers_use_no_code_loaders():
    root = Path(__file__).resolve().parents[1] / "rippleb"
    for name in ("simulator/scenario.py", "data.py", "log_files.py"):
        source = (root / name).read_text()
        for banned in ("pickle", "eval(", "exec(", "yaml", "allow_pickle=True", "__import__"):
            assert banned not in source, (name, banned)
    assert "allow_pickle=False" in (root / "engine" / "cache.py").read_text()
    for name in ("engine/runner.py", "engine/process/pool.py", "engine/cache.py"):   # the runner never unpickles what a job sends
        assert "pickle.load" not in (root / name).read_text(), name


@pytest.mark.slow
def test_names_cannot_make_the_runner_write_outside_out(tmp_path):
    """A scenario file named ``..x.toml``: every file the run writes stays under ``--out``.
    A plugin named ``../../escape`` is refused at discovery (issue 25: a method name is an
    identifier with dashes), before anything is written."""
    site = tmp_path / "site"
    install_dist(site, "rippleb-escape", "escape_mod", PLUGIN, {"../../escape": "Plugin"})
    work = tmp_path / "work"
    work.mkdir()
    (work / "..x.toml").write_text(GOOD)
    before = set(tmp_path.rglob("*"))
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(site), os.environ.get("PYTHONPATH", "")])}
    command = [sys.executable, "-m", "rippleb", "run", "--methods", "../../escape,raw", "--scenarios",
               "..x.toml", "--seeds", "1", "--jobs", "1", "--no-progress", "--out", "deep/out"]
    proc = subprocess.run(command, cwd=work, env=env, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 2 and "method '../../escape' (rippleb-escape: escape_mod:Plugin)" in proc.stderr
    assert set(tmp_path.rglob("*")) == before
    command[command.index("../../escape,raw")] = "raw"
    proc = subprocess.run(command, cwd=work, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    out = (work / "deep" / "out").resolve()
    created = [p for p in set(tmp_path.rglob("*")) - before if "__pycache__" not in p.parts]
    outside = [p for p in created if out not in p.resolve().parents and p.resolve() != out
               and p.resolve() not in out.parents]
    assert outside == [], outside
    rows = pd.read_csv(out / "results.csv")
    assert set(rows.method) == {"raw"} and set(rows.scenario) == {"..x"}
    assert (rows.status == "ok").all(), rows[["method", "status", "message"]]
"""Third-party plugins, pip-installed from packages built in a temporary directory."""

import json
import os
import shutil
import subprocess
import sys
import textwrap
from pathlib import Path

import pandas as pd
import pytest
from conftest import HANG_TIMEOUT_S

ROOT = Path(__file__).resolve().parents[1]
EXAMPLE = ROOT / "examples" / "rippleb-median"
pytestmark = pytest.mark.slow

MISBEHAVING = '''
import time
import numpy as np
from rippleb import Method

class Raises(Method):
    name = "raises"
    def step(self, block):
        raise ValueError("plugin bug")

class Nans(Method):
    name = "nans"
    def step(self, block):
        return np.full(len(block), np.nan)

class Short(Method):
    name = "short"
    def step(self, block):
        return np.zeros(3)

class Sleeps(Method):
    name = "sleeps"
    def step(self, block):
        time.sleep(3600)

class Chatty(Method):
    name = "chatty"
    def step(self, block):
        print("hello from a plugin")
        return block.strain * 0.0
'''


TUNABLE = '''
from rippleb import Method
from rippleb.dsp import fit_gain_offset

class Gain(Method):
    """The calibrated strain times scale: its default, 0.5, halves every torque."""
    name = "gain"
    tunable = {"scale": (0.5, 1.5, "linear")}

    def __init__(self, scale=0.5):
        self.scale = scale

    def fit(self, calibration):
        self.gain_, self.offset_ = fit_gain_offset(calibration.strain, calibration.torque_ref)

    def step(self, block):
        return self.scale * (block.strain * self.gain_ + self.offset_)
'''


def _package(root, name, module, source, entry_points):
    root.mkdir()
    eps = "\n".join(f'{k} = "{module}:{v}"' for k, v in entry_points.items())
    (root / "pyproject.toml").write_text(textwrap.dedent(f'''\
        [build-system]
        requires = ["setuptools>=61"]
        build-backend = "setuptools.build_meta"

        [project]
        name = "{name}"
        version = "0.1.0"

        [project.entry-points."rippleb.methods"]
        ''') + eps + "\n")
    (root / f"{module}.py").write_text(source)


@pytest.fixture(scope="module")
def site(tmp_path_factory):
    """A --target directory with the README plugin (as shipped in examples/rippleb-median/,
    which tests/test_plugin_example.py keeps equal to the README) and a package of
    misbehaving plugins."""
    tmp = tmp_path_factory.mktemp("plugins")
    readme_pkg = tmp / "rippleb-median"
    shutil.copytree(EXAMPLE, readme_pkg, ignore=shutil.ignore_patterns("__pycache__", ".*"))
    _package(tmp / "bad", "rippleb-bad", "rippleb_bad", MISBEHAVING,
             {"raises": "Raises", "nans": "Nans", "short": "Short", "sleeps": "Sleeps", "chatty": "Chatty"})
    _package(tmp / "broken", "rippleb-broken", "rippleb_broken", "import no_such_module\n",
             {"broken-one": "Anything"})
    _package(tmp / "gain", "rippleb-gain", "rippleb_gain", TUNABLE, {"gain": "Gain"})
    target = tmp / "site"
    # --no-deps keeps it offline apart from the build backend, which pip caches after the first run
    proc = subprocess.run([sys.executable, "-m", "pip", "install", "-q", "--no-deps", "--target", str(target),
                           str(readme_pkg), str(tmp / "bad"), str(tmp / "broken"), str(tmp / "gain")],
                          capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr
    return target


def rippleb(site, *args, cwd=None, timeout=300):
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(site), os.environ.get("PYTHONPATH", "")])}
    return subprocess.run([sys.executable, "-m", "rippleb", *map(str, args)], capture_output=True,
                          text=True, env=env, cwd=cwd, timeout=timeout)


def test_installed_plugins_are_listed_with_their_origin(site):
    proc = rippleb(site, "list")
    assert proc.returncode == 0, proc.stderr
    lines = {line.split()[0]: line for line in proc.stdout.splitlines() if line.startswith("  ")}
    assert "plugin" in lines["median"]
    # no description, no class docstring: its module's docstring says what it is
    assert "A running median of the calibrated strain" in lines["median"]
    assert "broken" in lines["broken-one"] and "No module named 'no_such_module'" in lines["broken-one"]
    assert "builtin" in lines["raw"]


@pytest.mark.heavy
def test_misbehaving_plugins_get_their_status_and_the_others_complete(site, tmp_path):
    out = tmp_path / "run"
    proc = rippleb(site, "run", "--methods", "median,raises,nans,short,sleeps,chatty,broken-one,raw",
                   "--scenarios", "static-contact", "--seeds", "1", "--jobs", "2", "--timeout", HANG_TIMEOUT_S,
                   "--out", out, "--no-progress")
    # the broken plugin's row is kept and the others ran, but the run says so and exits 1
    assert proc.returncode == 1, proc.stderr
    assert proc.stderr.strip().splitlines() == [
        line for line in proc.stderr.strip().splitlines() if "broken-one" in line]
    assert "rippleb_broken" in proc.stderr and "no_such_module" in proc.stderr
    assert "hello from a plugin" not in proc.stdout
    rows = pd.read_csv(out / "results.csv").set_index("method")
    assert rows.status.to_dict() == {"median": "ok", "raises": "error", "nans": "invalid", "short": "invalid",
                                     "sleeps": "timeout", "chatty": "ok", "broken-one": "error", "raw": "ok"}
    assert rows.loc["raises", "message"] == "ValueError: plugin bug"
    assert "no_such_module" in rows.loc["broken-one", "message"]
    assert rows.loc["median", "params"] == '{"window": 200}'


def test_the_readme_plugin_passes_check_method(site):
    code = "from rippleb.testing import check_method; from rippleb_median import Median; check_method(Median)"
    env = {**os.environ, "PYTHONPATH": str(site)}
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env)
    assert proc.returncode == 0, proc.stderr


def test_a_plugin_named_like_a_builtin_is_a_clear_error(tmp_path):
    _package(tmp_path / "clash", "rippleb-clash", "rippleb_clash", "", {"raw": "Raw"})
    target = tmp_path / "site"
    subprocess.run([sys.executable, "-m", "pip", "install", "-q", "--no-deps", "--target", str(target),
                    str(tmp_path / "clash")], check=True, capture_output=True)
    proc = rippleb(target, "list")
    assert proc.returncode == 2
    assert proc.stderr.startswith("rippleb: error: two methods are named 'raw'")
    assert "rippleb-clash" in proc.stderr and "Traceback" not in proc.stderr


@pytest.mark.heavy
def test_the_example_plugins_own_tests_pass(site, tmp_path):
    """As its author runs them: pytest in the plugin's directory, the plugin installed."""
    package = tmp_path / "rippleb-median"
    shutil.copytree(EXAMPLE, package, ignore=shutil.ignore_patterns("__pycache__", ".*"))
    env = {**os.environ, "PYTHONPATH": str(site)}
    proc = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "-p", "no:randomly",
                           "tests"], capture_output=True, text=True, env=env, cwd=package, timeout=1800)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "2 passed" in proc.stdout


def test_rippleb_check_passes_the_readme_plugin_and_fails_a_misbehaving_one(site):
    good = rippleb(site, "check", "median[window=5]")
    assert good.returncode == 0, good.stdout + good.stderr
    assert good.stdout.splitlines()[-1] == "median[window=5]: 9 of 9 checks passed"
    bad = rippleb(site, "check", "short")
    assert bad.returncode == 1, bad.stdout + bad.stderr
    assert "  FAIL  output" in bad.stdout and "  skip  causality" in bad.stdout


@pytest.mark.heavy
def test_variants_of_a_plugin_run_with_their_parameters_checked_in_a_child(site, tmp_path):
    refused = rippleb(site, "run", "--methods", "median[size=3]", "--scenarios", "static-contact",
                      "--seeds", "1", "--out", tmp_path / "refused", "--no-progress")
    assert refused.returncode == 2
    lines = refused.stderr.strip().splitlines()
    assert len(lines) == 1 and "method 'median': unknown parameter 'size'" in lines[0], refused.stderr
    out = tmp_path / "run"
    proc = rippleb(site, "run", "--methods", "median[window=50,200]", "--scenarios", "static-contact",
                   "--seeds", "1", "--out", out, "--no-progress")
    assert proc.returncode == 0, proc.stderr
    rows = pd.read_csv(out / "results.csv").set_index("method")
    assert rows.status.to_dict() == {"median[window=50]": "ok", "median[window=200]": "ok"}
    assert rows["params"].to_dict() == {"median[window=50]": '{"window": 50}',
                                        "median[window=200]": '{"window": 200}'}


def test_a_plugin_tuned_by_rippleb_tune_runs_with_the_values_it_adopted(site, tmp_path):
    """Issue 39: 'rippleb tune --methods mine' printed "replaces the default" though nothing was
    replaced, and nothing said how to run the tuned values."""
    record = tmp_path / "tuned.json"
    # One device and the former rule, which can adopt on one: the paired rule, the default
    # since the re-tuning, needs several devices to pass its signed-rank test.
    tune = rippleb(site, "tune", "--methods", "gain", "--budget", 4, "--seeds", "100", "--rule", "every-device",
                   "--jobs", 1, "--out", record, "--no-progress", timeout=1800)
    assert tune.returncode == 0, tune.stderr
    adopted = json.loads(record.read_text())["methods"]["gain"]["adopted"]
    assert adopted["scale"] > 0.5 and "replaces the default" not in tune.stdout
    variant = f"gain[scale={adopted['scale']!r}]"
    assert (f"better on every tuning device, adopted; its constructor's default is unchanged: run it with "
            f"--methods '{variant}' or --tuning {record}") in tune.stdout, tune.stdout
    out = tmp_path / "run"
    run = rippleb(site, "run", "--tuning", record, "--methods", "gain,raw", "--scenarios", "creep", "--seeds", 1,
                  "--jobs", 1, "--out", out, "--no-progress", timeout=1800)
    assert run.returncode == 0, run.stderr
    assert f"rippleb: --tuning tuned.json: gain runs as '{variant}' (the point 'rippleb tune' adopted)" in run.stderr
    rows = pd.read_csv(out / "results.csv").set_index("method")
    assert sorted(rows.index) == sorted([variant, "raw"]) and (rows.status == "ok").all()
    assert json.loads(rows.loc[variant, "params"]) == adopted
    by_hand = rippleb(site, "run", "--methods", variant, "--scenarios", "creep", "--seeds", 1, "--jobs", 1,
                      "--out", tmp_path / "by-hand", "--no-progress", timeout=1800)
    assert by_hand.returncode == 0, by_hand.stderr
    same = pd.read_csv(tmp_path / "by-hand" / "results.csv").set_index("method").loc[variant]
    assert same["rms_error_nm"] == rows.loc[variant, "rms_error_nm"]   # the same variant, bit for bit

"""``rippleb sweep`` through the real CLI: rows per grid point, equal to a run on a scenario
file holding the swept value, resumable, and its figure."""

import subprocess
import sys
from pathlib import Path

import tomllib

import pandas as pd
import pytest

from rippleb.engine.rows import scenario_hash
from rippleb.simulator.scenario import Parser

from rippleb.report.sweep_report import figures, points

BIN = Path(sys.executable).parent
ROOT = Path(__file__).resolve().parents[1]


def rippleb(*args):
    return subprocess.run([str(BIN / "rippleb"), *map(str, args)], capture_output=True, text=True, timeout=600)


@pytest.mark.slow
def test_sweep_rows_equal_runs_of_files_with_the_value_resume_and_figure(tmp_path):
    out = tmp_path / "sweep"
    done = rippleb("sweep", "--param", "temperature_c=10,60", "--methods", "raw", "--scenarios",
                   "paper-quintic", "--seeds", "2", "--jobs", "2", "--no-progress", "--out", out)
    assert done.returncode == 0, done.stderr
    frame = pd.read_csv(out / "results.csv")
    assert len(frame) == 4 and (frame["status"] == "ok").all()
    assert sorted(frame["temperature_c"]) == [10.0, 10.0, 60.0, 60.0]
    assert not frame.duplicated(["method", "scenario", "condition", "seed", "temperature_c"]).any()

    # a grid point ran the scenario a file with that value describes (same content hash)
    text = (ROOT / "scenarios" / "paper-quintic.toml").read_text()
    hot = text.replace("temperature_c = 40.0", "temperature_c = 60.0")
    assert hot != text
    scenario = Parser(Path("hot.toml"), "paper-quintic").scenario(tomllib.loads(hot))
    swept = frame[frame["temperature_c"] == 60.0]
    assert set(swept["scenario_sha256"]) == {scenario_hash(scenario)}
    assert frame["scenario_sha256"].nunique() == 2
    cold = frame[frame["temperature_c"] == 10.0]
    assert set(cold["rms_error_nm"]).isdisjoint(swept["rms_error_nm"])

    # drop one finished row: --resume runs it again, and only it
    lines = (out / "results.csv").read_text().splitlines()
    (out / "results.csv").write_text("\n".join(lines[:-1]) + "\n")
    again = rippleb("sweep", "--resume", out, "--jobs", "1", "--no-progress")
    assert again.returncode == 0, again.stderr
    resumed = pd.read_csv(out / "results.csv")
    assert len(resumed) == 4
    pd.testing.assert_frame_equal(resumed[["temperature_c", "seed", "rms_error_nm"]],
                                  frame[["temperature_c", "seed", "rms_error_nm"]])
    assert resumed["run_id"].nunique() == 2

    # a run --resume of a sweep directory is refused by name
    refused = rippleb("run", "--resume", out)
    assert refused.returncode == 2 and "sweep" in refused.stderr

    drawn = figures(resumed, tmp_path / "figures")
    assert drawn["sweep-temperature_c"][0].is_file()
    table = points(resumed, "temperature_c")
    assert list(table["n"]) == [2, 2] and table["half"].notna().all()
    assert table["mean"].tolist() == [resumed[resumed["temperature_c"] == t]["rms_error_nm"].mean()
                                      for t in (10.0, 60.0)]


def test_sweep_help_lists_every_parameter_with_its_range():
    from rippleb.engine.sweep import PARAMS

    text = rippleb("sweep", "--help").stdout
    for param in PARAMS.values():
        assert param.name in text and f"{param.kind(param.low)} .. {param.kind(param.high)}" in text


@pytest.mark.parametrize("args, words", [
    (["--param", "encoder.nope=1"], ["unknown sweep parameter"]),
    (["--param", "temperature_c=500"], ["outside the valid range"]),
    ([], ["at least one"]),
    (["--param", "temperature_c=20", "--seeds", "0"], ["--seeds must be at least 1"]),
])
def test_bad_sweep_options_are_one_line(tmp_path, args, words):
    done = rippleb("sweep", *args, "--out", tmp_path / "x")
    assert done.returncode == 2
    for word in words:
        assert word in done.stderr
    assert "Traceback" not in done.stderr
    assert not (tmp_path / "x").exists() or not any((tmp_path / "x").iterdir())

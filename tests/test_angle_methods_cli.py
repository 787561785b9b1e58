"""The issue-33 methods through the real command (``python -m rippleb`` in a subprocess)."""

import subprocess
import sys

import pandas as pd
import pytest

NEW = {"spatial-filter": "Chawda & Niemeyer", "fourier-lms": "Vaz & Thakor",
       "periodic-dob": "Muramatsu & Katsura"}


def rippleb(*args, timeout=1800):
    # a loaded 2-core machine may be ten times slower than a quiet one: a wide margin
    return subprocess.run([sys.executable, "-m", "rippleb", *map(str, args)], capture_output=True,
                          text=True, timeout=timeout)


def test_list_names_each_method_with_its_source():
    proc = rippleb("list")
    assert proc.returncode == 0, proc.stderr
    text = " ".join(proc.stdout.split())          # the descriptions wrap over lines
    for name, source in NEW.items():
        entry = text[text.index(f" {name} builtin "):][:300]
        assert source in entry, entry


@pytest.mark.slow
@pytest.mark.heavy
def test_run_scores_each_method_below_raw_and_through_a_power_cycle(tmp_path):
    out = tmp_path / "run"
    proc = rippleb("run", "--methods", ",".join(["raw", *NEW]), "--scenarios", "paper-quintic",
                   "--seeds", 1, "--conditions", "same-session,power-cycled", "--jobs", 1,
                   "--out", out)
    assert proc.returncode == 0, proc.stderr
    rows = pd.read_csv(out / "results.csv").set_index(["condition", "method"])
    assert (rows["status"] == "ok").all(), rows["status"]
    for condition in ("same-session", "power-cycled"):
        raw = rows.loc[(condition, "raw"), "rms_error_nm"]
        for name in NEW:
            assert rows.loc[(condition, name), "rms_error_nm"] < raw, (condition, name)

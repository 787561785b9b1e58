"""What decides a row's last bits is recorded, and a run that mixes environments says so
(docs/reproducibility.md, "Provenance")."""

import json
import os

import pandas as pd
import pytest

from rippleb import numerics
from rippleb.cli import main
from rippleb.report.provenance import (NUMBER_PRODUCERS, collect_provenance, environment, environment_changes,
                                environment_sentence, environment_warnings, machine_rows)

#: Every test here reads what rippleb records of the host: CI runs them once more with
#: the description of the other kind of CPU (``-m host --fake-cpu``, tests/conftest.py).
pytestmark = pytest.mark.host


def test_provenance_names_every_package_that_computes_a_number_and_the_numeric_paths():
    prov = collect_provenance(["run"])
    assert set(prov["versions"]) == set(NUMBER_PRODUCERS)
    assert all(v and v != "not installed" for v in prov["versions"].values()), prov["versions"]
    assert prov["machine"]["numerics"] == numerics.PORTABLE
    assert "avx2" in prov["machine"]["cpu_simd"].split()
    assert prov["machine"]["numpy_dispatch"] and prov["machine"]["libc"]


def test_changes_name_each_version_and_machine_entry_that_differs():
    here = environment()
    other = json.loads(json.dumps(here))
    other["versions"]["numpy"] = "1.26.4"
    # the other machine is derived from this one, so it differs on any host: without
    # AVX-512 where this one has it, with it where this one has not
    simd = here["machine"]["cpu_simd"]
    other["machine"]["cpu_simd"] = other_cpu_simd(simd)
    assert other["machine"]["cpu_simd"] != simd
    assert environment_changes(here, here) == []
    assert environment_changes(here, other) == [
        f"numpy: {here['versions']['numpy']} -> 1.26.4",
        f"cpu_simd: {simd} -> {other['machine']['cpu_simd']}"]


def other_cpu_simd(simd: str) -> str:
    """A SIMD feature list that is never ``simd``: AVX-512 taken away or added."""
    features = simd.split()
    if any(f.startswith("avx512") for f in features):
        return " ".join(f for f in features if not f.startswith("avx512"))
    return " ".join(sorted(features + ["avx512f"]))


@pytest.mark.parametrize("simd", ["avx avx2 fma", "avx avx2 avx512bw avx512f fma", ""])
def test_the_derived_other_machine_differs_from_either_kind_of_host(simd):
    assert other_cpu_simd(simd) != simd


def _rows(**columns) -> pd.DataFrame:
    base = {"method": ["raw", "raw"], "rippleb_version": ["1", "1"], "python": ["3.11.7"] * 2,
            "numpy": ["2.4.6"] * 2, "numerics": [numerics.PORTABLE] * 2}
    return pd.DataFrame({**base, **columns})


def test_report_warnings_for_mixed_or_native_rows():
    assert environment_warnings(_rows(), {}) == []
    mixed = environment_warnings(_rows(numpy=["2.4.6", "2.5.0"]), {})
    assert len(mixed) == 1 and "2 different numpy values (2.4.6, 2.5.0)" in mixed[0]
    native = environment_warnings(_rows(numerics=[numerics.PORTABLE, "native: numpy X86_V4"]), {})
    assert any("1 rows ran the host's own numeric paths (native: numpy X86_V4)" in w for w in native)
    resumed = environment_warnings(_rows(), {"environment_changes": [
        {"command": "rippleb run --resume x", "changes": ["numpy: 2.4.6 -> 2.5.0"], "portable": True}]})
    assert len(resumed) == 1 and "numpy: 2.4.6 -> 2.5.0" in resumed[0]


def test_the_report_header_says_how_the_numbers_reproduce():
    run = collect_provenance(["run"])
    assert "re-runs bit for bit on any x86-64 CPU with AVX2" in environment_sentence(run)
    run["machine"]["numerics"] = "native: numpy X86_V3+X86_V4"
    # the recorded value written as Markdown text (its underscores escaped): it renders as itself
    assert "host's own numeric paths (native: numpy X86\\_V3+X86\\_V4)" in environment_sentence(run)
    assert "not recorded" in environment_sentence({})


@pytest.mark.slow
def test_resume_on_another_environment_warns_records_and_reports(tmp_path, capsys):
    run_dir = tmp_path / "run"
    args = ["run", "--methods", "raw", "--scenarios", "static-contact", "--seeds", "1", "--jobs", "1",
            "--no-progress"]
    assert main(args + ["--out", str(run_dir)]) == 0
    path = run_dir / "provenance.json"
    first = json.loads(path.read_text())
    first["versions"]["numpy"] = "1.26.4"  # as if the run had been started with another numpy
    path.write_text(json.dumps(first))
    capsys.readouterr()

    assert main(["run", "--resume", str(run_dir), "--no-progress"]) == 0
    err = capsys.readouterr().err
    line = [x for x in err.splitlines() if "was started with other versions" in x]
    assert len(line) == 1 and f"numpy: 1.26.4 -> {environment()['versions']['numpy']}" in line[0]
    recorded = json.loads(path.read_text())["environment_changes"]
    assert recorded[0]["changes"] == [f"numpy: 1.26.4 -> {environment()['versions']['numpy']}"]
    assert recorded[0]["portable"] is True

    assert main(["report", str(run_dir), "--no-figures"]) == 0
    assert "the run was resumed on another environment (numpy: 1.26.4" in capsys.readouterr().err


def test_the_report_names_the_cpu_features_and_says_when_they_are_faked():
    run = collect_provenance(["run"])
    rows = {name: value for name, value in machine_rows(run)}
    assert rows["CPU SIMD features (LLVM)"] == run["machine"]["cpu_simd"]
    faked = os.environ.get(numerics.FAKE_CPU_SWITCH)
    assert ("CPU description faked" in rows) == bool(faked)
    if faked:
        assert f"RIPPLEB_FAKE_CPU={faked}" in rows["CPU description faked"]

"""Issue 25, item 7: resume and report answer bad input in one line, or warn and keep the data.

Each case went wrong before (a traceback, an option silently ignored, a silent mix, a
broken table, a nonsense number reported as it is); docs/robustness.md lists them with
their outcome before and after. Through the real CLI: ``rippleb.cli.main`` in-process, or
``python -m rippleb`` where a plugin must be installed.
"""

import csv
import io
import json
import os
import shutil
import subprocess
import sys

import pytest

from conftest import vouch_for

import rippleb  # noqa: F401 - before numpy: the portable numeric paths
from rippleb.cli import main
from support import GOOD, PLUGIN, install_dist, one_error

SELECTION = {"methods": ["raw"], "conditions": ["same-session"], "seeds": [0], "scenarios": ["static-contact"]}


def _run_dir(tmp_path, **changes) -> str:
    """A run directory holding only a run.json (the selection) with ``changes`` applied."""
    config = {**SELECTION, **changes}
    config = {k: v for k, v in config.items() if v is not None}
    (tmp_path / "run").mkdir()
    (tmp_path / "run" / "run.json").write_text(json.dumps(config))
    return str(tmp_path / "run")


@pytest.mark.parametrize("field, value, words", [
    ("seeds", None, ["'seeds'", "the field is missing"]),
    ("scenarios", None, ["'scenarios'", "the field is missing"]),
    ("seeds", ["0"], ["'seeds'", '["0"]']),
    ("seeds", "abc", ["'seeds'", '"abc"']),
    ("seeds", [True], ["'seeds'", "[true]"]),
    ("seeds", [], ["'seeds'"]),
    ("conditions", "same-session", ["'conditions'"]),
    ("methods", ["raw", 3], ["not a rippleb run file"]),
    ("sealed", {"commitment": "md5:abc"}, ["'sealed'"]),
])
def test_a_damaged_run_json_is_one_line_on_resume(tmp_path, capsys, field, value, words):
    out = _run_dir(tmp_path, **{field: value})
    if field == "methods":
        words = ["'methods'"]
    assert main(["run", "--resume", out, "--no-progress"]) == 2
    one_error(capsys, f"{out}/run.json", *words)
    assert sorted(p.name for p in (tmp_path / "run").iterdir()) == ["run.json"]   # nothing written


@pytest.mark.parametrize("command, extra, words", [
    ("run", ["--out", "elsewhere"], ["--out does not apply with --resume"]),
    ("run", ["--calibration", "cal.csv"], ["--calibration does not apply with --resume"]),
    ("sweep", ["--out", "elsewhere"], ["--out does not apply with --resume"]),
])
def test_options_that_resume_would_ignore_are_refused(tmp_path, monkeypatch, capsys, command, extra, words):
    monkeypatch.chdir(tmp_path)
    out = _run_dir(tmp_path, sweep={"joint.fs": [20000.0]} if command == "sweep" else None)
    assert main([command, "--resume", out, *extra, "--no-progress"]) == 2
    one_error(capsys, *words)
    assert not (tmp_path / "elsewhere").exists()
    assert sorted(p.name for p in (tmp_path / "run").iterdir()) == ["run.json"]


def test_seeds_have_an_upper_bound(tmp_path, monkeypatch, capsys):
    from rippleb.engine.runner import MAX_SEEDS

    monkeypatch.chdir(tmp_path)
    assert main(["run", "--methods", "raw", "--seeds", "100000", "--out", "out"]) == 2
    one_error(capsys, "--seeds 100000", f"at most {MAX_SEEDS}")
    assert main(["sweep", "--param", "joint.fs=20000", "--seeds", str(MAX_SEEDS + 1), "--out", "out"]) == 2
    one_error(capsys, f"at most {MAX_SEEDS}")
    out = _run_dir(tmp_path, seeds=list(range(MAX_SEEDS + 1)))
    assert main(["run", "--resume", out]) == 2
    one_error(capsys, "'seeds'", f"{MAX_SEEDS + 1} seeds")
    assert not (tmp_path / "out").exists()


def test_a_sweep_of_no_values_is_refused(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    assert main(["sweep", "--param", "joint.fs=,,", "--methods", "raw", "--out", "out"]) == 2
    one_error(capsys, "--param 'joint.fs=,,'", "no values")
    assert not (tmp_path / "out").exists()


@pytest.mark.slow
@pytest.mark.parametrize("name", ["all", "a,b", "ALL", "has space", "../up"])
def test_a_plugin_named_all_or_not_an_identifier_is_refused_at_discovery(tmp_path, name):
    site = tmp_path / "site"
    install_dist(site, "rippleb-oddname", "odd_mod", PLUGIN, {name: "Plugin"})
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(site), os.environ.get("PYTHONPATH", "")])}
    for args in (["list"], ["run", "--methods", "raw", "--seeds", "1", "--out", "out"]):
        proc = subprocess.run([sys.executable, "-m", "rippleb", *args], cwd=tmp_path, env=env,
                              capture_output=True, text=True, timeout=300)
        assert proc.returncode == 2, proc.stderr
        lines = proc.stderr.strip().splitlines()
        assert len(lines) == 1 and f"method {name!r} (rippleb-oddname: odd_mod:Plugin)" in lines[0], lines
        assert not (tmp_path / "out").exists()


def test_method_names_are_checked():
    from rippleb.errors import PluginError
    from rippleb.registry import check_method_name

    for good in ("raw", "order-tracking-no-backprop", "my_method2", "_private"):
        check_method_name(good, "x")
    for bad in ("all", "All", "a,b", "", "-x", "2fast", "a b", "a/b", "a|b"):
        with pytest.raises(PluginError, match="rename its entry point"):
            check_method_name(bad, "x")


# ----------------------------------------------------------------------------- report


@pytest.fixture(scope="module")
def finished(tmp_path_factory):
    """A finished run: raw on static-contact and on a scenario file named ``a|b.toml``."""
    root = tmp_path_factory.mktemp("finished")
    (root / "a|b.toml").write_text(GOOD)
    cwd = os.getcwd()
    os.chdir(root)
    try:
        assert main(["run", "--methods", "raw,lowpass", "--scenarios", "static-contact,a|b.toml", "--seeds",
                     "2", "--jobs", "2", "--no-progress", "--out", "run"]) == 0
    finally:
        os.chdir(cwd)
    return root / "run"


@pytest.fixture
def run_copy(finished, tmp_path):
    return shutil.copytree(finished, tmp_path / "run")


def _table_lines(text: str) -> list[str]:
    return [line for line in text.splitlines() if line.startswith("|")]


@pytest.mark.slow
def test_a_bar_in_a_scenario_name_stays_in_its_cell(run_copy, capsys):
    import re

    from rippleb.report.markdown_html import table_html

    assert main(["report", str(run_copy), "--no-figures", "--html"]) == 0
    readme = (run_copy / "report" / "README.md").read_text()
    assert "a\\|b" in readme
    tables, table = [], []
    for line in readme.splitlines() + [""]:
        if line.startswith("|"):
            table.append(line)
        elif table:
            tables.append(table)
            table = []
    assert tables
    for table in tables:   # every row of a table has as many cells as its header
        counts = {len(re.split(r"(?<!\\)\|", line)) for line in table}
        assert len(counts) == 1, table
    html = table_html("\n".join(next(t for t in tables if any("a\\|b" in line for line in t))))
    assert ">a|b<" in html and "a\\|b" not in html
    assert "a|b" in (run_copy / "report" / "index.html").read_text()


@pytest.mark.slow
@pytest.mark.parametrize("where", ["run.json", "provenance.json"])
def test_report_of_a_run_file_that_is_a_list_is_one_line(run_copy, capsys, where):
    (run_copy / where).write_text("[1, 2]\n")
    assert main(["report", str(run_copy), "--no-figures"]) == 2
    one_error(capsys, f"{run_copy}/{where}", "not a rippleb run file", "JSON list")


@pytest.mark.slow
def test_report_on_a_full_disk_is_one_line(run_copy, monkeypatch, capsys):
    """ENOSPC while the figures are written (docs/robustness.md measured it on a 64 KiB tmpfs)."""
    import errno

    import matplotlib.figure

    def full(self, *args, **kwargs):
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
    monkeypatch.setattr(matplotlib.figure.Figure, "savefig", full)
    assert main(["report", str(run_copy), "--speed-seeds", "1"]) == 2
    one_error(capsys, f"{run_copy}/report", "cannot write", "No space left on device")
    assert (run_copy / "results.csv").is_file()


def _edit_cells(path, edits: dict) -> None:
    """Set ``{(line number, column): text}`` in a results CSV."""
    rows = list(csv.reader(io.StringIO(path.read_text())))
    header = rows[0]
    for (line, column), text in edits.items():
        rows[line - 1][header.index(column)] = text
    buffer = io.StringIO()
    csv.writer(buffer, lineterminator="\n").writerows(rows)
    path.write_text(buffer.getvalue())


@pytest.mark.slow
def test_report_warns_of_a_negative_or_infinite_metric_and_keeps_the_rows(run_copy, capsys):
    _edit_cells(run_copy / "results.csv", {(2, "rms_error_nm"): "-0.5", (3, "max_error_nm"): "inf",
                                           (4, "step_latency_ms"): "-0.2"})    # a lead: legitimate
    vouch_for(run_copy)   # rows a rippleb wrote (else their hashes fail and they are dropped)
    assert main(["report", str(run_copy), "--no-figures"]) == 0
    err = capsys.readouterr().err
    warning = [line for line in err.splitlines() if "no rippleb run writes" in line]
    assert len(warning) == 1, err
    assert "2 metric value(s)" in warning[0] and "rms_error_nm = -0.5" in warning[0]
    assert "max_error_nm = inf" in warning[0] and "step_latency_ms" not in warning[0]
    readme = (run_copy / "report" / "README.md").read_text()
    assert "8 rows" in readme   # kept


@pytest.mark.slow
def test_resume_names_rows_of_another_rippleb_version(run_copy, capsys):
    from rippleb import __version__

    _edit_cells(run_copy / "results.csv", {(2, "rippleb_version"): "0.0.1", (3, "rippleb_version"): "0.0.1"})
    lines = (run_copy / "results.csv").read_text().splitlines()
    (run_copy / "results.csv").write_text("\n".join(lines[:-1]) + "\n")   # one row to run again
    vouch_for(run_copy)   # rows another rippleb version wrote, not forged ones
    assert main(["run", "--resume", str(run_copy), "--no-progress", "--jobs", "1"]) == 0
    err = capsys.readouterr().err
    warning = [line for line in err.splitlines() if "another rippleb version" in line]
    assert len(warning) == 1, err
    assert f"{run_copy}/results.csv: 2 finished row(s)" in warning[0] and "2 by 0.0.1" in warning[0]
    assert f"this is {__version__}" in warning[0]
    assert len((run_copy / "results.csv").read_text().splitlines()) == 9   # kept, and the row added


@pytest.mark.slow
def test_report_says_whether_its_rows_were_sealed(run_copy, capsys):
    assert main(["report", str(run_copy), "--no-figures"]) == 0
    readme = (run_copy / "report" / "README.md").read_text()
    assert "Not sealed:" in readme and "| sealed" in readme and "no: public seeds" in readme
    capsys.readouterr()

"""Issue 41, item 4: inputs that cannot be turned against their reader.

Each case went wrong before (a hang, a traceback, gigabytes read or planned, an ``ok`` row
of a joint that cannot exist, a formula in a results file); each is now one line naming
the file, field or option and exit 2, before anything is expanded in memory. Through the
real CLI (``rippleb.cli.main`` in-process), each refused command leaves nothing behind.
docs/robustness.md, section 11, lists them with their outcome before and after.
"""

from __future__ import annotations

import csv
import io
import json
import os
import threading

import pytest
from hypothesis import given, strategies as st

import rippleb  # noqa: F401 - before numpy: the portable numeric paths
from rippleb.cli import main
from rippleb.printable import CSV_ACTIVE, csv_read, csv_text
from support import GOOD, log_frame
from support import one_error


# --------------------------------------------------------------------------- run directories

def _run_dir(tmp_path, **files):
    run = tmp_path / "run"
    run.mkdir()
    for name, text in files.items():
        (run / name.replace("_", ".")).write_text(text)
    return run


@pytest.mark.parametrize("name", ["run.json", "results.csv", "rows.mac", "provenance.json"])
def test_a_run_directory_file_that_is_a_link_to_dev_zero_is_one_line(tmp_path, monkeypatch, capsys, name):
    """``run.json`` or ``rows.mac`` a link to /dev/zero was read to a MemoryError (5.4 GB)."""
    monkeypatch.chdir(tmp_path)
    run = _run_dir(tmp_path, run_json=json.dumps({"methods": ["raw"], "seeds": [0], "scenarios": ["creep"]}),
                   results_csv="method,scenario,seed,status\n")
    (run / name).unlink(missing_ok=True)
    os.symlink("/dev/zero", run / name)
    for argv in (["report", str(run)], ["run", "--resume", str(run), "--no-progress"]):
        status = main(argv)
        err = capsys.readouterr().err
        if name in ("rows.mac", "provenance.json") and argv[0] == "run":
            continue   # --resume stops at run.json's missing integrity field first
        assert status == 2, err
        assert err.count("rippleb: error: ") == 1 and str(run) in err, err
    assert os.path.islink(run / name)   # nothing written through it


def test_a_run_json_that_links_elsewhere_is_not_followed(tmp_path, capsys):
    elsewhere = tmp_path / "elsewhere.json"
    elsewhere.write_text(json.dumps({"methods": ["raw"], "seeds": [0], "scenarios": ["creep"]}))
    run = _run_dir(tmp_path)
    os.symlink(elsewhere, run / "run.json")
    assert main(["run", "--resume", str(run), "--no-progress"]) == 2
    one_error(capsys, f"{run}/run.json", "a symbolic link")


def test_a_results_file_over_its_cap_is_refused_before_it_is_read(tmp_path, monkeypatch, capsys):
    from rippleb import reading

    run = _run_dir(tmp_path, results_csv="method,scenario,seed,status\n" + "x,y,0,ok\n" * 100)
    monkeypatch.setattr(reading, "RESULTS_BYTES", 64)
    assert main(["report", str(run)]) == 2
    one_error(capsys, "results.csv", "more than the 64 bytes a results file may have")


@pytest.mark.parametrize("depth", [40, 100_000])
def test_a_deeply_nested_run_json_is_one_line(tmp_path, capsys, depth):
    run = _run_dir(tmp_path, run_json='{"methods": ' + "[" * depth + "]" * depth + "}")
    assert main(["run", "--resume", str(run), "--no-progress"]) == 2
    one_error(capsys, "run.json", "nested more than 32 levels")


def test_a_report_into_a_directory_of_links_writes_nothing_through_them(tmp_path, capsys):
    """``figures`` a link to a directory elsewhere took the report's figures there."""
    from rippleb.engine.results import COLUMNS, ResultsFile
    from rippleb.report.writer import REPORT_ENTRIES

    run = _run_dir(tmp_path)
    ResultsFile(run / "results.csv").add({c: None for c in COLUMNS} | {
        "method": "raw", "scenario": "creep", "condition": "same-session", "seed": 0, "status": "ok",
        "rms_error_nm": 1.0})
    outside = tmp_path / "outside"
    outside.mkdir()
    for name in REPORT_ENTRIES:
        report = tmp_path / f"report-{name}"
        report.mkdir()
        os.symlink(outside / name, report / name)
        assert main(["report", str(run), "--out", str(report)]) == 2
        one_error(capsys, f"{report / name}: a symbolic link")
    inner = tmp_path / "report-inner"
    (inner / "figures").mkdir(parents=True)
    os.symlink(outside / "x.png", inner / "figures" / "rows.png")   # a link inside figures/
    assert main(["report", str(run), "--out", str(inner)]) == 2
    one_error(capsys, f"{inner / 'figures' / 'rows.png'}: a symbolic link")
    os.symlink(outside, run / "report")   # the run's own report entry, a link to elsewhere
    assert main(["report", str(run)]) == 2
    one_error(capsys, f"{run / 'report'}: a symbolic link")
    assert not list(outside.iterdir())   # nothing written there


# --------------------------------------------------------------------------- user files

def _fifo(path) -> str:
    os.mkfifo(path)
    return str(path)


def _bounded(target, seconds: float = 60.0):
    """Run ``target()`` in a thread; fail if it does not return within ``seconds`` (a hang
    would otherwise hang the suite), return its result."""
    result = {}
    thread = threading.Thread(target=lambda: result.setdefault("value", target()), daemon=True)
    thread.start()
    thread.join(seconds)
    assert not thread.is_alive(), "still reading after 60 s: it blocked on the FIFO"
    return result["value"]


def test_a_fifo_as_joint_file_scenario_or_log_is_one_line_not_a_hang(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    log_frame(n=8000).to_csv("rec.csv", index=False)
    cases = [(["run", "--log", "rec.csv", "--joint", _fifo(tmp_path / "joint.toml"), "--out", "o"], "joint.toml"),
             (["run", "--methods", "raw", "--scenarios", _fifo(tmp_path / "s.toml"), "--out", "o"], "s.toml"),
             (["run", "--log", _fifo(tmp_path / "fifo.csv"), "--out", "o"], "fifo.csv"),
             (["simulate", _fifo(tmp_path / "t.toml"), "--out", "x.csv"], "t.toml")]
    for argv, name in cases:
        assert _bounded(lambda: main(argv)) == 2
        one_error(capsys, name, "a FIFO (named pipe), not a regular file")
    assert not (tmp_path / "o").exists() and not (tmp_path / "x.csv").exists()


@pytest.mark.parametrize("device", ["/dev/zero", "/dev/urandom"])
def test_a_log_or_scenario_that_names_a_device_is_one_line(tmp_path, monkeypatch, capsys, device):
    monkeypatch.chdir(tmp_path)
    os.symlink(device, tmp_path / "dev.toml")
    os.symlink(device, tmp_path / "dev.csv")
    assert main(["run", "--methods", "raw", "--scenarios", "dev.toml", "--out", "o"]) == 2
    one_error(capsys, "dev.toml", "a character device")
    assert main(["run", "--log", "dev.csv", "--out", "o"]) == 2
    one_error(capsys, "dev.csv", "a character device")


@pytest.mark.parametrize("kind, text, words", [
    ("array", "[joint]\ncounts_per_rev = " + "[" * 100_000 + "]" * 100_000 + "\n", ["nested more than 32"]),
    ("table", "[joint]\ncolumns = " + "{a = " * 40 + "1" + "}" * 40 + "\n", ["nested more than 32"]),
    ("integer", "[joint]\ncounts_per_rev = " + "1" * 5000 + "\n", ["not valid TOML", "4300"]),
])
def test_a_joint_file_nested_too_deep_or_with_a_giant_integer_is_one_line(tmp_path, monkeypatch, capsys,
                                                                            kind, text, words):
    monkeypatch.chdir(tmp_path)
    log_frame(n=8000).to_csv("rec.csv", index=False)
    (tmp_path / "joint.toml").write_text(text)
    (tmp_path / "deep.toml").write_text(text.replace("[joint]\ncounts_per_rev", "duration").replace(
        "[joint]\ncolumns", "duration") + GOOD)
    assert main(["run", "--log", "rec.csv", "--joint", "joint.toml", "--out", "o"]) == 2
    one_error(capsys, "joint.toml", *words)
    assert main(["run", "--methods", "raw", "--scenarios", "deep.toml", "--out", "o"]) == 2
    one_error(capsys, "deep.toml", *words)
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize("key, value", [("counts_per_rev", "4611686018427387904"), ("gear_ratio", "1e308"),
                                        ("control_rate", "1e-9"), ("rated_torque", "1e300"),
                                        ("rotor_inertia", "1e-300"), ("torque_constant", "5e5")])
def test_absurd_joint_values_are_refused_in_a_joint_file_and_a_scenario(tmp_path, monkeypatch, capsys, key, value):
    """2**62 counts per revolution, a gear of 1e308 and a control rate of 1e-9 Hz gave ok rows."""
    from rippleb.reading import JOINT_RANGES

    monkeypatch.chdir(tmp_path)
    log_frame(n=8000).to_csv("rec.csv", index=False)
    (tmp_path / "joint.toml").write_text(f"[joint]\n{key} = {value}\n")
    (tmp_path / "s.toml").write_text(f"[joint]\n{key} = {value}\n" + GOOD)
    low, high = JOINT_RANGES[key]
    assert main(["run", "--log", "rec.csv", "--joint", "joint.toml", "--out", "o"]) == 2
    one_error(capsys, "joint.toml", f"joint.{key}", f"[{low:g}, {high:g}]")
    assert main(["run", "--methods", "raw", "--scenarios", "s.toml", "--out", "o"]) == 2
    one_error(capsys, "s.toml", f"joint.{key}", f"[{low:g}, {high:g}]")
    assert not (tmp_path / "o").exists()


def test_a_log_column_mapped_twice_is_refused(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    log_frame(n=8000).to_csv("rec.csv", index=False)
    (tmp_path / "joint.toml").write_text('[joint.columns]\nstrain = "strain"\ncurrent = "strain"\n')
    assert main(["run", "--log", "rec.csv", "--joint", "joint.toml", "--out", "o"]) == 2
    one_error(capsys, "joint.toml", "strain and current both map the log's column 'strain'")


def test_a_log_with_more_rows_than_the_cap_is_refused_reading_no_further(tmp_path, monkeypatch, capsys):
    from rippleb import log_files

    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr(log_files, "MAX_LOG_SAMPLES", 100)
    frame = log_frame(n=8000)
    frame.to_csv("rec.csv", index=False)
    frame.to_parquet("rec.parquet")
    for name in ("rec.csv", "rec.parquet"):
        assert main(["run", "--log", name, "--out", "o"]) == 2
        one_error(capsys, name, "more than the 100 rows a log may hold")


# --------------------------------------------------------------------------- options

def test_a_value_of_5000_digits_is_one_line(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    for value, words in (("1" * 5000, ["5000 characters"]), ("9" * 40, ["beyond 64 bits"]),
                         ("1e999", ["not a finite number"]), ("nan", ["not a finite number"])):
        assert main(["run", "--methods", f"lowpass[cutoff_hz={value}]", "--out", "o"]) == 2
        one_error(capsys, "lowpass", "cutoff_hz", *words)
    assert not (tmp_path / "o").exists()


def test_a_variant_grid_of_1e9_points_is_refused_before_it_is_made(tmp_path, monkeypatch, capsys):
    """The 1e9 grid was expanded in memory (3.6 GB, MemoryError) before any check."""
    import tracemalloc

    monkeypatch.chdir(tmp_path)
    values = ",".join(map(str, range(1000)))
    tracemalloc.start()
    assert main(["run", "--methods", f"raw[a={values},b={values},c={values}]", "--out", "o"]) == 2
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    one_error(capsys, "1e+09 variants", "more than the 1000")
    assert peak < 200e6, peak   # a few MB of parsing; the grid itself would be gigabytes


def test_a_sweep_of_40000_points_is_refused_before_it_is_made(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    rates = ",".join(f"{100 + 0.05 * i:g}" for i in range(200))
    ratios = ",".join(f"{30 + 0.6 * i:g}" for i in range(200))
    assert main(["sweep", "--param", f"joint.control_rate={rates}", "--param", f"joint.gear_ratio={ratios}",
                 "--methods", "raw", "--out", "o"]) == 2
    one_error(capsys, "a grid of 40000 points (200 x 200 values)", "more than the 1000")
    assert not (tmp_path / "o").exists()


def test_a_run_of_more_rows_than_the_cap_is_refused_before_planning(tmp_path, monkeypatch, capsys):
    from rippleb.engine import rows

    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr(rows, "MAX_ROWS", 10)
    assert main(["run", "--methods", "raw,lowpass", "--scenarios", "creep,reversal", "--seeds", "3",
                 "--out", "o"]) == 2
    one_error(capsys, "2 methods x 2 scenarios x 1 conditions x 3 seeds is 12 rows", "more than the 10")
    assert not (tmp_path / "o").exists()


def test_tune_budget_and_seeds_are_bounded(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    assert main(["tune", "--budget", "1000000", "--out", "t.json"]) == 2
    one_error(capsys, "--budget", "1-1024", "1000000")
    assert main(["tune", "--seeds", "0-99999999999", "--out", "t.json"]) == 2
    one_error(capsys, "--seeds", "more than the 10000")
    assert not (tmp_path / "t.json").exists()


def test_planning_a_large_run_gives_way_to_ctrl_c(monkeypatch):
    """A signal while a large plan is made stops it at the next seed (it ran to the end, 123 s)."""
    from rippleb import interrupts
    from rippleb.engine import runner

    def planned(*args, **kwargs):
        raise AssertionError("the plan was finished and executed despite the signal")
    monkeypatch.setattr(runner, "_execute", planned)
    with interrupts.handling(), interrupts.held():
        interrupts._handler(2, None)   # a SIGINT, recorded while held, as in `rippleb run`
        with pytest.raises(KeyboardInterrupt):
            runner.run("raw", "creep", 3)


# --------------------------------------------------------------------------- CSV

@given(st.text(max_size=40))
def test_csv_text_reads_back_and_never_starts_a_formula(value):
    cell = csv_text(value)
    assert csv_read(cell) == value
    assert not cell[:1] or cell[:1] not in set(CSV_ACTIVE) - {"'"}


def test_results_csv_and_the_report_s_copy_hold_no_formula(tmp_path):
    """``=HYPERLINK(...)`` started a results.csv cell (a scenario file, a message); numbers
    (a negative metric) stay numbers; the reader gets every text back."""
    from rippleb.engine.results import COLUMNS, ResultsFile, copy_rows, read_rows, row_key

    row = {c: None for c in COLUMNS} | {"method": "raw", "scenario": '=HYPERLINK("http://e","x")',
                                         "condition": "same-session", "seed": 0, "status": "error",
                                         "message": "@SUM(1)", "step_latency_ms": -0.5, "params": "'quoted"}
    results = ResultsFile(tmp_path / "results.csv")
    results.add(row)
    cells = list(csv.reader(io.StringIO((tmp_path / "results.csv").read_text())))
    record = dict(zip(cells[0], cells[1]))
    assert record["scenario"] == '\'=HYPERLINK("http://e","x")' and record["message"] == "'@SUM(1)"
    assert record["step_latency_ms"] == "-0.5" and record["params"] == "''quoted"
    back = read_rows(tmp_path / "results.csv")[0]
    assert (back["scenario"], back["message"], back["params"], back["step_latency_ms"]) == \
        (row["scenario"], row["message"], row["params"], -0.5)
    # a file written before (raw formulas): its copy in a report is neutralised
    legacy = (tmp_path / "results.csv").read_text().replace("'=HYPERLINK", "=HYPERLINK")
    (tmp_path / "legacy.csv").write_text(legacy)
    copy_rows(tmp_path / "legacy.csv", tmp_path / "copy.csv", {row_key(back)})
    assert (tmp_path / "copy.csv").read_text() == (tmp_path / "results.csv").read_text()

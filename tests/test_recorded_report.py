"""Reports of a recorded log: ranked by what the log can score (rippleb/report/recorded.py)."""

import subprocess
import sys
import warnings

import numpy as np
import pandas as pd
import pytest

from rippleb.report import figures, recorded, tables
from rippleb.report.error_figures import plot_accuracy_vs_cost

NAN = float("nan")


def _log_frame(**columns):
    """Rows of one recorded log; ``columns`` maps a column to its value per method."""
    methods = ["raw", "lowpass", "order-tracking"]
    rows = []
    for i, method in enumerate(methods):
        row = {"method": method, "scenario": "log:rec.csv", "condition": "same-session", "seed": 0,
               "status": "ok", "message": "", "rms_error_nm": NAN, "max_error_nm": NAN,
               "rms_error_ref_nm": NAN, "ripple_wg_nm": NAN, "rest_std_nm": NAN, "strain_delay_ms": NAN,
               "us_per_tick_p50": 2.0, "us_per_tick_p99": 5.0}
        rows.append(row | {c: values[i] for c, values in columns.items()})
    return pd.DataFrame(rows)


def test_the_ranking_column_is_the_best_score_the_log_has():
    assert recorded.ranking_column(_log_frame(ripple_wg_nm=[1.0, 0.5, 0.2])) == "ripple_wg_nm"
    assert recorded.ranking_column(_log_frame(ripple_wg_nm=[1.0, 0.5, 0.2],
                                              rms_error_ref_nm=[2.0, 1.0, 3.0])) == "rms_error_ref_nm"
    assert recorded.ranking_column(_log_frame(rms_error_nm=[2.0, 1.0, 3.0],
                                              rms_error_ref_nm=[2.0, 1.0, 3.0])) == "rms_error_nm"


def test_a_log_without_reference_is_ranked_by_the_ripple_left_with_each_columns_rank():
    frame = _log_frame(ripple_wg_nm=[1.0, 0.6, 0.2], rest_std_nm=[0.01, 0.001, 0.02],
                       strain_delay_ms=[0.0, 7.5, -1.0])
    text = recorded.recorded_tables_markdown(frame)
    table = [line for line in text.splitlines() if line.startswith("| ")]
    assert [line.split("|")[2].strip() for line in table[1:]] == ["order-tracking", "lowpass", "raw"]
    assert "0.2 (1)" in table[1] and "0.02 (3)" in table[1] and "-1 (2)" in table[1]   # |delay| ranks
    assert "neither `torque_true` nor `torque_ref`" in text and "n/a" not in table[1]
    # shares of raw's ripple removed, from the rows: 1 - 0.2/1, 1 - 0.6/1
    assert "`order-tracking` 80%, `lowpass` 40%" in text
    assert "What the scores cannot tell" in text


def test_a_log_without_two_revolutions_is_ranked_by_the_delay_and_without_any_score_not_at_all():
    frame = _log_frame(strain_delay_ms=[0.5, 7.5, -0.2])
    assert recorded.ranking_column(frame) == "strain_delay_ms"
    text = recorded.recorded_tables_markdown(frame)
    assert "No run of motion in one direction spans two motor revolutions" in text
    table = [line.split("|") for line in text.splitlines() if line.startswith("| ")][1:]
    assert [cells[2].strip() for cells in table] == ["order-tracking", "raw", "lowpass"]   # by |delay|
    unranked = [line.split("|") for line in recorded.log_markdown(_log_frame()).splitlines()
                if line.startswith("| ")][1:]
    assert [cells[1].strip() for cells in unranked] == ["-", "-", "-"]


def test_a_log_with_a_reference_is_ranked_by_it():
    frame = _log_frame(rms_error_ref_nm=[2.0, 1.0, 3.0], ripple_wg_nm=[1.0, 0.6, 0.2])
    text = recorded.recorded_tables_markdown(frame)
    assert "methods ranked by `rms_error_ref_nm`" in text
    assert "`lowpass` ranks first by `rms_error_ref_nm` (1 Nm)" in text


def test_failed_rows_are_listed_not_ranked():
    frame = _log_frame(ripple_wg_nm=[1.0, 0.6, 0.2])
    frame.loc[2, ["status", "message", "ripple_wg_nm"]] = ["error", "ValueError: boom", NAN]
    text = recorded.recorded_tables_markdown(frame)
    assert "ValueError: boom" in text
    assert [line.split("|")[2].strip() for line in text.splitlines() if line.startswith("| ")][1:3] == \
        ["lowpass", "raw"]
    assert "ValueError: boom" in recorded.run_summary(frame)


def test_the_run_summary_of_a_log_ranks_and_of_simulated_devices_is_unchanged():
    frame = _log_frame(ripple_wg_nm=[1.0, 0.6, 0.2])
    assert "log:rec.csv: 3 ranked rows of 3, ranked by ripple_wg_nm" in recorded.run_summary(frame)
    simulated = frame.assign(scenario="paper-quintic", rms_error_nm=[1.0, 0.5, 0.3], max_error_nm=1.0)
    assert recorded.run_summary(simulated) == tables.summary_text(simulated)


def test_no_cost_figure_without_a_score_and_no_legend_warning_without_points(tmp_path):
    assert figures._cost_figure_column(_log_frame()) is None
    assert figures._cost_figure_column(_log_frame(ripple_wg_nm=[1.0, 0.6, 0.2])) == "ripple_wg_nm"
    assert figures._cost_figure_column(_log_frame(strain_delay_ms=[0.0, 7.5, -1.0])) is None   # no log axis
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        plot_accuracy_vs_cost(_log_frame(), tmp_path / "empty.png", "ripple_wg_nm")


@pytest.mark.slow
def test_a_log_without_truth_is_ranked_end_to_end_through_the_cli(tmp_path):
    def rippleb(*args):
        proc = subprocess.run([sys.executable, "-m", "rippleb", *map(str, args)], capture_output=True,
                              text=True, cwd=tmp_path, timeout=1800)
        assert proc.returncode == 0, proc.stderr
        return proc

    rippleb("simulate", "paper-quintic", "--seed", 3, "--out", "sim.csv")
    rippleb("simulate", "calibration", "--seed", 3, "--out", "cal.csv")
    sim = pd.read_csv(tmp_path / "sim.csv")
    sim.drop(columns=["torque_true", "torque_ref"]).to_csv(tmp_path / "lab.csv", index=False)
    methods = "raw,lowpass,order-tracking"
    run = rippleb("run", "--log", "lab.csv", "--calibration", "cal.csv", "--methods", methods, "--out", "r")
    assert "log:lab.csv: 3 ranked rows of 3, ranked by ripple_wg_nm" in run.stdout
    rows = pd.read_csv(tmp_path / "r" / "results.csv")
    # no reference: accuracy cannot be scored, the truth-free columns rank the rows
    assert (rows["status"] == "no-reference").all() and rows["rms_error_ref_nm"].isna().all()
    assert (rows["ripple_wg_nm"] > 0).all() and np.isfinite(rows["rest_std_nm"]).all()
    # the ranking printed is the rows' order by ripple_wg_nm
    printed = [line.split("|")[2].strip() for line in run.stdout.splitlines() if line.startswith("| ")][1:]
    assert printed == list(rows.sort_values("ripple_wg_nm")["method"])

    report = rippleb("report", "r", "--html")
    assert report.stderr == "", report.stderr      # no warning of any kind (legend, empty figure)
    readme = (tmp_path / "r" / "report" / "README.md").read_text()
    assert "methods ranked by `ripple_wg_nm`" in readme and "no rows to rank" not in readme
    assert "`ripple_wg_nm` against per-tick cost" in readme
    assert (tmp_path / "r" / "report" / "figures" / "accuracy_vs_cost.png").stat().st_size > 0
    page = (tmp_path / "r" / "report" / "index.html").read_text()
    assert "methods ranked by <code>ripple_wg_nm</code>" in page and printed[0] in page


def test_the_html_page_of_a_log_ranks_it_and_plots_the_ranking_column(tmp_path):
    from rippleb.report import html_report

    frame = _log_frame(ripple_wg_nm=[1.0, 0.6, 0.2], rest_std_nm=[0.01, 0.001, 0.02])
    prov = {"run": {"command": "rippleb run --log rec.csv"}, "report": {"command": "rippleb report"},
            "published": False, "run_dir": "runs/log", "seeds_text": "0 (1 seed)"}
    page = html_report.write_html(frame, prov, tmp_path / "index.html").read_text()
    assert "methods ranked by <code>ripple_wg_nm</code>" in page and "Method x condition" not in page
    assert page.index(">order-tracking<") < page.index(">lowpass<") < page.index(">raw<")
    cost = html_report._cost_figure(html_report.with_condition(frame), "ripple_wg_nm")
    assert sorted(float(y) for trace in cost.data for y in trace.y) == [0.2, 0.6, 1.0]
    assert "ripple left at WG orders" in cost.layout.yaxis.title.text


def test_no_invalid_method_is_printed_as_a_rank():
    """Issue 39: with 13 of 14 rows invalid, the one ok row was printed 'rank 1'; rows that were
    not measured are listed, never ranked, and a log with none measured ranks nothing."""
    frame = _log_frame(ripple_wg_nm=[1.0, 0.6, 0.2])
    frame["status"] = "invalid"
    frame["message"] = "its estimate reaches 7124 Nm, beyond 510 Nm"
    summary = recorded.run_summary(frame)
    assert "0 ranked rows of 3" in summary and "(no rows to rank)" in summary
    assert not [line for line in summary.splitlines() if line.startswith("| 1 ")]
    assert summary.count("invalid: its estimate reaches 7124 Nm") == 3


def test_a_model_reference_is_ranked_by_the_rebuilt_torque_and_a_transducer_by_itself():
    frame = _log_frame(rms_error_ref_nm=[2.0, 1.0, 0.5], rms_error_rebuilt_nm=[1.0, 2.0, 3.0])
    assert recorded.ranking_column(frame) == "rms_error_rebuilt_nm"
    text = recorded.recorded_tables_markdown(frame, {"reference_kind": "model"})
    assert "`raw` ranks first by `rms_error_rebuilt_nm`" in text and "lacks the gear's own torque" in text
    transducer = _log_frame(rms_error_ref_nm=[2.0, 1.0, 0.5])
    text = recorded.recorded_tables_markdown(transducer, {"reference_kind": "transducer"})
    assert "a torque transducer in series" in text and "`order-tracking` ranks first by `rms_error_ref_nm`" in text


def test_the_ranking_says_how_far_to_trust_it_from_the_panels_nearest_joint():
    from rippleb.report.agreement import trust_sentence

    cells = [{"gear_ratio": ratio, "counts_per_rev": counts, "condition": condition, "reference_kind": "model",
              "score": "rms_error_rebuilt_nm", "devices": 10, "mean_rho": rho, "min_rho": rho - 0.2}
             for ratio, counts, rho in ((100, 2500, 0.5), (160, 4096, 0.9))
             for condition, rho in (("same-session", rho), ("realistic", rho - 0.1))]
    record = {"protocol": {"scenario": "paper-quintic", "seeds": "3000-3009"}, "cells": cells}
    said = trust_sentence("rms_error_rebuilt_nm", {"gear_ratio": 150.0, "counts_per_rev": 5000,
                                                   "reference_kind": "model"}, record)
    assert "gear ratio 160, 4096 counts per revolution, model reference" in said
    assert "+0.85 on average over 20 devices (per condition +0.80 to +0.90; the least on one device +0.60" in said
    assert trust_sentence("rms_error_ref_nm", {"gear_ratio": 150.0, "counts_per_rev": 5000,
                                               "reference_kind": "transducer"}, record) == ""   # not measured
    assert trust_sentence("rms_error_rebuilt_nm", None, record) == ""


def test_a_log_without_reference_shows_the_cost_it_measured():
    """Issue 39: the no-reference report showed n/a for p50 though results.csv has it."""
    frame = _log_frame(ripple_wg_nm=[1.0, 0.6, 0.2]).assign(status="no-reference")
    table = [line for line in recorded.log_markdown(frame).splitlines() if line.startswith("| ")][1:]
    assert all(line.rstrip(" |").endswith("2") for line in table), table

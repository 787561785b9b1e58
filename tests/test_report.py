"""rippleb report: confidence intervals, Table I replica, README, figures, provenance, CLI."""

import json
import subprocess
from types import SimpleNamespace

import numpy as np
import pandas as pd
import pytest

from rippleb import figures, report
from rippleb.cli import main

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


def _frame(rows):
    """Result rows with the columns the report reads; unspecified metrics are 1.0."""
    base = {"status": "ok", "message": "", "rms_error_nm": 1.0, "max_error_nm": 1.0,
            "rms_error_ref_nm": 1.0, "max_error_ref_nm": 1.0, "delay_ms": 1.0,
            "us_per_tick_p99": 10.0, "rippleb_version": "0.1.0", "python": "3.11", "cpu": "x"}
    return pd.DataFrame([{**base, **r} for r in rows])


# --------------------------------------------------------------------------- statistics

def test_t_interval_of_known_values():
    mean, half, n = report.t_interval([1.0, 2.0, 3.0, 4.0, 5.0])
    # s = sqrt(2.5); t_{0.975, 4} = 2.776445 (printed tables)
    assert (mean, n) == (3.0, 5)
    assert half == pytest.approx(2.776445 * np.sqrt(2.5) / np.sqrt(5), rel=1e-6)


def test_t_interval_ignores_nan_and_has_no_width_for_one_value():
    assert report.t_interval([2.0, np.nan])[0] == 2.0
    assert np.isnan(report.t_interval([2.0, np.nan])[1])
    mean, half, n = report.t_interval([])
    assert np.isnan(mean) and np.isnan(half) and n == 0


def test_t_interval_covers_the_true_mean_95_percent_of_the_time():
    rng = np.random.default_rng(1)
    hits = 0
    trials = 2000
    for _ in range(trials):
        mean, half, _ = report.t_interval(rng.normal(5.0, 2.0, size=6))
        hits += abs(mean - 5.0) <= half
    # binomial sd of the rate is 0.005; a z-interval would give about 0.88 here
    assert abs(hits / trials - 0.95) < 0.02


def test_matrix_cells_are_mean_and_half_width_and_mark_missing_seeds():
    rows = [{"method": "raw", "scenario": "creep", "seed": k, "rms_error_nm": v}
            for k, v in enumerate([1.0, 2.0, 3.0, 4.0, 5.0])]
    rows += [{"method": "lowpass", "scenario": "creep", "seed": k, "rms_error_nm": 0.5,
              "status": "ok" if k else "error", "message": "boom"} for k in range(5)]
    text = report.matrix_markdown(_frame(rows), "rms_error_nm")
    assert "| raw " in text and "3 ± 2" in text
    assert "0.5 ± 0 (n=4)" in text


def test_equal_values_show_no_spread():
    mean, half, _ = report.t_interval([7.7] * 20)
    assert report.fmt_interval(mean, half) == "7.7 ± 0"


def test_ranking_says_whether_the_lead_is_resolved():
    rows = [{"method": m, "scenario": "creep", "seed": k, "rms_error_nm": base + 0.01 * k}
            for m, base in (("kalman-ripple", 0.1), ("raw", 1.0), ("lowpass", 1.005)) for k in range(5)]
    ranked = report.ranking(_frame(rows))
    assert list(ranked["method"]) == ["kalman-ripple", "raw", "lowpass"]
    assert "do not overlap" in report.ranking_markdown(_frame(rows))
    assert report.headline_sentences(_frame(rows)) == [
        "`kalman-ripple` has the lowest mean `rms_error_nm` on 1 of 1 scenarios (creep)."]
    close = [r for r in rows if r["method"] != "kalman-ripple"]
    assert "not separated" in report.ranking_markdown(_frame(close))


# --------------------------------------------------------------------------- Table I

def _table_one_rows():
    rows = []
    for k, (cmax, crms, omax, orms) in enumerate([(8.0, 1.0, 4.0, 0.5), (10.0, 2.0, 6.0, 1.5)]):
        rows.append({"method": "current-based", "scenario": "paper-quintic", "seed": k,
                     "max_error_ref_nm": cmax, "rms_error_ref_nm": crms})
        rows.append({"method": "order-tracking", "scenario": "paper-quintic", "seed": k,
                     "max_error_ref_nm": omax, "rms_error_ref_nm": orms})
    # other methods and scenarios must not leak into the table
    rows.append({"method": "order-tracking", "scenario": "creep", "seed": 0, "max_error_ref_nm": 99.0})
    rows.append({"method": "raw", "scenario": "paper-quintic", "seed": 0, "max_error_ref_nm": 99.0})
    return rows


def test_table_one_replica_from_a_synthetic_frame():
    table = report.table_one(_frame(_table_one_rows()))
    assert table.loc["max", "current-based"] == 9.0
    assert table.loc["max", "order-tracking"] == 5.0
    assert table.loc["max", "ratio_pct"] == pytest.approx(100 * 5 / 9)
    assert table.loc["rms", "ratio_pct"] == pytest.approx(100 * 1.0 / 1.5)
    # per-seed ratios 50 % and 60 %: mean 55, half-width t_{0.975,1} * s / sqrt(2)
    assert table.loc["max", "ratio_pct_seeds"] == pytest.approx(55.0)
    assert table.loc["max", "ratio_pct_half"] == pytest.approx(12.706205 * np.std([50, 60], ddof=1) / np.sqrt(2))
    assert table.loc["rms", "n"] == 2
    assert (table.loc["max", "paper_current-based"], table.loc["max", "paper_order-tracking"],
            table.loc["max", "paper_ratio_pct"]) == (8.2, 4.8, 58.0)
    assert (table.loc["rms", "paper_current-based"], table.loc["rms", "paper_order-tracking"],
            table.loc["rms", "paper_ratio_pct"]) == (1.4, 0.9, 64.0)


def test_table_one_markdown_states_numbers_from_the_data():
    text = report.table_one_markdown(_frame(_table_one_rows()))
    assert "| Error max [Nm]" in text and "56 %" in text and "58 %" in text
    assert "order tracking is lower than current-based (5 vs 9 Nm, ratio 56 %), as in the paper" in text


def test_table_one_needs_both_methods():
    rows = [r for r in _table_one_rows() if r["method"] != "current-based"]
    assert report.table_one(_frame(rows)).empty
    assert report.table_one_markdown(_frame(rows)).startswith("Not available")


# --------------------------------------------------------------------------- README

def test_failed_rows_are_listed_and_left_out_of_the_means():
    rows = [{"method": "raw", "scenario": "creep", "seed": 0, "rms_error_nm": 1.0},
            {"method": "raw", "scenario": "creep", "seed": 1, "rms_error_nm": 500.0,
             "status": "timeout", "message": "killed after 300 s"}]
    text = report.tables_markdown(_frame(rows))
    assert "1 of 2 rows did not finish ok" in text
    assert "| raw      | creep      | same-session | 1      | timeout  | killed after 300 s |" in text
    assert "500" not in report.matrix_markdown(_frame(rows), "rms_error_nm")


def test_seeds_text():
    assert report.seeds_text([3, 0, 1, 2]) == "0-3 (4 seeds)"
    assert report.seeds_text([0, 5]) == "0, 5 (2 seeds)"
    assert report.seeds_text([7]) == "7 (1 seed)"


def test_compare_rows_finds_a_changed_value_and_a_missing_row():
    rows = _frame([{"method": "raw", "scenario": "creep", "seed": 0, "rms_error_nm": 0.1 + 0.2}])
    assert report.compare_rows(rows, rows.copy(), ["rms_error_nm"]) == []
    tampered = rows.copy()
    tampered.loc[0, "rms_error_nm"] = np.nextafter(0.1 + 0.2, 1.0)  # one bit off
    assert len(report.compare_rows(tampered, rows, ["rms_error_nm"])) == 1
    other = rows.assign(seed=1)
    assert "not in the published rows" in report.compare_rows(rows, other, ["rms_error_nm"])[0]


# --------------------------------------------------------------------------- figures

def _signals(n=8000, fs=2000.0):
    """A fake scenario: a hold, a move with ripple, a hold and a restart."""
    t = np.arange(n) / fs
    speed = np.where((t > 0.5) & (t < 2.0), 1.0, 0.0) + np.where(t > 3.0, 0.5, 0.0)
    truth = 10 * np.sin(t)
    log = SimpleNamespace(t=t, torque_true=truth, torque_ref=truth + 0.2, meta={"scenario": "fake"})
    sim = SimpleNamespace(log=log, moving=speed > 0, joint_velocity=speed, eval_mask=t > 0.1)
    ripple = np.sin(2 * np.pi * 8 * t) * (speed > 0)
    return figures.ScenarioSignals(sim, {"raw": truth + ripple, "order-tracking": truth + 0.1 * ripple,
                                         "current-based": truth + 0.3}, {})


def _is_png(path):
    return path.is_file() and path.read_bytes()[:8] == PNG_MAGIC and path.stat().st_size > 10_000


def test_signal_figures_are_written_as_png(tmp_path):
    sig = _signals()
    assert _is_png(figures.plot_ripple_compensation(sig, tmp_path / "fig5.png"))
    assert _is_png(figures.plot_estimates(sig, tmp_path / "fig6.png"))
    assert _is_png(figures.plot_error_vs_speed([sig], tmp_path / "speed.png"))
    assert _is_png(figures.plot_restart_zoom(sig, tmp_path / "restart.png"))


def test_accuracy_vs_cost_is_written_as_png(tmp_path):
    rows = [{"method": m, "scenario": s, "seed": k, "rms_error_nm": e * (1 + 0.1 * k), "us_per_tick_p99": c}
            for m, e, c in (("raw", 1.5, 2.0), ("kalman-ripple", 0.2, 300.0)) for s in ("a", "b")
            for k in range(3)]
    assert _is_png(figures.plot_accuracy_vs_cost(_frame(rows), tmp_path / "cost.png"))


def test_error_by_speed_puts_rest_in_bin_zero_and_ripple_in_moving_bins():
    table = figures.error_by_speed([_signals()])
    assert table["speed"][0] == 0.0
    assert table["order-tracking"][0] == pytest.approx(0.0, abs=1e-12)  # no ripple at rest
    moving = table["raw"][1:][np.isfinite(table["raw"][1:])]
    assert np.all(moving > 0.5)  # the unit sine ripple has RMS 0.71


def test_restart_after_the_longest_rest_is_found():
    sig = _signals()
    i = figures.longest_rest_restart(sig)
    assert sig.sim.log.t[i] == pytest.approx(3.0, abs=1e-3)


# --------------------------------------------------------------------------- provenance

def test_provenance_has_every_field():
    prov = report.collect_provenance(["run", "--seeds", "20", "--out", "runs/x y"])
    assert prov["command"] == "rippleb run --seeds 20 --out 'runs/x y'"
    for key in ("rippleb_version", "git_commit", "git_dirty", "python", "numpy", "scipy",
                "pinocchio", "cpu", "platform", "started"):
        assert prov[key] not in ("", None), key


def test_git_state_outside_and_inside_a_checkout(tmp_path):
    assert report.git_state(tmp_path)["git_commit"] == "unknown"
    repo = tmp_path / "repo"
    (repo / "methods").mkdir(parents=True)
    git = ["git", "-C", str(repo), "-c", "user.name=t", "-c", "user.email=t@t"]
    subprocess.run(git + ["init", "-q"], check=True)
    (repo / "methods" / "m.py").write_text("x = 1\n")
    (repo / "notes.txt").write_text("not code\n")
    subprocess.run(git + ["add", "."], check=True)
    subprocess.run(git + ["commit", "-qm", "c"], check=True)
    clean = report.git_state(repo)
    assert len(clean["git_commit"]) == 40 and clean["git_dirty"] is False
    (repo / "notes.txt").write_text("edited notes do not move a result\n")
    assert report.git_state(repo)["git_dirty"] is False
    (repo / "methods" / "m.py").write_text("x = 2\n")
    dirty = report.git_state(repo)
    assert dirty["git_dirty"] is True and dirty["git_dirty_paths"] == ["methods/m.py"]


# --------------------------------------------------------------------------- CLI

def test_report_of_a_directory_without_results_is_a_one_line_error(tmp_path, capsys):
    assert main(["report", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "no results.csv" in err and err.startswith("rippleb: error:")


@pytest.mark.slow
def test_report_through_the_cli_on_a_tiny_run(tmp_path, capsys):
    run_dir, pub = tmp_path / "run", tmp_path / "pub"
    run_args = ["run", "--methods", "raw,lowpass", "--scenarios", "paper-quintic", "--seeds", "2",
                "--jobs", "1", "--out", str(run_dir), "--no-progress"]
    assert main(run_args) == 0
    recorded = json.loads((run_dir / "provenance.json").read_text())
    assert recorded["command"] == "rippleb " + " ".join(run_args)
    assert recorded["completed"] is True and recorded["wall_s"] > 0

    assert main(["report", str(run_dir), "--out", str(pub), "--figure-seed", "1"]) == 0
    readme = (pub / "README.md").read_text()
    assert (pub / "results.csv").read_bytes() == (run_dir / "results.csv").read_bytes()
    frame = report.read_results_exact(pub / "results.csv")
    assert report.tables_markdown(frame) in readme
    assert "4 rows: 2 methods x 1 scenarios x 2 seeds (4 ok)" in readme
    assert "Not available" in readme  # no current-based/order-tracking in this run
    assert f"`rippleb {' '.join(run_args)}`" in readme
    prov = json.loads((pub / "provenance.json").read_text())
    assert prov["seeds"] == [0, 1] and prov["figure_seed"] == 1
    assert prov["run"]["command"] == recorded["command"]
    for name in ("fig2_order_spectra", "fig4_trajectory", "fig5_ripple_compensation", "fig6_estimates", "error_vs_speed",
                 "accuracy_vs_cost"):
        assert f"figures/{name}.png" in readme
        assert _is_png(pub / "figures" / f"{name}.png")
    assert "warning" not in capsys.readouterr().err  # figure signals reproduce the rows of seed 1


@pytest.mark.slow
def test_a_resumed_run_keeps_its_first_command_and_adds_the_resume(tmp_path):
    run_dir = tmp_path / "run"
    first = ["run", "--methods", "raw", "--scenarios", "paper-quintic", "--seeds", "1", "--jobs", "1",
             "--out", str(run_dir), "--no-progress"]
    assert main(first) == 0
    again = ["run", "--resume", str(run_dir), "--methods", "raw,lowpass", "--jobs", "1", "--no-progress"]
    assert main(again) == 0
    recorded = json.loads((run_dir / "provenance.json").read_text())
    assert recorded["command"] == "rippleb " + " ".join(first)
    assert recorded["resumes"] == ["rippleb " + " ".join(again)] and recorded["completed"] is True
    assert f"`rippleb {' '.join(again)}`" in report.provenance_markdown(
        {"run": recorded, "report": recorded, "seeds_text": "0 (1 seed)"})

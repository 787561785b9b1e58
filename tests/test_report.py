"""rippleb report: confidence intervals, Table I replica, README, figures, provenance, CLI."""

import json
import subprocess
from types import SimpleNamespace

import numpy as np
import pandas as pd
import pytest

from rippleb.report import figures, tables, writer as report
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


def test_t_quantile_is_scipy_stats_t_ppf_exactly():
    from scipy import stats

    from rippleb.report.stats import t_quantile

    for p in (0.9, 0.95, 0.975, 0.995):
        for dof in (1, 2, 4, 19, 99):
            assert t_quantile(p, dof) == float(stats.t.ppf(p, dof))


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


def test_ranking_says_whether_the_lead_is_made_and_replicated():
    # lowpass is raw plus 0.02 on the even seeds and minus 0.015 on the odd ones: a lead of
    # raw's that the discovery devices show and the replication devices do not
    rows = [{"method": m, "scenario": "creep", "seed": k,
             "rms_error_nm": base + 0.01 * k + (wobble if k % 2 == 0 else -0.75 * wobble)}
            for m, base, wobble in (("kalman-ripple", 0.1, 0.0), ("raw", 1.0, 0.0), ("lowpass", 1.0, 0.02))
            for k in range(16)]
    ranked = report.ranking(_frame(rows))
    assert list(ranked["method"]) == ["kalman-ripple", "raw", "lowpass"]
    assert ("replicated: kalman-ripple leads raw, lower on 8/8 even seeds (p = 0.0078) and 8/8 odd seeds "
            "(one-sided p = 0.0039)") in report.ranking_markdown(_frame(rows))
    assert report.headline_sentences(_frame(rows)) == [
        "`kalman-ripple` has the lowest mean `rms_error_nm` on 1 of 1 scenarios (creep)."]
    close = [r for r in rows if r["method"] != "kalman-ripple"]
    text = report.ranking_markdown(_frame(close))
    assert "not replicated: raw leads lowpass, lower on 8/8 even seeds" in text and "0/8 odd seeds" in text


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
    assert "| Error max, whole log [Nm]" in text and "56 %" in text and "58 %" in text
    assert "order tracking is lower than current-based (5 vs 9 Nm, ratio 56 %), as in the paper" in text
    assert "during the motion [Nm]" not in text   # rows written before the columns existed


def test_table_one_has_a_row_scored_during_the_motion_beside_the_whole_log():
    rows = _table_one_rows()
    for row in rows:   # during the motion: current-based's max is at a stop, order-tracking's in the motion
        row["max_error_ref_motion_nm"] = row.get("max_error_ref_nm", np.nan) * (
            0.5 if row["method"] == "current-based" else 1.0)
        row["rms_error_ref_motion_nm"] = row.get("rms_error_ref_nm", np.nan)
    table = report.table_one(_frame(rows))
    assert list(table.index) == ["max", "rms", "max_motion", "rms_motion"]
    assert table.loc["max_motion", "ratio_pct"] == pytest.approx(100 * 5 / 4.5)
    assert table.loc["max_motion", "paper_ratio_pct"] == 58.0 and table.loc["rms_motion", "paper_ratio_pct"] == 64.0
    text = report.table_one_markdown(_frame(rows))
    assert "| Error max, during the motion [Nm]" in text and "111 %" in text
    assert "maximum error during the motion: order tracking is higher than current-based" in text


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
    counts = np.floor(np.cumsum(speed) / fs * 100 * 2500 / (2 * np.pi)).astype(int)  # motor at 100 x joint
    log = SimpleNamespace(t=t, torque_true=truth, torque_ref=truth + 0.2, meta={"scenario": "fake"},
                          encoder=counts, spec=SimpleNamespace(fs=fs, counts_per_rev=2500, control_rate=1000.0))
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
    assert "4 rows: 2 methods x 1 scenarios x 1 condition x 2 seeds (4 ok)" in readme
    assert readme.startswith("# rippleb report of `")  # a trial report, not the published one
    assert "Not available" in readme  # no current-based/order-tracking in this run
    assert "mean over 0-1 devices (2 seeds)" in readme  # error against speed over every seed
    assert f"`rippleb {' '.join(run_args)}`" in readme
    prov = json.loads((pub / "provenance.json").read_text())
    assert prov["seeds"] == [0, 1] and prov["figure_seed"] == 1
    assert prov["run"]["command"] == recorded["command"]
    assert "order 4 the largest line on" in readme   # the population's Fig. 2, re-simulated
    for name in ("fig2_order_spectra", "fig2_orders_vs_speed", "fig4_trajectory", "fig5_ripple_compensation", "fig6_estimates", "error_vs_speed",
                 "residual_spectra", "accuracy_vs_cost"):
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


# --------------------------------------------------------------------------- conditions

def _conditions_rows(seeds: int = 4):
    """Two conditions; kalman-ripple leads under same-session and trails under re-assembled.
    Per seed k the errors are base + 0.01 k, so intervals are known in closed form."""
    rows = []
    for condition, kalman in (("same-session", 0.2), ("re-assembled", 1.0)):
        for method, base in (("raw", 2.0), ("order-tracking", 0.5), ("kalman-ripple", kalman)):
            for scenario, extra in (("paper-quintic", 0.0), ("creep", 0.1)):
                rows += [{"method": method, "scenario": scenario, "condition": condition, "seed": k,
                          "rms_error_nm": base + extra + 0.01 * k} for k in range(seeds)]
    return rows


def test_condition_summary_is_the_mean_over_scenarios_then_over_seeds():
    table = tables.condition_summary(_frame(_conditions_rows()))
    cell = table[(table["condition"] == "re-assembled") & (table["method"] == "kalman-ripple")].iloc[0]
    # per seed: mean of (1.0 + 0.01k) and (1.1 + 0.01k) = 1.05 + 0.01k, k = 0..3
    assert cell["mean"] == pytest.approx(1.065)
    assert cell["half"] == pytest.approx(3.182446 * np.std([0, 0.01, 0.02, 0.03], ddof=1) / 2, rel=1e-5)
    assert (cell["n"], cell["scenarios"]) == (4, 2)
    assert list(table["condition"].unique()) == ["same-session", "re-assembled"]  # CONDITIONS order


def test_headline_says_who_leads_under_which_condition():
    lines = tables.condition_headline(_frame(_conditions_rows(16)))
    assert lines[0].startswith("Under `same-session`, on the discovery devices, `kalman-ripple` has the lowest mean")
    assert "ahead of `order-tracking`" in lines[0]
    assert ("`kalman-ripple` leads `order-tracking` under `same-session`: on the 8 discovery devices (even "
            "seeds), `kalman-ripple` is lower on 8/8 devices (median 0.3 Nm; mean 0.3 ± 0 Nm, 97.5 % "
            "t-interval for 2 claims; Wilcoxon signed-rank p = 0.016, Holm for 2 claims); replicated on the 8 "
            "odd seeds") in lines[0]
    assert lines[1].startswith("Under `re-assembled`, on the discovery devices, `order-tracking` has the lowest")
    assert lines[2] == ("Over every device, the lowest mean depends on the condition: `kalman-ripple` under "
                        "`same-session`, `order-tracking` under `re-assembled`.")
    assert tables.headline_lines(_frame(_conditions_rows(16)))[0].startswith(
        "`kalman-ripple` leads `order-tracking` under `same-session`: lower by a median of 0.3 Nm per device, "
        "on 8/8 discovery and 8/8 replication devices")


def test_four_devices_make_no_claim_and_no_headline():
    """Two discovery devices cannot separate two methods at 5 %: the report says so
    instead of headlining a lead."""
    lines = tables.headline_lines(_frame(_conditions_rows(4)))
    assert lines[0] == "No claim of who leads under a condition replicated, so there is no headline."
    assert "(not separated)" in lines[1]


def test_every_table_is_given_per_condition():
    text = report.tables_markdown(_frame(_conditions_rows()))
    for condition in ("same-session", "re-assembled"):
        assert f"## Condition `{condition}`" in text
        assert f"### `rms_error_nm`: RMS error against torque_true [Nm] ({condition})" in text
        assert f"### Ranking per scenario by `rms_error_nm` ({condition})" in text
    assert "| method         | same-session (2 scenarios)   | re-assembled (2 scenarios)   |" in text


def test_rows_without_a_condition_column_are_same_session():
    rows = [{k: v for k, v in r.items() if k != "condition"} for r in _conditions_rows()
            if r["condition"] == "same-session"]
    frame = _frame(rows)
    assert "condition" not in frame
    assert "## Condition `same-session`" in report.tables_markdown(frame)
    assert list(tables.condition_summary(frame)["condition"].unique()) == ["same-session"]


def test_noisy_timing_cells_are_flagged():
    rows = [{"method": "raw", "scenario": "creep", "seed": k, "us_per_tick_p50": 2.0,
             "us_per_tick_p99": p99} for k, p99 in enumerate([5.0, 5.2, 4.9, 5.1])]
    rows += [{"method": "kalman-ripple", "scenario": "creep", "seed": k, "us_per_tick_p50": 50.0,
              "us_per_tick_p99": p99} for k, p99 in enumerate([80.0, 1500.0, 90.0, 6000.0])]
    cells = tables.timing_cells(_frame(rows)).set_index("method")
    assert not cells.loc["raw", "noisy"] and cells.loc["kalman-ripple", "noisy"]
    text = tables.timing_markdown(_frame(rows))
    assert "| raw " in text and "2 / 5.05" in text and "noisy" in text


def test_closing_table_of_run_fits_100_columns_with_the_longest_names():
    rows = [{"method": m, "scenario": s, "condition": "same-session", "seed": k,
             "rms_error_nm": 0.123 + 0.01 * k, "max_error_nm": 12.3 + k, "us_per_tick_p50": 123.0}
            for m in ("order-tracking-no-deadzone", "angle-adaptive-frozen") for s in ("static-contact", "paper-quintic")
            for k in range(3)]
    rows.append({**rows[0], "seed": 9, "status": "timeout", "message": "killed after 300 s " * 10})
    text = tables.summary_text(_frame(rows))
    assert max(len(line) for line in text.splitlines()) <= 100
    assert text.count("killed") == 10  # a failed row's message is wrapped, not cut
    assert "0.13 ± 0.025" in text and "Mean ± 95 % interval" in text  # means with intervals, as the report


def test_title_says_published_only_when_asked_and_recorded_logs_are_not_simulated():
    frame = _frame([{"method": "raw", "scenario": "paper-quintic", "seed": 0}])
    prov = {"run": {}, "report": {"command": "rippleb report"}, "seeds_text": "0 (1 seed)"}
    trial = report.readme_markdown(frame, prov, {}, run_dir="runs/a")
    assert trial.startswith("# rippleb report of `runs/a` (simulated devices)") and "do not edit" not in trial
    published = report.readme_markdown(frame, prov, {}, published=True)
    assert published.startswith("# rippleb: published comparison") and "do not edit by hand" in published
    recorded = report.readme_markdown(frame.assign(scenario="log:pq.csv"), prov, {})
    assert "(recorded log)" in recorded.splitlines()[0]
    assert "comes from the simulator" not in recorded and "comes from the recorded log" in recorded


def test_error_against_speed_is_averaged_over_devices_with_an_interval():
    one = {"speed": np.array([0.0, 1.0]), "raw": np.array([1.0, 2.0])}
    two = {"speed": np.array([0.0, 1.0]), "raw": np.array([3.0, 2.0])}
    table = figures.error_by_speed_over_seeds([one, two])
    mean, half = table["raw"]
    np.testing.assert_allclose(mean, [2.0, 2.0])
    assert half[0] == pytest.approx(12.706205 * np.std([1, 3], ddof=1) / np.sqrt(2)) and half[1] == 0.0
    assert table["n"] == 2


def test_residual_spectrum_shows_the_ripple_a_method_leaves_behind(tmp_path):
    spectra = figures.residual_spectra(_signals(), max_freq=50.0)
    raw_f, _ = spectra["raw"]
    peak = spectra["freq"][1:][np.argmax(raw_f[1:])]
    assert peak == pytest.approx(8.0, abs=0.5)  # the fake ripple is at 8 Hz
    tracked_f, _ = spectra["order-tracking"]
    assert tracked_f.max() < 0.2 * raw_f.max()  # a tenth of the ripple left
    assert len(spectra["order"]) > 0  # the fake move turns the motor many revolutions one way
    assert _is_png(figures.plot_residual_spectra(_signals(), tmp_path / "spectra.png"))


def test_figures_can_be_written_as_svg_and_pdf(tmp_path):
    svg = figures.plot_error_vs_speed([_signals()], tmp_path / "speed.svg")
    assert b"<svg" in svg.read_bytes()[:1000]
    pdf = figures.plot_ripple_compensation(_signals(), tmp_path / "fig5.pdf")
    assert pdf.read_bytes()[:5] == b"%PDF-"


def test_dashed_motion_lines_are_labelled_in_figs_5_and_6(tmp_path):
    import matplotlib.pyplot as plt

    figures.plot_ripple_compensation(_signals(), tmp_path / "fig5.png")
    seen = []
    original = plt.Figure.savefig

    def spy(fig, *args, **kwargs):
        seen.append([t.get_text() for ax in fig.axes if ax.get_legend() for t in ax.get_legend().get_texts()])
        return original(fig, *args, **kwargs)

    plt.Figure.savefig = spy
    try:
        figures.plot_ripple_compensation(_signals(), tmp_path / "fig5.png")
        figures.plot_estimates(_signals(), tmp_path / "fig6.png")
    finally:
        plt.Figure.savefig = original
    assert all(figures.MOTION_EDGE_LABEL in labels for labels in seen) and len(seen) == 2


def test_the_report_says_how_timing_was_taken():
    rows = [{"method": "raw", "scenario": "creep", "seed": k, "us_per_tick_p50": 2.0, "us_per_tick_p99": 5.0}
            for k in range(3)]
    note = tables.timing_note({"run": {"jobs": 2, "cpu_count": 2}}, _frame(rows))
    assert "2 rows ran in parallel (`--jobs 2`) on a machine with 2 CPUs; 0 cells are flagged" in note
    assert "`--jobs 1`" in note  # how to get quiet timings
    quiet = tables.timing_note({"run": {"jobs": 1, "cpu_count": 8}}, _frame(rows))
    assert "rows ran one at a time (`--jobs 1`) on a machine with 8 CPUs" in quiet
    assert "not recorded" in tables.timing_note({"run": {}}, _frame(rows))


def test_a_dirty_build_is_told_from_a_dev_version():
    from rippleb.report.provenance import built_dirty

    assert not built_dirty("0.1.1.dev79+gf4de4a038")
    assert built_dirty("0.1.1.dev79+gf4de4a038.d20261122")
    assert not built_dirty("0.1.0")

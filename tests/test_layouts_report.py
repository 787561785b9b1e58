"""The report's "Gauge layouts and hardware compensation" section: computed from the rows of a
gauges.layout sweep, paired per device, cheapest combination per target."""

import subprocess
import sys

import numpy as np
import pandas as pd
import pytest

from rippleb.engine.params import PARAMS
from rippleb.layouts import LAYOUT_NAMES
from rippleb.report.layouts_section import cheapest, combination_table, layouts_markdown


def frame(errors: dict) -> pd.DataFrame:
    """Rows of ``{(layout, method): [error per seed]}`` on two scenarios (the second one
    0.1 Nm worse), with a residual ripple of half the error and 5 us per tick."""
    rows = []
    for (name, method), values in errors.items():
        for seed, value in enumerate(values):
            for scenario, extra in (("paper-quintic", 0.0), ("stop-restart", 0.1)):
                rows.append(dict(method=method, scenario=scenario, condition="same-session", seed=seed,
                                 status="ok", rms_error_nm=value + extra, ripple_wg_nm=(value + extra) / 2,
                                 us_per_tick_p50=5.0, **{"gauges.layout": LAYOUT_NAMES.index(name)}))
    return pd.DataFrame(rows)


ERRORS = {("paper", "raw"): [1.0, 1.2, 1.1, 0.9], ("ring-5", "raw"): [0.45, 0.5, 0.48, 0.42],
          ("paper", "order-tracking"): [0.6, 0.7, 0.65, 0.55], ("ring-3", "raw"): [1.1, 1.1, 1.3, 1.0]}


def test_each_combination_is_paired_against_the_same_method_on_the_paper_layout():
    rows = {(r["layout"], r["method"]): r for r in combination_table(frame(ERRORS), "same-session")}
    ring = rows[("ring-5", "raw")]
    difference = np.subtract(ERRORS[("paper", "raw")], ERRORS[("ring-5", "raw")])
    assert ring["lead"].mean == pytest.approx(difference.mean()) and ring["lead"].wins == 4
    assert ring["mean"] == pytest.approx(np.mean(ERRORS[("ring-5", "raw")]) + 0.05)   # mean over scenarios
    assert ring["ripple"] == pytest.approx(ring["mean"] / 2)
    assert (ring["gauges"], ring["channels"]) == (10, 5)
    assert rows[("paper", "raw")]["lead"] is None
    assert rows[("paper", "order-tracking")]["lead"] is None       # no ring-5 row to pair it with


def test_the_cheapest_combination_under_a_target_has_its_whole_interval_below_it():
    rows = combination_table(frame(ERRORS), "same-session")
    assert cheapest(rows, 1.0)["layout"] == "paper" and cheapest(rows, 1.0)["method"] == "order-tracking"
    best = cheapest(rows, 0.7)       # order-tracking's interval reaches 0.78 Nm; ring-5's does not
    assert best["layout"] == "ring-5" and best["mean"] + best["half"] < 0.7
    assert cheapest(rows, 0.3) is None
    text = "\n".join(layouts_markdown(frame(ERRORS)))
    assert "| ring-5" in text and "no combination's 95 % interval lies below it" in text


def test_rows_without_a_layout_column_get_no_section():
    assert layouts_markdown(frame(ERRORS).drop(columns="gauges.layout")) == []


def test_a_layout_is_written_by_name_in_a_sweep_and_held_as_its_position():
    param = PARAMS["gauges.layout"]
    assert [param.parse(name) for name in LAYOUT_NAMES] == list(range(len(LAYOUT_NAMES)))
    assert param.name_of(3) == LAYOUT_NAMES[3] and param.parse("2") == 2
    with pytest.raises(Exception, match="one of paper"):
        param.parse("ring-4")


@pytest.mark.slow
@pytest.mark.heavy
def test_the_section_comes_from_the_cli_at_small_scale(tmp_path):
    """rippleb sweep over two layouts, then rippleb report: the section's numbers are the
    rows' (mean over the scenarios per device, then over devices)."""
    out = tmp_path / "run"
    cmd = [sys.executable, "-m", "rippleb", "sweep", "--param", "gauges.layout=paper,ring-3",
           "--methods", "raw,gain-tuned", "--scenarios", "stop-restart", "--seeds", "2", "--jobs", "1",
           "--no-progress", "--out", str(out)]
    subprocess.run(cmd, check=True, capture_output=True, timeout=900)
    subprocess.run([sys.executable, "-m", "rippleb", "report", str(out), "--out", str(tmp_path / "rep")],
                   check=True, capture_output=True, timeout=300)
    text = (tmp_path / "rep" / "README.md").read_text()
    assert "## Gauge layouts and hardware compensation" in text
    rows = pd.read_csv(out / "results.csv")
    ring = rows[(rows["gauges.layout"] == LAYOUT_NAMES.index("ring-3")) & (rows["method"] == "gain-tuned")]
    line = next(x for x in text.splitlines() if x.startswith("| ring-3") and "| gain-tuned " in x)
    assert f"{ring['rms_error_nm'].mean():.3g}" in line

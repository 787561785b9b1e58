"""The published comparison in results/ must be what the code produces today.

A few published rows, chosen to be quick (no slow fit), are re-run through the real runner
and their accuracy columns compared with ``results/results.csv`` exactly; timing columns
are left out because they depend on the machine. A stale table (code changed since the
run) or a hand-edited one fails here. If ``results/`` is missing the tests fail, not skip:
the table is a deliverable, regenerated with the commands in ``docs/report.md``.
"""

from pathlib import Path

import numpy as np
import pandas as pd
import pytest

import rippleb
from rippleb import report
from rippleb.simulator.conditions import CONDITIONS
from rippleb.registry import Registry
from rippleb.scenario import scored_scenarios

RESULTS = Path(__file__).resolve().parent.parent / "results"
PUBLISHED = RESULTS / "results.csv"
MIN_SEEDS = 20

#: (method, scenario, condition, seed): the paper's method, the new adaptive method and
#: two baselines, on the paper's trajectory and on restarts, two devices, three conditions.
SUBSET = [("order-tracking", "paper-quintic", "same-session", 0),
          ("angle-adaptive", "stop-restart", "power-cycled", 1),
          ("raw", "paper-quintic", "re-assembled", 0),
          ("lowpass", "stop-restart", "aged", 1)]


def _published() -> pd.DataFrame:
    if not PUBLISHED.is_file():
        pytest.fail(f"{PUBLISHED} is missing: regenerate the published comparison with the "
                    "commands in docs/report.md")
    return report.read_results_exact(PUBLISHED)


def _rerun(tmp_path) -> pd.DataFrame:
    fresh = []
    for i, (method, scenario, condition, seed) in enumerate(SUBSET):
        out = tmp_path / f"row{i}"
        rippleb.run([method], [scenario], [seed], conditions=[condition], jobs=1, out=out)
        # read back from the CSV the runner wrote, exactly as the published rows were
        fresh.append(report.read_results_exact(out / "results.csv"))
    return pd.concat(fresh, ignore_index=True)


# Not marked slow (about 10 s): this is the check that keeps results/ honest.
@pytest.mark.slow
def test_published_rows_are_reproduced_exactly(tmp_path):
    published = _published()
    problems = report.compare_rows(published, _rerun(tmp_path))
    assert not problems, ("results/ is stale or edited by hand; regenerate it (docs/report.md):\n"
                          + "\n".join(problems))


def test_a_tampered_copy_is_detected(tmp_path):
    published = _published()
    keys = published.set_index(["method", "scenario", "condition", "seed"]).index
    rows = published[keys.isin(SUBSET)]
    assert len(rows) == len(SUBSET), "the published table lacks rows of the checked subset"
    tampered = published.copy()
    i = rows.index[0]
    tampered.loc[i, "rms_error_nm"] = np.nextafter(tampered.loc[i, "rms_error_nm"], np.inf)
    path = tmp_path / "results.csv"
    tampered.to_csv(path, index=False)
    problems = report.compare_rows(report.read_results_exact(path), rows)
    assert len(problems) == 1 and "rms_error_nm" in problems[0]
    # and the untouched copy passes the same comparison
    published.to_csv(path, index=False)
    assert report.compare_rows(report.read_results_exact(path), rows) == []


def test_published_run_covers_every_builtin_method_scored_scenario_and_condition():
    published = _published()
    methods = Registry.discover().names("builtin")
    seeds = published.groupby(["method", "scenario", "condition"])["seed"].nunique()
    short = [f"{m} / {s} / {c}: {seeds.get((m, s, c), 0)} seeds"
             for m in methods for s in scored_scenarios() for c in CONDITIONS
             if seeds.get((m, s, c), 0) < MIN_SEEDS]
    assert not short, f"the published run needs at least {MIN_SEEDS} seeds of each:\n" + "\n".join(short)


def test_published_readme_tables_are_generated_from_the_published_rows():
    published = _published()
    readme = (RESULTS / "README.md").read_text()
    assert report.tables_markdown(published) in readme, \
        "results/README.md does not hold the tables of results/results.csv: edited by hand, or stale"

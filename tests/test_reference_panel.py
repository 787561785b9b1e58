"""The panel of joints behind a recorded log's trust sentence (benchmarks/reference_panel.py,
rippleb/report/agreement.py): docs/metrics.md holds the record's tables, and a small panel runs."""

import importlib.util
import subprocess
import sys
import types
from pathlib import Path

import pytest

from rippleb.report.agreement import DOCS_BEGIN, DOCS_END, SCORES, docs_block, read_record

ROOT = Path(__file__).resolve().parents[1]
SCRIPT = ROOT / "benchmarks" / "reference_panel.py"


def _script():
    spec = importlib.util.spec_from_file_location("reference_panel", SCRIPT)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_docs_metrics_holds_the_tables_of_the_shipped_record():
    record = read_record()
    assert record is not None, "rippleb/agreement.json is missing: run benchmarks/reference_panel.py --write"
    text = (ROOT / "docs" / "metrics.md").read_text()
    assert docs_block(record) in text, "docs/metrics.md's panel tables are not the record's: re-run --write"
    assert text.count(DOCS_BEGIN) == text.count(DOCS_END) == 1


def test_the_record_covers_the_panel():
    """Each joint it holds under every condition, both kinds, each kind's scores; ten devices
    a cell. The panel is nine joints; the shipped record holds the issue's joint (ratio 160,
    4096 counts) so far, and its command names that subset (docs/metrics.md)."""
    from rippleb.simulator.conditions import CONDITIONS

    record = read_record()
    joints = {(c["gear_ratio"], c["counts_per_rev"]) for c in record["cells"]}
    assert (160.0, 4096) in joints
    assert joints <= {(r, n) for r in (50.0, 100.0, 160.0) for n in (2500, 4096, 16384)}
    if len(joints) < 9:
        assert "--ratios" in record["protocol"]["command"] and "--counts" in record["protocol"]["command"]
    for joint in joints:
        assert {c["condition"] for c in record["cells"]
                if (c["gear_ratio"], c["counts_per_rev"]) == joint} == set(CONDITIONS)
    for kind, scores in SCORES.items():
        cells = [c for c in record["cells"] if c["reference_kind"] == kind]
        assert {c["score"] for c in cells} == set(scores)
    ranking = [c for c in record["cells"] if (c["reference_kind"], c["score"]) in
               (("model", "rms_error_rebuilt_nm"), ("transducer", "rms_error_ref_nm"))]
    assert len(ranking) == 2 * len(joints) * len(CONDITIONS) and min(c["devices"] for c in ranking) >= 10


@pytest.mark.slow
def test_a_small_panel_runs_and_writes_its_record_and_tables(tmp_path):
    """One joint, one condition, one device, four methods, through the script as the lead runs it."""
    out = tmp_path / "panel"
    done = subprocess.run([sys.executable, str(SCRIPT), "--seeds", "1", "--seed-start", "3000", "--ratios", "160",
                           "--counts", "4096", "--conditions", "same-session", "--methods",
                           "raw,order-tracking,fourier-lms,angle-adaptive-frozen", "--out", str(out)],
                          capture_output=True, text=True, timeout=3600)
    assert done.returncode == 0, done.stderr
    panel = _script()
    rows = panel._read(out / "panel.csv")
    assert len(rows) == 2 * 4 and {r["status"] for r in rows} == {"ok"}
    assert all(r["rms_error_rebuilt_nm"] > 0 for r in rows if r["reference_kind"] == "model")
    docs = tmp_path / "metrics.md"
    docs.write_text(f"head\n{DOCS_BEGIN}\nold\n{DOCS_END}\ntail\n")

    args = types.SimpleNamespace(scenario="paper-quintic", out=out)   # the script's options
    record = panel.write(rows, args, 60.0, record_path=tmp_path / "agreement.json", docs=docs)
    cells = {(c["reference_kind"], c["score"]): c for c in record["cells"]}
    assert cells[("model", "rms_error_rebuilt_nm")]["devices"] == 1
    assert -1.0 <= cells[("transducer", "rms_error_ref_nm")]["mean_rho"] <= 1.0
    assert docs.read_text() == f"head\n{docs_block(record)}\ntail\n"
    assert read_record((tmp_path / "agreement.json").read_text()) == record

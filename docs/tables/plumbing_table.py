"""The plumbing cases of docs/robustness.md section 9 (issue 25, item 2), through the real CLI.

    python docs/tables/plumbing_table.py                      # this checkout
    python docs/tables/plumbing_table.py --code /tmp/old      # another checkout (PYTHONPATH)

Runs the probing plugin of tests/test_plumbing.py (from tests/support/hostile.py) beside
``raw`` and prints what it reached; then edits a finished run (a row's cell, a forged row,
``run.json``'s seeds) and prints what ``report`` and ``--resume`` say. Each case in a fresh
temporary directory, with the key for row hashes in it (``RIPPLEB_KEY_FILE``).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "tests"))   # the support package
from support import install_dist as _dist  # noqa: E402
from support.hostile import PLUMBING_PROBER, csv_rows, write_csv_rows  # noqa: E402


def _cli(code: str | None, where: Path, site: Path, *args, env_extra=None):
    path = [str(site)] + ([code] if code else []) + [os.environ.get("PYTHONPATH", "")]
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(path), "TMPDIR": str(where),
           "RIPPLEB_KEY_FILE": str(where / "key"), **(env_extra or {})}
    return subprocess.run([sys.executable, "-m", "rippleb", *map(str, args)], capture_output=True, text=True,
                          env=env, cwd=where, timeout=600)


def _last(text: str) -> str:
    lines = [line for line in text.strip().splitlines() if line.startswith("rippleb:")]
    return lines[-1] if lines else (text.strip().splitlines() or [""])[-1]


def probe(code, site) -> list[str]:
    where = Path(tempfile.mkdtemp(prefix="rippleb-probe-"))
    run = where / "run"
    proc = _cli(code, where, site, "run", "--methods", "prober,raw", "--scenarios", "static-contact", "--seeds", "1",
                "--jobs", "2", "--no-progress", "--out", run,
                env_extra={"PROBE_OUT": str(where / "found"), "PROBE_RUN_DIR": str(run), "PROBE_RUNNER": "0"})
    found = json.loads(next(where.glob("found.*")).read_text())
    forged_seen = "12 rows (12 ok)" in proc.stdout + proc.stderr
    key = found.get("key_bytes")
    return [
        f"| processes the worker sees in /proc | {len(found['visible'])} |",
        f"| descriptors of other processes it opens for writing | {len(found['opened'])} "
        f"({sum(1 for o in found['opened'] if 'pipe:' in o[2])} pipes) |",
        f"| terminals (/dev/pts) it opens | {sum(v == 'opened' for v in found['terminals'].values())} of "
        f"{len(found['terminals'])} |",
        f"| files it creates in the run directory | {'; '.join(f'{k}: {v}' for k, v in found['run_dir'].items())} |",
        f"| files it creates in the cache | {', '.join(sorted(set(found['cache'].values()))) or 'no cache found'} |",
        f"| bytes of rippleb's key it reads | {key} |",
        f"| its forged summary line on rippleb's output | {'shown' if forged_seen else 'not shown (in its log)'} |",
        f"| exit, rows | {proc.returncode}, {_last(proc.stdout + proc.stderr)} |",
    ]


def edits(code, site) -> list[str]:
    out = []
    for case in ("an edited cell", "a forged row", "run.json's seeds changed"):
        where = Path(tempfile.mkdtemp(prefix="rippleb-edit-"))
        run = where / "run"
        _cli(code, where, site, "run", "--methods", "raw,lowpass", "--scenarios", "static-contact", "--seeds", "2",
             "--no-progress", "--out", run)
        rows = csv_rows(run / "results.csv")
        if case == "an edited cell":
            rows[0]["rms_error_nm"] = "0.001"
            write_csv_rows(run / "results.csv", rows)
        elif case == "a forged row":
            write_csv_rows(run / "results.csv", rows + [dict(rows[0], seed="9", rms_error_nm="0.001")])
        else:
            config = json.loads((run / "run.json").read_text())
            config["seeds"] = list(range(6))
            (run / "run.json").write_text(json.dumps(config))
        report = _cli(code, where, site, "report", run, "--out", "rep")
        reported = len(csv_rows(where / "rep" / "results.csv")) if (where / "rep" / "results.csv").is_file() else "-"
        resumed = _cli(code, where, site, "run", "--resume", run, "--no-progress")
        kept = csv_rows(run / "results.csv")
        out.append(f"| {case} | report {report.returncode}, {reported} rows; "
                   f"{_last(report.stderr) if 'warning' in report.stderr else 'no warning'} | "
                   f"resume {resumed.returncode}, {len(kept)} rows, "
                   f"{sum(r['rms_error_nm'] == '0.001' for r in kept)} holding 0.001; {_last(resumed.stderr)} |")
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--code", help="checkout whose rippleb to run (put first on PYTHONPATH)")
    args = parser.parse_args()
    site = Path(tempfile.mkdtemp(prefix="rippleb-prober-site-"))
    _dist(site, "rippleb-prober", "rippleb_prober", PLUMBING_PROBER, {"prober": "Prober"})
    print("\n".join(probe(args.code, site)))
    print("\n".join(edits(args.code, site)))


if __name__ == "__main__":
    main()

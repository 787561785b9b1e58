"""The containment cases of docs/robustness.md (issue 25, items 5 and 7), each through the real CLI.

    python docs/tables/containment_table.py                          # this checkout
    python docs/tables/containment_table.py --python OTHER/.venv/bin/python
                                                                     # another install (e.g. 05c5036)

Every case runs as ``OTHER -m rippleb ...`` subprocesses in a fresh temporary directory,
with the re-simulating plugin of tests/test_sealing.py (from tests/support/hostile.py) and
oddly named plugins on PYTHONPATH. Prints one Markdown row per case: exit code(s) and the
outcome (the last error or warning line, or what the rows say). The full-disk case mounts a
64 KiB tmpfs and needs root; elsewhere it says so.
"""

from __future__ import annotations

import argparse
import csv
import io
import json
import os
import re
import subprocess
import sys
import tempfile
from pathlib import Path

import rippleb  # noqa: F401 - before numpy: the portable numeric paths (rippleb/numerics.py)

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "tests"))   # the support package
from support import GOOD, PLUGIN, install_dist as _dist  # noqa: E402
from support.hostile import RESIMULATOR  # noqa: E402

RUN = ["run", "--seeds", "1", "--jobs", "2", "--no-progress"]


class Case:
    """A fresh directory and a way to call the CLI of the install under test there."""

    def __init__(self, python: str, site: Path):
        self.dir = Path(tempfile.mkdtemp(prefix="rippleb-case-"))
        self.python = python
        self.env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(site), os.environ.get("PYTHONPATH", "")]),
                    "TMPDIR": str(self.dir)}

    def cli(self, *args, timeout=600):
        try:
            proc = subprocess.run([self.python, "-m", "rippleb", *map(str, args)], capture_output=True,
                                  text=True, env=self.env, cwd=self.dir, timeout=timeout, start_new_session=True)
        except subprocess.TimeoutExpired:
            return None, f"still running after {timeout} s"
        return proc.returncode, proc.stderr

    def rows(self, out="out") -> list[dict]:
        path = self.dir / out / "results.csv"
        return list(csv.DictReader(io.StringIO(path.read_text()))) if path.is_file() else []

    def finished(self, methods="raw,lowpass", scenarios="static-contact"):
        code, err = self.cli(*RUN, "--methods", methods, "--scenarios", scenarios, "--out", "out")
        assert code == 0, err
        return self.dir / "out"


def last(stderr: str) -> str:
    """The line that says what happened: the error, else the warnings, else the last line."""
    lines = [line for line in stderr.splitlines() if line.strip()]
    errors = [line for line in lines if line.startswith("rippleb: error") or "Error" in line.split(":")[0]]
    warnings = [line for line in lines if line.startswith("rippleb: warning")]
    return " / ".join(errors[-1:] or warnings or lines[-1:])[:230]


def rms(rows, method) -> str:
    row = next((r for r in rows if r["method"] == method), None)
    return "no row" if row is None else f"{method}: {row['status']} {float(row['rms_error_nm']):.3f}"


# ----------------------------------------------------------------------------- item 5


def resimulate(sealed: bool):
    def case(c: Case):
        extra = ["--sealed", c.dir / "salt"] if sealed else []
        code, err = c.cli(*RUN, "--methods", "resimulator,raw", "--scenarios", "static-contact", "--out", "out",
                          *extra)
        rows = c.rows()
        return code, (f"{rms(rows, 'resimulator')}; {rms(rows, 'raw')}" if rows else last(err))
    return case


# ----------------------------------------------------------------------------- item 7: resume


def damaged_run_json(change):
    def case(c: Case):
        out = c.dir / "out"
        out.mkdir()
        config = {"methods": ["raw"], "conditions": ["same-session"], "seeds": [0], "scenarios": ["static-contact"]}
        change(config)
        (out / "run.json").write_text(json.dumps(config))
        code, err = c.cli("run", "--resume", "out", "--no-progress")
        return code, last(err)
    return case


def resume_with(*extra):
    def case(c: Case):
        out = c.finished()
        lines = (out / "results.csv").read_text().splitlines()
        (out / "results.csv").write_text("\n".join(lines[:-1]) + "\n")   # one row left to run
        code, err = c.cli("run", "--resume", "out", *extra, "--no-progress")
        if code:
            return code, last(err)
        return code, (f"{last(err) or 'no message'}; the missing row run into out/ "
                      f"({len(c.rows())} rows); {' '.join(map(str, extra))} ignored")
    return case


def other_version(c: Case):
    out = c.finished()
    _edit(out / "results.csv", {(2, "rippleb_version"): "0.0.1"})
    lines = (out / "results.csv").read_text().splitlines()
    (out / "results.csv").write_text("\n".join(lines[:-1]) + "\n")
    code, err = c.cli("run", "--resume", "out", "--no-progress")
    versions = sorted({r["rippleb_version"] for r in c.rows()})
    return code, f"{last(err) or 'no message'}; versions in results.csv: {', '.join(versions)}"


def _edit(path: Path, edits: dict) -> None:
    rows = list(csv.reader(io.StringIO(path.read_text())))
    for (line, column), text in edits.items():
        rows[line - 1][rows[0].index(column)] = text
    buffer = io.StringIO()
    csv.writer(buffer, lineterminator="\n").writerows(rows)
    path.write_text(buffer.getvalue())


# ----------------------------------------------------------------------------- item 7: report


def report_case(prepare, *extra):
    def case(c: Case):
        out = c.finished()
        target = prepare(c, out)
        code, err = c.cli("report", "out", *(extra or ("--no-figures",)), *(["--out", target] if target else []))
        return code, last(err) if err.strip() else "no warning"
    return case


def run_json_list(c, out):
    (out / "run.json").write_text("[1, 2]\n")


def negative_rms(c, out):
    _edit(out / "results.csv", {(2, "rms_error_nm"): "-0.5"})


def full_disk(c, out):
    tiny = c.dir / "tiny"
    tiny.mkdir()
    if os.geteuid() != 0 or subprocess.run(["mount", "-t", "tmpfs", "-o", "size=64k", "tmpfs", str(tiny)]).returncode:
        raise RuntimeError("needs root to mount a tmpfs")
    return tiny / "report"


def bar_in_name(c: Case):
    (c.dir / "a|b.toml").write_text(GOOD)
    out = c.finished(scenarios="a|b.toml")
    c.cli("report", "out", "--no-figures")
    broken = 0
    table = []
    for line in (out / "report" / "README.md").read_text().splitlines() + [""]:
        if line.startswith("|"):
            table.append(len(re.split(r"(?<!\\)\|", line)))
        elif table:
            broken += sum(n != table[0] for n in table)
            table = []
    return 0, f"{broken} table row(s) with more cells than their header"


# ----------------------------------------------------------------------------- item 7: options, plugins


def command(*args, timeout=600):
    def case(c: Case):
        code, err = c.cli(*args, timeout=timeout)
        rows = len(c.rows())
        return code, f"{last(err) or 'no message'}; {rows} rows" if (c.dir / "out").exists() else last(err)
    return case


def plugin_named(name: str):
    def case(c: Case):
        site = c.dir / "site"
        _dist(site, "rippleb-oddname", "odd_mod", PLUGIN, {name: "Plugin"})
        c.env["PYTHONPATH"] = os.pathsep.join([str(site), c.env["PYTHONPATH"]])
        code, err = c.cli("list", "--import-timeout", "60")
        return code, last(err) if code else f"listed as {name!r}"
    return case


CASES = [
    ("re-simulating plugin, unsealed run", resimulate(False)),
    ("re-simulating plugin, --sealed", resimulate(True)),
    ("run.json without seeds", damaged_run_json(lambda c: c.pop("seeds"))),
    ("run.json without scenarios", damaged_run_json(lambda c: c.pop("scenarios"))),
    ("run.json with seeds [\"0\"]", damaged_run_json(lambda c: c.update(seeds=["0"]))),
    ("run.json with seeds \"abc\"", damaged_run_json(lambda c: c.update(seeds="abc"))),
    ("--resume with --out", resume_with("--out", "elsewhere")),
    ("--resume with --calibration", resume_with("--calibration", "cal.csv")),
    ("--resume onto rows of another version", other_version),
    ("report: run.json is a list", report_case(run_json_list)),
    ("report: disk full (64 KiB tmpfs)", report_case(full_disk, "--format", "png")),
    ("report: scenario a|b.toml", bar_in_name),
    ("report: negative rms_error_nm", report_case(negative_rms)),
    ("sweep --param joint.fs=,,", command("sweep", "--param", "joint.fs=,,", "--methods", "raw", "--scenarios",
                                          "static-contact", "--seeds", "1", "--no-progress", "--out", "out")),
    ("run --seeds 100000", command("run", "--methods", "raw", "--scenarios", "static-contact", "--seeds", "100000",
                                   "--no-progress", "--out", "out", timeout=60)),
    ("plugin named all", plugin_named("all")),
    ("plugin named a,b", plugin_named("a,b")),
]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--python", default=sys.executable, help="the interpreter of the install to test")
    parser.add_argument("-k", help="only cases whose title contains one of these comma-separated words")
    args = parser.parse_args()
    site = Path(tempfile.mkdtemp(prefix="rippleb-site-"))
    _dist(site, "rippleb-resimulator", "rippleb_resimulator", RESIMULATOR, {"resimulator": "Resimulator"})
    print("| case | exit | outcome |\n|---|---|---|")
    for title, fn in CASES:
        if args.k and not any(word in title for word in args.k.split(",")):
            continue
        c = Case(args.python, site)
        try:
            code, outcome = fn(c)
        except Exception as exc:  # noqa: BLE001 - a case that breaks the harness is a row too
            code, outcome = "?", f"harness: {type(exc).__name__}: {exc}"[:150]
        finally:
            subprocess.run(["umount", str(c.dir / "tiny")], capture_output=True)
        print(f"| {title} | {code} | {str(outcome).replace('|', '/')} |", flush=True)


if __name__ == "__main__":
    main()

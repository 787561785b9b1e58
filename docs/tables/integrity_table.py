"""The integrity cases of docs/robustness.md, each through the real CLI, as a Markdown table.

    python docs/tables/integrity_table.py                # this checkout
    python docs/tables/integrity_table.py --root DIR     # another copy of rippleb (e.g. an older commit),
                                                         # put first on PYTHONPATH

Every case runs in a fresh temporary directory; plugins come from a site directory of
``.dist-info`` distributions put on PYTHONPATH (the hostile package of
tests/test_integrity.py, from tests/support/hostile.py). Prints one row per case: exit code(s) and the outcome.
"""

from __future__ import annotations

import argparse
import os
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import rippleb  # noqa: F401 - before numpy: the portable numeric paths (rippleb/numerics.py)

import numpy as np
import pandas as pd

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "tests"))   # the support package
from support import NAPPER, install_dist as _dist, nap, napping, write_move_scenario  # noqa: E402
from support.hostile import INTEGRITY_HOSTILE, SLOW_IMPORT  # noqa: E402

RUN = ["run", "--seeds", "1", "--jobs", "2", "--no-progress"]


class Case:
    def __init__(self, root: Path | None, site: Path):
        self.dir, self.site = Path(tempfile.mkdtemp(prefix="rippleb-case-")), site
        paths = [str(site)] + ([str(root)] if root else []) + [os.environ.get("PYTHONPATH", "")]
        self.env = {**os.environ, "PYTHONPATH": os.pathsep.join(paths), "TMPDIR": str(self.dir),
                    "HOSTILE_PIDS": str(self.dir / "pids")}

    def scenario(self, name, by=0.1, duration=0.2, posture="1.5"):
        write_move_scenario(self.dir / name, by, duration, posture)

    def cli(self, *args, timeout=300):
        try:
            # Its own session: a hostile plugin of an unprotected rippleb must not end this script.
            proc = subprocess.run([sys.executable, "-m", "rippleb", *map(str, args)], capture_output=True,
                                  text=True, env=self.env, cwd=self.dir, timeout=timeout,
                                  start_new_session=True)
        except subprocess.TimeoutExpired:
            return None, f"still running after {timeout} s"
        return proc.returncode, _last_line(proc.stderr)

    def rows(self, out="out"):
        path = self.dir / out / "results.csv"
        return pd.read_csv(path, keep_default_na=False) if path.is_file() else None


def _last_line(text: str) -> str:
    lines = [line for line in text.splitlines() if line.strip()]
    errors = [line for line in lines if line.startswith("rippleb: error")]
    return (errors or lines or [""])[-1][:150]


def _short(rows, columns=("method", "scenario", "status", "rms_error_nm")):
    if rows is None:
        return "no results.csv"
    parts = []
    for _, r in rows.iterrows():
        value = r.get("rms_error_nm", "")
        number = f" {float(value):.3f}" if value not in ("", None) else ""
        parts.append(f"{r['method']}/{r['scenario']}: {r['status']}{number}")
    return "; ".join(parts)


def _spawned() -> int:
    count = 0
    for entry in os.listdir("/proc"):
        try:
            cmd = Path(f"/proc/{entry}/cmdline").read_bytes()
        except OSError:
            continue
        count += cmd in (b"sleep\0987\0", b"sleep\0988\0")
    return count


def _kill_spawned() -> None:
    for entry in os.listdir("/proc"):
        try:
            if Path(f"/proc/{entry}/cmdline").read_bytes() in (b"sleep\0987\0", b"sleep\0988\0"):
                os.kill(int(entry), signal.SIGKILL)
        except OSError:
            pass


def _recording(path: Path, n=40_000, fs=20_000.0, t_scale=1.0):
    t = np.arange(n) / fs
    torque = 10 * np.sin(2 * np.pi * 2 * t)
    pd.DataFrame({"t": t * t_scale, "strain": 0.01 * torque, "encoder": np.arange(n) // 2,
                  "current": torque / 7, "torque_ref": torque}).to_csv(path, index=False)


# ----------------------------------------------------------------------------- the cases


def _two_files(c, first: str, second: str):
    """Two scenario files whose names a careless key would mix, run together: their rows."""
    c.scenario(first, by=0.1)
    c.scenario(second, by=0.05)
    code, err = c.cli(*RUN, "--methods", "raw", "--scenarios", f"{first},{second}", "--out", "out")
    return code, err if code else _short(c.rows())


def rows_mixed_space_underscore(c):
    return _two_files(c, "a b.toml", "a_b.toml")


def rows_mixed_emoji(c):
    return _two_files(c, "\N{SLIGHTLY SMILING FACE}.toml", "\N{UPSIDE-DOWN FACE}.toml")


def rows_mixed_same_stem(c):
    return _two_files(c, "d1/x.toml", "d2/x.toml")


def rows_mixed_builtin_shadow(c):
    c.scenario("creep.toml", by=0.1)
    code, err = c.cli(*RUN, "--methods", "raw", "--scenarios", "creep,./creep.toml", "--out", "out")
    return code, err if code else _short(c.rows())


def rows_mixed_calibration_file(c):
    c.scenario("calibration.toml", by=0.1)
    code, err = c.cli(*RUN, "--methods", "raw", "--scenarios", "calibration.toml", "--out", "out")
    return code, err if code else _short(c.rows())


def rows_lost_second_run(c):
    c.cli(*RUN, "--methods", "raw", "--scenarios", "static-contact", "--out", "out")
    before = (c.dir / "out" / "results.csv").read_bytes()
    code, err = c.cli(*RUN, "--methods", "lowpass", "--scenarios", "static-contact", "--out", "out")
    kept = (c.dir / "out" / "results.csv").read_bytes() == before
    return code, f"{err or 'exit 0'}; first run's results.csv {'kept' if kept else 'REPLACED'}"


def rows_lost_concurrent(c):
    args = [sys.executable, "-m", "rippleb", *RUN, "--methods", "raw,lowpass", "--scenarios",
            "static-contact,creep", "--out", "out"]
    procs = [subprocess.Popen(args, env=c.env, cwd=c.dir, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                              text=True, start_new_session=True) for _ in range(2)]
    outs = [p.communicate(timeout=600) for p in procs]
    codes = [p.returncode for p in procs]
    rows = c.rows()
    n = 0 if rows is None else len(rows)
    return codes, f"{n} rows in results.csv; {'; '.join(_last_line(e) for _, e in outs if _last_line(e))[:150]}"


def forged_cache(c):
    code, err = c.cli(*RUN[:-3], "--jobs", "1", "--no-progress", "--methods", "forger,lowpass,raw",
                      "--scenarios", "static-contact", "--out", "out")
    return code, err if code else _short(c.rows())


def peeked_truth(c):
    code, err = c.cli(*RUN, "--methods", "peeker", "--scenarios", "static-contact", "--out", "out")
    return code, err if code else _short(c.rows())


def escaped_processes(c):
    _kill_spawned()
    code, err = c.cli(*RUN, "--methods", "spawner", "--scenarios", "static-contact", "--out", "out")
    time.sleep(0.5)
    left = _spawned()
    _kill_spawned()
    return code, f"{_short(c.rows())}; {left} process(es) left running"


def signals_runner(c):
    code, err = c.cli(*RUN, "--methods", "killer,raw", "--scenarios", "static-contact", "--out", "out")
    return code, f"{err}; {_short(c.rows())}" if code else _short(c.rows())


def slow_import_list(c):
    start = time.monotonic()
    code, err = c.cli("list", timeout=60)
    return code, err if code is None else f"listed in {time.monotonic() - start:.0f} s"


def slow_import_run(c):
    start = time.monotonic()
    code, err = c.cli(*RUN, "--methods", "slow-import,raw", "--scenarios", "static-contact", "--timeout", "15",
                      "--out", "out", timeout=120)
    return code, f"{_short(c.rows())}; {time.monotonic() - start:.0f} s"


def resume_truncated(c):
    c.cli(*RUN, "--methods", "raw,lowpass", "--scenarios", "static-contact", "--out", "out")
    path = c.dir / "out" / "results.csv"
    lines = path.read_text().splitlines()
    lines[-1] = lines[-1][:60]            # a row cut inside its metrics, as by a crash mid-write
    path.write_text("\n".join(lines) + "\n")
    code, err = c.cli("run", "--resume", "out", "--no-progress")
    return code, f"{err + '; ' if err else ''}{_short(c.rows())}"


def resume_na_name(c):
    c.scenario("NA.toml")
    c.cli(*RUN, "--methods", "raw", "--scenarios", "NA.toml", "--out", "out")
    code, err = c.cli("run", "--resume", "out", "--no-progress")
    return code, f"{err + '; ' if err else ''}{_short(c.rows())}"


def resume_other_seeds(c):
    c.cli(*RUN, "--methods", "raw", "--scenarios", "static-contact", "--out", "out")
    code, err = c.cli("run", "--resume", "out", "--seeds", "1", "--seed-start", "5", "--no-progress")
    rows = c.rows()
    return code, f"{err + '; ' if err else ''}seeds in results.csv: {sorted(set(rows.seed))}"


def resume_environmental(c):
    c.cli(*RUN, "--methods", "raw", "--scenarios", "static-contact", "--out", "out")
    path = c.dir / "out" / "results.csv"
    frame = pd.read_csv(path, keep_default_na=False)
    frame["status"], frame["message"] = "error", "environment: process killed by SIGKILL (out of memory?)"
    frame.to_csv(path, index=False)
    code, err = c.cli("run", "--resume", "out", "--no-progress")
    return code, f"{err + '; ' if err else ''}{_short(c.rows())}"


def interrupted_early(c):
    args = [sys.executable, "-m", "rippleb", *RUN, "--methods", "napper,raw", "--scenarios", "static-contact",
            "--out", "out"]
    with nap(c.site):
        proc = subprocess.Popen(args, env=c.env, cwd=c.dir, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                text=True, start_new_session=True)
        deadline = time.monotonic() + 120
        while not napping(Path(c.dir) / "out") and time.monotonic() < deadline:
            time.sleep(0.05)
        proc.send_signal(signal.SIGTERM)
        _, err = proc.communicate(timeout=60)
    code, resumed = c.cli("run", "--resume", "out", "--no-progress")
    return [proc.returncode, code], f"{_last_line(err)} / resume: {resumed or _short(c.rows())}"


def option(*args):
    def case(c):
        code, err = c.cli(*RUN, "--scenarios", "static-contact", "--out", "out", *args)
        return code, err if code else _short(c.rows())
    return case


def recording(t_scale=1.0, fs=20_000.0, cal=None):
    def case(c):
        _recording(c.dir / "rec.csv", fs=fs, t_scale=t_scale)
        extra = []
        if cal is not None:
            _recording(c.dir / "cal.csv", **cal)
            extra = ["--calibration", "cal.csv"]
        code, err = c.cli("run", "--log", "rec.csv", *extra, "--methods", "raw", "--no-progress", "--out", "out")
        return code, err if code else _short(c.rows())
    return case


def trajectory(**kwargs):
    def case(c):
        c.scenario("bad.toml", **kwargs)
        code, err = c.cli(*RUN, "--methods", "raw", "--scenarios", "bad.toml", "--out", "out")
        return code, err if code else _short(c.rows())
    return case


def report_case(change):
    def case(c):
        c.cli(*RUN, "--methods", "raw", "--scenarios", "static-contact", "--seeds", "2", "--out", "out")
        path = c.dir / "out" / "results.csv"
        frame = change(pd.read_csv(path, keep_default_na=False))
        frame.to_csv(path, index=False)
        code, err = c.cli("report", "out", "--no-figures", "--out", "rep")
        readme = c.dir / "rep" / "README.md"
        text = readme.read_text() if readme.is_file() else ""
        seeds = [w for w in ("(1 seed)", "(2 seeds)", "(3 seeds)") if w in text]
        return code, f"{err}{'; README counts ' + ' and '.join(seeds) if seeds else ''}"
    return case


def _duplicate(frame):
    return pd.concat([frame, frame.iloc[[0]]])


def _text_cell(frame):
    frame = frame.astype({"rms_error_nm": object})
    frame.loc[0, "rms_error_nm"] = "oops"
    return frame


CASES = [
    ("rows mixed: 'a b.toml,a_b.toml'", rows_mixed_space_underscore),
    ("rows mixed: two emoji names", rows_mixed_emoji),
    ("rows mixed: d1/x.toml,d2/x.toml", rows_mixed_same_stem),
    ("rows mixed: creep,./creep.toml", rows_mixed_builtin_shadow),
    ("rows mixed: user calibration.toml", rows_mixed_calibration_file),
    ("rows lost: second run into one --out", rows_lost_second_run),
    ("rows lost: two runs at once into one --out", rows_lost_concurrent),
    ("rows forged: plugin rewrites the cache", forged_cache),
    ("rows forged: plugin reads truth from the cache", peeked_truth),
    ("escape: plugin leaves processes", escaped_processes),
    ("escape: plugin signals group, parent, ancestors", signals_runner),
    ("escape: plugin sleeps at import: list", slow_import_list),
    ("escape: plugin sleeps at import: run", slow_import_run),
    ("resume: truncated last row", resume_truncated),
    ("resume: scenario named NA", resume_na_name),
    ("resume: --seeds 1 --seed-start 5", resume_other_seeds),
    ("resume: row failed for the environment", resume_environmental),
    ("interrupt before the first row, then resume", interrupted_early),
    ("option --timeout -1", option("--methods", "raw", "--timeout", "-1")),
    ("option --timeout nan", option("--methods", "raw", "--timeout", "nan")),
    ("option --memory-limit -1", option("--methods", "raw", "--memory-limit", "-1")),
    ("option --jobs 0", option("--methods", "raw", "--jobs", "0")),
    ("option --methods ''", option("--methods", "")),
    ("option --conditions sunny", option("--methods", "raw", "--conditions", "sunny")),
    ("log t in microseconds", recording(t_scale=1e6)),
    ("log at 1 Hz", recording(fs=1.0)),
    ("log at 1 GHz", recording(fs=1e9)),
    ("calibration of two samples", recording(cal={"n": 2})),
    ("calibration at another rate", recording(cal={"fs": 10_000.0})),
    ("trajectory asks ~2800 rad/s", trajectory(by=3.0, duration=0.002)),
    ("posture NaN", trajectory(posture="nan")),
    ("report: duplicated row", report_case(_duplicate)),
    ("report: metric column missing", report_case(lambda f: f.drop(columns=["rms_error_nm"]))),
    ("report: text in a numeric cell", report_case(_text_cell)),
]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--root", type=Path, help="a rippleb source tree to test instead of this one")
    parser.add_argument("-k", help="only cases whose title contains one of these comma-separated words")
    args = parser.parse_args()
    site = Path(tempfile.mkdtemp(prefix="rippleb-site-"))
    _dist(site, "rippleb-hostile", "rippleb_hostile", INTEGRITY_HOSTILE,
          {"forger": "Forger", "peeker": "Peeker", "spawner": "Spawner", "killer": "Killer"})
    _dist(site, "rippleb-slow", "rippleb_slow", SLOW_IMPORT, {"slow-import": "Anything"})
    _dist(site, "rippleb-napper", "rippleb_napper", NAPPER, {"napper": "Napper"})
    print("| case | exit | outcome |\n|---|---|---|")
    for title, fn in CASES:
        if args.k and not any(word in title for word in args.k.split(",")):
            continue
        try:
            code, outcome = fn(Case(args.root, site))
        except Exception as exc:  # noqa: BLE001 - a case that breaks the harness is a row too
            code, outcome = "?", f"harness: {type(exc).__name__}: {exc}"[:150]
        print(f"| {title} | {code} | {str(outcome).replace('|', '/')} |", flush=True)


if __name__ == "__main__":
    main()

"""The outcome of each attack of issue 41 on the walls, as docs/robustness.md section 11 shows it.

    python docs/tables/walls_table.py [--only NAME,...]

Every case runs the real CLI in a fresh directory, with the hostile methods of
``tests/support/walls.py`` (the plugin ``tests/test_walls.py`` installs, as a distribution
on ``PYTHONPATH``) and a secret exported to the runner; it prints one Markdown row per case:
the command, its exit status and what happened (what the prober reached, the rows'
statuses, raw's error beside it). The tests of ``tests/test_walls.py`` assert the same outcomes.
"""

from __future__ import annotations

import argparse
import json
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "tests"))   # the support package

import rippleb  # noqa: E402,F401 - before numpy: the portable numeric paths

from support import install_dist as _dist  # noqa: E402
from support.walls import (WALLS_METHODS, WALLS_PROBER, Listener, probe_of, rows_by_method,  # noqa: E402
                           walls_cli, walls_label)

RUN = ("--scenarios", "static-contact", "--seeds", "1", "--no-progress")


def _reached(found: dict) -> str:
    """What the prober's findings say, in a few words."""
    read = {k: v for k, v in found["read"].items() if v is not None and k not in ("own_package", "numpy")}
    opened = sorted(k for k, v in read.items() if v > 0)
    text = [f"reads: {'read ' + ', '.join(opened) if opened else 'every one refused'} "
            f"({', '.join(f'{k} {v}' for k, v in read.items())}); its package and numpy readable: "
            f"{found['read']['own_package'] > 0 and found['read']['numpy'] > 0}",
            f"secret in environ / /proc/self/environ / memory: {found['environ_secret']} / "
            f"{found['proc_environ_secret']} / {found['memory_secret']}",
            f"TCP to 127.0.0.1: errno {found['tcp']}" if found["tcp"] is not None else "",
            f"Dask: {found['dask']}" if found["dask"] else "",
            f"forks before refused: {found['forks']} of 300",
            f"write rippleb/report/tables.py: errno {found['write_package']}"]
    return "; ".join(t for t in text if t)


def _rows_text(run: Path, skip=("prober",)) -> str:
    rows = rows_by_method(run)
    return ", ".join(f"{m} {r['status']}" + (f" {float(r['rms_error_nm']):.3f}" if r["status"] == "ok" else "")
                     for m, r in sorted(rows.items()) if m not in skip)


def case_local(where: Path, site: Path, executor: str = "local") -> tuple[str, int, str]:
    listener = Listener()
    try:
        method = walls_label(run_dir=str(where / "run"), home_file=str(Path.home() / ".bashrc"), port=listener.port)
        args = ("run", "--methods", f"raw,{method}", *RUN, "--jobs", "2", "--executor", executor, "--out", "run")
        proc = walls_cli(where, site, *args)
    finally:
        listener.close()
    return (f"`rippleb run --methods raw,prober[...] ... --executor {executor}`", proc.returncode,
            f"{_reached(probe_of(where / 'run'))}; the listener received {len(listener.received)} connection(s); "
            f"rows: {_rows_text(where / 'run')}")


def case_scheduler(where: Path, site: Path) -> tuple[str, int, str]:
    import os

    from support import Cluster

    os.environ["PYTHONPATH"] = os.pathsep.join([str(site), os.environ.get("PYTHONPATH", "")])
    cluster = Cluster(where, n=2)
    try:
        cluster.wait_for_workers(2)
        method = walls_label(run_dir=str(where / "run"), scheduler=cluster.address)
        proc = walls_cli(where, site, "run", "--methods", f"raw,{method}", *RUN, "--scheduler", cluster.address,
                         "--out", "run")
    finally:
        cluster.close()
    report = walls_cli(where, site, "report", "run", "--out", "rep")
    return ("`rippleb run --methods raw,prober[scheduler=ADDR,...] --scheduler ADDR` (a `dask scheduler` and two "
            "`dask worker` started by hand)", proc.returncode,
            f"{_reached(probe_of(where / 'run'))}; rows: {_rows_text(where / 'run')}; `rippleb report run`: exit "
            f"{report.returncode}, {'no row ignored' if 'ignored' not in report.stderr else report.stderr.strip()}")


def case_log(where: Path, site: Path) -> tuple[str, int, str]:
    from rippleb.log_files import write_log
    from rippleb.simulator import simulate

    write_log(simulate("static-contact", 0).log, where / "rec.csv")
    write_log(simulate("calibration", 0).log, where / "cal.csv")
    method = walls_label(log=str(where / "rec.csv"), run_dir=str(where / "run"))
    proc = walls_cli(where, site, "run", "--log", "rec.csv", "--calibration", "cal.csv", "--methods", f"raw,{method}",
                     "--no-progress", "--out", "run")
    found = probe_of(where / "run")
    return ("`rippleb run --log rec.csv --calibration cal.csv --methods raw,prober[log=rec.csv,...]`",
            proc.returncode, f"the log: {found['read']['log']} (-EACCES); {_reached(found)}; "
                             f"rows: {_rows_text(where / 'run')}")


def case_salt(where: Path, site: Path, given: str) -> tuple[str, int, str]:
    first = walls_cli(where, site, "run", "--methods", "raw", *RUN, "--sealed", "salt", "--out", "run")
    assert first.returncode == 0, first.stderr
    shutil.copy(where / "salt", where / "salt-copy")
    method = walls_label(run_dir=str(where / "run"), salt=str(where / "salt"), salt_copy=str(where / "salt-copy"))
    proc = walls_cli(where, site, "run", "--resume", "run", "--methods", f"raw,{method}", "--salt-file",
                     "salt" if given == "file" else "-", "--no-progress",
                     stdin=(where / "salt").read_text() if given == "stdin" else None)
    found = probe_of(where / "run")
    return (f"`rippleb run --sealed salt`, then `rippleb run --resume run --methods raw,prober[salt=...,salt_copy=...] "
            f"--salt-file {'salt' if given == 'file' else '- < salt'}`", proc.returncode,
            f"the salt file: {found['read']['salt']}, its copy: {found['read']['salt_copy']}; {_reached(found)}; "
            f"rows: {_rows_text(where / 'run')}")


def case_check(where: Path, site: Path, name: str) -> tuple[str, int, str]:
    start = time.monotonic()
    proc = walls_cli(where, site, "check", name, "--timeout", "20")
    failed = [line.strip() for line in proc.stdout.splitlines() if line.startswith("  FAIL")]
    return (f"`rippleb check {name} --timeout 20`", proc.returncode,
            f"{'; '.join(failed)}; `{proc.stdout.strip().splitlines()[-1]}`; {time.monotonic() - start:.0f} s")


def case_tune(where: Path, site: Path) -> tuple[str, int, str]:
    script = (f"import sys, json; sys.path.insert(0, {str(site)!r})\n"
              "import rippleb\n"
              "from rippleb.registry import Registry\n"
              "from rippleb.engine.tuner import plan, tune\n"
              "registry = Registry.discover()\n"
              "entry = tune(plan(['wobbly'], registry, 4), [100], jobs=2, timeout=20, registry=registry)['wobbly']\n"
              "print(json.dumps([[p['params']['x'], p['scores'][0]] for p in entry['points']] + [entry['errors']]))\n")
    import os

    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(site), os.environ.get("PYTHONPATH", "")])}
    proc = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, env=env, cwd=where,
                          timeout=1200)
    *points, errors = json.loads(proc.stdout.strip().splitlines()[-1])
    return ("`tune(plan(['wobbly'], registry, 4), [100], timeout=20)` (a point hangs above x = 0.8, exits below 0.2)",
            proc.returncode, "points (x, score): " + ", ".join(f"({x:g}, {s:.3f})" for x, s in points)
            + f"; errors: {errors}")


def case_tune_peek(where: Path, site: Path) -> tuple[str, int, str]:
    """A tuning point that looks for the simulations it is tuned on, through the CLI."""
    import os

    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(site), os.environ.get("PYTHONPATH", "")]),
           "RIPPLEB_KEY_FILE": str(where / "key")}
    env.pop("TMPDIR", None)                     # the runner's cache in /tmp, where the peeker looks
    proc = subprocess.run([sys.executable, "-m", "rippleb", "tune", "--methods", "peeker", "--budget", "2",
                           "--seeds", "100", "--jobs", "2", "--no-progress", "--out", "t.json"],
                          capture_output=True, text=True, env=env, cwd=where, timeout=1200)
    errors = json.loads((where / "t.json").read_text())["methods"]["peeker"]["errors"]
    return ("`rippleb tune --methods peeker --budget 2 --seeds 100` (its fit lists `/tmp` for the runner's "
            "`rippleb-cache-*` and reads every file in them)", proc.returncode, f"errors: {errors}")


def case_forgers(where: Path, site: Path) -> tuple[str, int, str]:
    proc = walls_cli(where, site, "run", "--methods", "raw,clockstopper,framer,huge", *RUN, "--jobs", "2", "--out", "run")
    rows = rows_by_method(where / "run")
    text = "; ".join(f"{m}: {r['status']} ({r['message'][:110]})" for m, r in sorted(rows.items()) if m != "raw")
    return ("`rippleb run --methods raw,clockstopper,framer,huge ...`", proc.returncode,
            f"{text}; clockstopper's fit_s {float(rows['clockstopper']['fit_s']):.2f} s (it slept 2 s, its clock "
            f"turned back); raw ok {float(rows['raw']['rms_error_nm']):.3f}")


def case_fat(where: Path, site: Path, limit: str) -> tuple[str, int, str]:
    import os

    script = (f"import resource, sys; sys.path.insert(0, {str(site)!r})\n"
              "import rippleb\n"
              f"frame = rippleb.run(['raw', 'fat[mb=600]'], ['static-contact'], [0], memory_mb={limit})\n"
              "print(dict(zip(frame.method, frame.status)), dict(zip(frame.method, frame.message.str[:90])), "
              "resource.getrusage(resource.RUSAGE_SELF).ru_maxrss // 1024)\n")
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(site), os.environ.get("PYTHONPATH", "")])}
    proc = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, env=env, cwd=where,
                          timeout=1200)
    return (f"`rippleb.run(['raw', 'fat[mb=600]'], ..., memory_mb={limit})` (600 MB of fitted state)", proc.returncode,
            f"{proc.stdout.strip()} (statuses, messages, the runner's peak RSS in MB)")


def _nobodys(where: Path, site: Path) -> Path:
    """``where`` and a copy of the plugin's ``site`` in it, given to uid 65534 (the original
    is the runner's temporary directory, which only root may read)."""
    import os

    shutil.copytree(site, where / "site")
    for path in [where, *where.rglob("*")]:
        os.chown(path, 65534, 65534)
    return where / "site"


def case_nobody(where: Path, site: Path) -> tuple[str, int, str]:
    """The prober run by uid 65534, whose home (``/nonexistent``) cannot be written."""
    site = _nobodys(where, site)
    listener = Listener()
    try:
        method = walls_label(run_dir=str(where / "run"), port=listener.port)
        proc = walls_cli(where, site, "run", "--methods", f"raw,{method}", *RUN, "--jobs", "2", "--out", "run",
                         user=65534, env={"HOME": "/nonexistent", "TMPDIR": str(where)})
    finally:
        listener.close()
    warned = [line for line in proc.stderr.splitlines() if "warning" in line]
    return ("`setpriv --reuid=65534 ... rippleb run --methods raw,prober[...]` (`HOME=/nonexistent`)", proc.returncode,
            f"{_reached(probe_of(where / 'run'))}; the listener received {len(listener.received)} connection(s); "
            f"warnings: {len(warned)}; rows: {_rows_text(where / 'run')}")


def case_no_key(where: Path, site: Path) -> tuple[str, int, str]:
    """uid 65534 with no writable home and no ``RIPPLEB_KEY_FILE``: a run, then its resume."""
    site = _nobodys(where, site)
    env = {"HOME": "/nonexistent", "TMPDIR": str(where), "RIPPLEB_KEY_FILE": ""}
    first = walls_cli(where, site, "run", "--methods", "raw", *RUN, "--out", "run", user=65534, env=env)
    resumed = walls_cli(where, site, "run", "--resume", "run", "--no-progress", user=65534, env=env)
    said = [line for line in first.stderr.splitlines() if line.startswith("rippleb: warning")]
    return ("`setpriv --reuid=65534 ... rippleb run --methods raw ...`, then `rippleb run --resume run` "
            "(`HOME=/nonexistent`, no `RIPPLEB_KEY_FILE`)", f"{first.returncode}, {resumed.returncode}",
            f"the run: `{said[0] if said else 'no warning'}`; the resume: `{resumed.stderr.strip()[:160]}`")


def case_tune_stopped(where: Path, site: Path, how: str) -> tuple[str, int, str]:
    import signal

    from support import stopped_tune

    code, ended, family, left = stopped_tune(where, signal.SIGINT if how == "sigint" else signal.SIGKILL)
    return (f"`rippleb tune --methods order-tracking --seeds 100-104 --jobs 2`, {how.upper()} 12 s in", code,
            f"ended {ended:.1f} s after the signal; of its {family} processes, {left} left 5 s later")


CASES = {
    "local": case_local,
    "dask": lambda w, s: case_local(w, s, "dask"),
    "scheduler": case_scheduler,
    "log": case_log,
    "salt-file": lambda w, s: case_salt(w, s, "file"),
    "salt-stdin": lambda w, s: case_salt(w, s, "stdin"),
    "check-hang": lambda w, s: case_check(w, s, "hanger"),
    "check-exit": lambda w, s: case_check(w, s, "exiter"),
    "tune": case_tune,
    "tune-peek": case_tune_peek,
    "forgers": case_forgers,
    "fat": lambda w, s: case_fat(w, s, "4096"),
    "fat-tight": lambda w, s: case_fat(w, s, "400"),
    "nobody": case_nobody,
    "no-key": case_no_key,
    "tune-sigint": lambda w, s: case_tune_stopped(w, s, "sigint"),
    "tune-kill": lambda w, s: case_tune_stopped(w, s, "kill"),
}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--only", help="comma-separated cases (default: all): " + ", ".join(CASES))
    args = parser.parse_args()
    site = Path(tempfile.mkdtemp(prefix="rippleb-walls-site-"))
    _dist(site, "rippleb-walls", "rippleb_walls", WALLS_PROBER, WALLS_METHODS)
    print("| case | command | exit | what happened |\n|---|---|---|---|", flush=True)
    for name in (args.only.split(",") if args.only else CASES):
        where = Path(tempfile.mkdtemp(prefix=f"rippleb-walls-{name}-"))
        try:
            command, code, text = CASES[name](where, site)
        except Exception as exc:  # noqa: BLE001 - a case that could not be measured says why
            command, code, text = name, "-", f"not measured: {type(exc).__name__}: {exc}"
        finally:
            shutil.rmtree(where, ignore_errors=True)
        print(f"| {name} | {command} | {code} | {text} |", flush=True)


if __name__ == "__main__":
    main()

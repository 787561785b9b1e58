"""Interrupt a small ``rippleb run`` at random moments and check that it always ends well.

    python benchmarks/signal_trials.py N [--max-delay S] [--seed K] [--resume-every M]
    python benchmarks/signal_trials.py N --python /path/to/python   # another rippleb (e.g. main)

Each trial starts ``python -m rippleb run`` (by default ``--seeds 2 --jobs 2 --methods
raw,lowpass --scenarios static-contact,creep``: 8 rows, a few seconds) in a fresh directory,
in a session of its own, waits a random delay in ``[0, --max-delay]`` s (start-up and
running alike), and sends one of: SIGINT to its process group (Ctrl-C in a terminal),
SIGINT to the process, SIGTERM to the process, or two SIGINTs to the group a fraction of a
second apart (an impatient user). It then checks, and counts as a failure:

* **hang**: the command has not exited ``--timeout`` s after the signal (it is then killed);
* **traceback**: ``Traceback`` on stderr, or any stderr line not starting ``rippleb: ``;
* **exit**: anything but 130 with one ``rippleb: interrupted`` line (or 0 with the run's
  summary, when the run ended before the signal). A signal that comes while Python itself
  starts, before the first line of rippleb runs (the first tens of milliseconds: the
  interpreter, ``site`` and the environment's ``.pth`` files), gets Python's own answer (the
  process is killed, or Python prints ``KeyboardInterrupt`` from its start-up); such a trial
  is counted apart as ``before-rippleb`` (only for delays under :data:`STARTUP_S`;
  :func:`_before_rippleb` says how it is told);
* **rows**: ``results.csv`` missing or unreadable while the interrupt line says rows
  finished, a row count other than that line's, or a row that is not ``ok`` (an
  interrupted row must be left to ``--resume``, not recorded as failed);
* **leftovers**: a process of the trial still alive 2 s after the command exited (found by
  a marker in its environment), a ``rippleb-cache-*`` directory left in its ``TMPDIR``, or
  git's ``index.lock`` left in the checkout rippleb runs from (a run records its git state);
* **resume** (every ``--resume-every``-th interrupted trial): ``rippleb run --resume DIR``
  must exit 0 with every row ``ok`` and the kept rows not run again.

``tests/test_signals.py`` runs :func:`trial` a bounded number of times on a smaller run.
Prints one line per failure and a summary; exit status 1 if any trial failed.
"""

from __future__ import annotations

import argparse
import collections
import functools
import os
import random
import shutil
import signal
import subprocess
import sys
import tempfile
import time
import uuid
from pathlib import Path

RUN = ["--seeds", "2", "--jobs", "2", "--methods", "raw,lowpass", "--scenarios", "static-contact,creep"]
ROWS = 8
MODES = ("ctrl-c", "int", "term", "ctrl-c-twice")
MARKER = "RIPPLEB_SIGNAL_TRIAL"
#: Python starts (interpreter, site, .pth files) well within this [s], even on a loaded
#: machine; a trial signalled later cannot be a signal that preceded rippleb's first line.
STARTUP_S = 0.3


def trial(delay: float, mode: str, *, python: str = sys.executable, run_args=RUN, rows: int = ROWS,
          timeout: float = 60.0, resume: bool = False, keep: bool = False) -> dict:
    """One interrupted run; returns ``{"outcome": ..., "problems": [...], "exit_s": ...}``
    (``exit_s``: seconds from the signal to the command's exit).

    ``outcome`` is ``interrupted`` (exit 130), ``completed`` (the run ended before the
    signal, exit 0), ``before-rippleb`` (the signal came while Python was starting, before
    rippleb's first line), ``bad-exit`` or ``hang``; ``problems`` lists every check that failed (empty: the trial passed).
    """
    work = Path(tempfile.mkdtemp(prefix="rippleb-signal-"))
    tmp, out, tag = work / "tmp", work / "out", uuid.uuid4().hex
    tmp.mkdir()
    env = {**os.environ, MARKER: tag, "TMPDIR": str(tmp)}
    cmd = [*_default_sigint(), python, "-m", "rippleb", "run", *run_args, "--out", str(out), "--no-progress"]
    # Its own session, as a command in a terminal has.
    proc = subprocess.Popen(cmd, cwd=work, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, start_new_session=True)
    result = {"delay": delay, "mode": mode, "problems": []}
    try:
        time.sleep(delay)
        _send(proc, mode)
        sent = time.monotonic()
        try:
            stdout, stderr = proc.communicate(timeout=timeout)
            result["exit_s"] = time.monotonic() - sent
        except subprocess.TimeoutExpired:
            result.update(outcome="hang", stderr=_processes(tag))
            result["problems"].append(f"hang: still running {timeout:g} s after the signal")
            _kill_all(proc, tag)
            stdout, stderr = proc.communicate()
            return result
        result.update(code=proc.returncode, stderr=stderr.strip())
        _check(result, stdout, stderr, out, rows)
        _check_leftovers(result, tag, tmp)
        _check_git_lock(result, python)
        if resume and result["outcome"] == "interrupted" and (out / "run.json").is_file():
            _check_resume(result, python, out, env, rows)
    finally:
        if proc.poll() is None:
            _kill_all(proc, tag)
        if not keep:
            shutil.rmtree(work, ignore_errors=True)
    return result


@functools.lru_cache(maxsize=1)
def _default_sigint() -> tuple[str, ...]:
    """A prefix that runs a command with SIGINT at its default action: a child of a background
    process (a pytest-xdist worker) inherits it ignored, and Python then keeps it ignored.
    GNU env does it without ``preexec_fn``, which is unsafe where threads run trials."""
    probe = subprocess.run(["env", "--default-signal=INT", "true"], capture_output=True)
    if probe.returncode != 0:
        raise RuntimeError("signal_trials needs GNU env >= 8.31 (env --default-signal)")
    return ("env", "--default-signal=INT")


def _send(proc: subprocess.Popen, mode: str) -> None:
    with_group = mode.startswith("ctrl-c")
    signum = signal.SIGTERM if mode == "term" else signal.SIGINT
    try:
        os.killpg(proc.pid, signum) if with_group else proc.send_signal(signum)
        if mode == "ctrl-c-twice":
            time.sleep(random.uniform(0.05, 0.5))
            os.killpg(proc.pid, signum)
    except ProcessLookupError:
        pass  # it had ended already


def _check(result: dict, stdout: str, stderr: str, out: Path, rows: int) -> None:
    problems, code = result["problems"], result["code"]
    if result["delay"] < STARTUP_S and _before_rippleb(code, stdout, stderr):
        result["outcome"] = "before-rippleb"
        return
    lines = [line for line in stderr.splitlines() if line.strip()]
    if "Traceback" in stderr or any(not line.startswith("rippleb: ") for line in lines):
        problems.append("traceback: " + " | ".join(lines[-3:]))
    interrupted = [line for line in lines if line.startswith("rippleb: interrupted")]
    if code == 0 and f"{rows} rows" in stdout and not lines:
        result["outcome"] = "completed"
    elif code == 130 and len(interrupted) == 1:
        result["outcome"] = "interrupted"
    else:
        result["outcome"] = "bad-exit"
        problems.append(f"exit: {code} with stderr {lines[-2:]}")
        return
    _check_rows(result, interrupted[0] if interrupted else None, out, rows)


def _before_rippleb(code: int, stdout: str, stderr: str) -> bool:
    """The signal came while Python itself was starting, before the first line of rippleb
    ran: killed by it (no handler yet), or Python's ``KeyboardInterrupt`` traceback from
    its own start-up (``site`` and the environment's ``.pth`` files), naming no file of
    rippleb. Nothing of the run existed yet; rippleb cannot handle what precedes it."""
    if stdout or code not in (1, -signal.SIGINT, -signal.SIGTERM):
        return False
    lines = [line for line in stderr.splitlines() if line.strip()]
    if not lines:
        return True
    return lines[-1] == "KeyboardInterrupt" and "/rippleb/" not in stderr and "rippleb:" not in stderr


def _check_rows(result: dict, line: str | None, out: Path, rows: int) -> None:
    import pandas as pd

    problems, path = result["problems"], out / "results.csv"
    said = 0
    if line is not None and "finished row(s) are in" in line:
        said = int(line.split("; ", 1)[1].split(" ", 1)[0])
    elif line is not None and "no row had finished" not in line and (out / "run.json").is_file():
        problems.append(f"rows: the run directory exists but the line names no rows: {line!r}")
    if line is not None and (out / "run.json").is_file() and "--resume" not in line:
        problems.append(f"rows: no resume command in {line!r}")
    if not path.is_file():
        if said or line is None:
            problems.append("rows: no results.csv")
        result["rows"] = 0
        return
    try:
        frame = pd.read_csv(path)
    except Exception as exc:  # noqa: BLE001 - any failure to read is the finding
        problems.append(f"rows: results.csv unreadable: {type(exc).__name__}: {exc}")
        return
    result["rows"] = len(frame)
    expected = rows if line is None else said
    if len(frame) != expected:
        problems.append(f"rows: results.csv has {len(frame)} rows, expected {expected}")
    if len(frame) and not (frame["status"] == "ok").all():
        bad = frame[frame["status"] != "ok"]
        problems.append(f"rows: {len(bad)} row(s) not ok: {bad['message'].astype(str).iloc[0][:120]}")


def _check_leftovers(result: dict, tag: str, tmp: Path) -> None:
    deadline = time.monotonic() + 2.0
    while _pids(tag) and time.monotonic() < deadline:
        time.sleep(0.05)
    left = _pids(tag)
    if left:
        result["problems"].append(f"leftovers: {len(left)} process(es) still running: {_processes(tag)}")
        for pid in left:
            with _quiet():
                os.kill(pid, signal.SIGKILL)
    caches = [p.name for p in tmp.iterdir() if p.name.startswith("rippleb-cache-")]
    if caches:
        result["problems"].append(f"leftovers: {caches} in TMPDIR")


def _check_git_lock(result: dict, python: str) -> None:
    """A run records its checkout's git state as it starts: an interrupt must not leave git's
    ``index.lock`` behind (the user's next commit would fail). A lock that goes within 2 s
    belongs to someone's git at work, not to the run."""
    lock = _git_dir(python) / "index.lock" if _git_dir(python) else None
    deadline = time.monotonic() + 2.0
    while lock is not None and lock.exists() and time.monotonic() < deadline:
        time.sleep(0.1)
    if lock is not None and lock.exists():
        result["problems"].append(f"leftovers: {lock}")


@functools.lru_cache(maxsize=None)
def _git_dir(python: str) -> Path | None:
    """The git directory of the checkout whose rippleb ``python`` imports (None if not one)."""
    code = "import pathlib, rippleb; print(pathlib.Path(rippleb.__file__).resolve().parent.parent)"
    root = subprocess.run([python, "-c", code], capture_output=True, text=True).stdout.strip()
    found = subprocess.run(["git", "-C", root, "rev-parse", "--absolute-git-dir"], capture_output=True, text=True)
    return Path(found.stdout.strip()) if found.returncode == 0 else None


def _check_resume(result: dict, python: str, out: Path, env: dict, rows: int) -> None:
    import pandas as pd

    kept = pd.read_csv(out / "results.csv") if (out / "results.csv").is_file() else None
    proc = subprocess.run([python, "-m", "rippleb", "run", "--resume", str(out), "--no-progress"],
                          capture_output=True, text=True, env=env, timeout=300)
    if proc.returncode != 0:
        result["problems"].append(f"resume: exit {proc.returncode}: {proc.stderr.strip()[-200:]}")
        return
    frame = pd.read_csv(out / "results.csv")
    if len(frame) != rows or not (frame["status"] == "ok").all():
        result["problems"].append(f"resume: {len(frame)} rows, statuses {sorted(set(frame['status']))}")
    if kept is not None and len(kept) and len(set(frame["run_id"])) < 2 and len(kept) < rows:
        result["problems"].append("resume: the kept rows were run again")


class _quiet:
    def __enter__(self):
        return self

    def __exit__(self, *exc):
        return exc[0] is not None and issubclass(exc[0], OSError)


def _pids(tag: str) -> list[int]:
    """Processes whose environment carries this trial's marker (in any PID namespace)."""
    needle = f"{MARKER}={tag}".encode()
    found = []
    for entry in os.listdir("/proc"):
        if not entry.isdigit():
            continue
        try:
            with open(f"/proc/{entry}/environ", "rb") as fh:
                if needle in fh.read().split(b"\0"):
                    found.append(int(entry))
        except OSError:
            continue
    return found


def _processes(tag: str) -> str:
    """``pid state wchan cmdline`` of every process of the trial (why it hangs)."""
    rows = []
    for pid in _pids(tag):
        try:
            stat = Path(f"/proc/{pid}/stat").read_text()
            wchan = Path(f"/proc/{pid}/wchan").read_text()
            cmd = Path(f"/proc/{pid}/cmdline").read_bytes().replace(b"\0", b" ").decode()[:60]
        except OSError:
            continue
        rows.append(f"{pid} {stat[stat.rfind(')') + 2]} {wchan} {cmd}")
    return "; ".join(rows)


def _kill_all(proc: subprocess.Popen, tag: str) -> None:
    with _quiet():
        os.killpg(proc.pid, signal.SIGKILL)
    for pid in _pids(tag):
        with _quiet():
            os.kill(pid, signal.SIGKILL)
    proc.wait()


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("n", type=int, help="number of trials")
    parser.add_argument("--max-delay", type=float, default=6.0, help="largest delay before the signal [s]")
    parser.add_argument("--timeout", type=float, default=60.0, help="seconds after the signal that count as a hang")
    parser.add_argument("--seed", type=int, default=0, help="seed of the delays and signal kinds")
    parser.add_argument("--resume-every", type=int, default=10, metavar="M",
                        help="resume every M-th interrupted trial and check it completes (0: never)")
    parser.add_argument("--python", default=sys.executable, help="the interpreter whose rippleb runs")
    parser.add_argument("--executor-dask", action="store_true",
                        help="run the rows on a local Dask cluster (--executor dask); give a --max-delay "
                             "that covers its start (tens of seconds on a loaded machine)")
    args = parser.parse_args(argv)
    run_args = RUN + (["--executor", "dask"] if args.executor_dask else [])
    rng = random.Random(args.seed)
    outcomes, failures, interrupted, start = collections.Counter(), 0, 0, time.monotonic()
    exit_s = []
    for i in range(args.n):
        delay, mode = rng.uniform(0.0, args.max_delay), rng.choice(MODES)
        resume = args.resume_every > 0 and interrupted % args.resume_every == 0
        res = trial(delay, mode, python=args.python, run_args=run_args, timeout=args.timeout, resume=resume)
        interrupted += res["outcome"] == "interrupted"
        if res["outcome"] == "interrupted":
            exit_s.append(res["exit_s"])
        outcomes[res["outcome"]] += 1
        for problem in res["problems"]:
            kind = problem.split(":", 1)[0]
            outcomes[f"problem:{kind}"] += 1
        if res["problems"]:
            failures += 1
            print(f"trial {i}: {mode} at {delay:.3f} s: exit {res.get('code')}: {'; '.join(res['problems'])}",
                  flush=True)
    took = time.monotonic() - start
    slowest = f"; interrupted runs ended {max(exit_s):.1f} s after the signal at most" if exit_s else ""
    print(f"{args.n} trials in {took:.0f} s: {dict(sorted(outcomes.items()))}; {failures} failed{slowest}")
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())

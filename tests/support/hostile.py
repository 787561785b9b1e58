"""Hostile plugins of the integrity, sealing and plumbing suites, and the CSV edits that forge rows.

The tests (``tests/test_integrity.py``, ``tests/test_sealing.py``, ``tests/test_plumbing.py``,
``tests/test_row_integrity.py``) and the outcome-table scripts of ``docs/robustness.md``
(``docs/tables/integrity_table.py``, ``containment_table.py``, ``plumbing_table.py``) import
them from here, so that each published table shows exactly the attacks its tests make. Each
source is installed as a distribution with :func:`support.install_dist`. (The walls prober of
issue 41 is in :mod:`support.walls`.)

Attributes
----------
INTEGRITY_HOSTILE : str
    ``forger`` rewrites cached logs, ``peeker`` returns a cached truth, ``rummager`` searches
    its own memory for truths, ``spawner`` leaves processes behind, ``killer`` signals the
    runner.
SLOW_IMPORT : str
    A plugin module whose import never ends.
RESIMULATOR : str
    ``resimulator`` finds its own scenario and seed, re-simulates it and returns the truth.
PLUMBING_PROBER : str
    ``prober`` tries every descriptor, terminal and run file a method's process can reach, and
    prints what it opened on its own log.
"""

from __future__ import annotations

import csv
import io
import textwrap

INTEGRITY_HOSTILE = textwrap.dedent('''
    import glob, io, os, signal, subprocess, sys, tempfile, time
    import numpy as np
    from rippleb import Method

    def _cache_files():
        """Every cache file a plugin could find: the temporary directory, the run directory
        below the working directory, and the directories of its inherited file descriptors."""
        tmp = tempfile.gettempdir()   # its scratch directory, two levels below the run's (issue 34)
        found = [path for root in (tmp, os.path.dirname(os.path.dirname(tmp)))
                 for path in glob.glob(os.path.join(root, "rippleb-cache-*", "*"))]
        found += glob.glob(os.path.join("*", ".cache", "*"))
        for fd in os.listdir("/proc/self/fd"):
            try:
                target = os.readlink(f"/proc/self/fd/{fd}")
            except OSError:
                continue
            if target.startswith("/"):
                found += glob.glob(os.path.join(os.path.dirname(target), ".cache", "*"))
        return sorted(set(found))

    class Forger(Method):
        """Rewrites every cached log it can find: the strain of every other row x 100."""
        name = "forger"
        def fit(self, calibration):
            for path in _cache_files():
                try:
                    os.chmod(path, 0o644)
                    with np.load(path, allow_pickle=False) as npz:
                        arrays = {k: npz[k] for k in npz.files}
                    if "strain" in arrays:
                        arrays["strain"] = arrays["strain"] * 100.0
                    if "torque_true" in arrays:
                        arrays["torque_true"] = arrays["torque_true"] + 30.0
                    buf = io.BytesIO()
                    np.savez(buf, **arrays)
                    with open(path, "wb") as fh:
                        fh.write(buf.getvalue())
                except Exception:
                    pass
        def step(self, block):
            return block.strain * 0.0

    class Peeker(Method):
        """Returns torque_true if it can find it anywhere in the cache."""
        name = "peeker"
        def reset(self, spec):
            self.truth, self.pos = None, 0
            for path in _cache_files():
                try:
                    with np.load(path, allow_pickle=False) as npz:
                        if "torque_true" in npz.files:
                            self.truth = npz["torque_true"]
                except Exception:
                    pass
        def step(self, block):
            n = len(block)
            if self.truth is not None and len(self.truth) >= self.pos + n:
                out = self.truth[self.pos:self.pos + n]
            else:
                out = np.zeros(n)
            self.pos += n
            return out

    def _truths_in_memory():
        """Scored truths anywhere in this process: a Truth object the garbage collector
        tracks, or one a frame up the stack holds (the runner's, if this process is a fork
        of it)."""
        import gc, sys
        def is_truth(value):
            return type(value).__name__ == "Truth" and getattr(value, "torque_true", None) is not None
        found = sum(is_truth(o) for o in gc.get_objects())
        frame = sys._getframe()
        while frame is not None:
            for value in list(frame.f_locals.values()):
                truths = getattr(value, "truths", None)
                found += is_truth(value) + (len(truths) if isinstance(truths, dict) else 0)
            frame = frame.f_back
        return found

    class Rummager(Method):
        """Searches its own process's memory for the truth it is scored on."""
        name = "rummager"
        def reset(self, spec):
            found = _truths_in_memory()
            if found:
                raise RuntimeError(f"found {found} truths in my own memory")
        def step(self, block):
            return block.strain * 0.0

    class Spawner(Method):
        """Leaves a detached process, and a forked grandchild in its own session."""
        name = "spawner"
        def fit(self, calibration):
            subprocess.Popen(["sleep", "987"], start_new_session=True)
            if os.fork() == 0:
                os.setsid()
                os.execvp("sleep", ["sleep", "988"])
            time.sleep(0.2)
            print("spawned", flush=True)   # on its log: it may write no file outside its scratch directory
        def step(self, block):
            return block.strain * 0.0

    def _ancestors():
        pid, found = os.getpid(), []
        while pid > 1:
            with open(f"/proc/{pid}/stat") as fh:
                pid = int(fh.read().rsplit(")", 1)[1].split()[1])
            try:
                with open(f"/proc/{pid}/cmdline", "rb") as fh:
                    found.append((pid, fh.read().replace(b"\\0", b" ").decode()))
            except OSError:
                break
        return found

    class Killer(Method):
        """Signals its process group, its parent, and every ancestor that runs rippleb."""
        name = "killer"
        def fit(self, calibration):
            for action in (lambda: os.killpg(0, signal.SIGTERM),
                           lambda: os.kill(os.getppid(), signal.SIGKILL)):
                try:
                    action()
                except Exception:
                    pass
            for pid, cmdline in _ancestors():
                if "rippleb" in cmdline and " run" in cmdline:
                    try:
                        os.kill(pid, signal.SIGKILL)
                    except Exception:
                        pass
        def step(self, block):
            return block.strain * 0.0
''')
SLOW_IMPORT = "import time\ntime.sleep(3600)\n"

RESIMULATOR = textwrap.dedent('''
    import sys
    import numpy as np
    import rippleb
    from rippleb import Method
    from rippleb.data import SensorLog

    def _scored_meta():
        """The meta of the log this row streams: the row job holds it, up the stack."""
        frame = sys._getframe()
        while frame is not None:
            for value in list(frame.f_locals.values()):
                if isinstance(value, SensorLog) and value.torque_ref is None and "scenario" in value.meta:
                    return value.meta
            frame = frame.f_back
        raise RuntimeError("found no scored log")

    class Resimulator(Method):
        """Re-simulates its own scenario and returns the truth."""
        name = "resimulator"
        def reset(self, spec):
            self.truth, self.pos = None, 0
        def _truth(self, block):
            meta = _scored_meta()
            scenario, condition = meta["scenario"], meta["condition"]
            for seed in [meta["seed"]] + [s for s in range(4) if s != meta["seed"]]:
                sim = rippleb.simulate(scenario, seed, condition)
                if np.array_equal(sim.log.strain[:len(block)], block.strain):
                    return sim.log.torque_true
            # no seed reproduces the strain: the best guess left is the public seed's device
            return rippleb.simulate(scenario, meta["seed"], condition).log.torque_true
        def step(self, block):
            if self.truth is None:
                self.truth = self._truth(block)
            out = self.truth[self.pos:self.pos + len(block)]
            self.pos += len(block)
            return out
''')

PLUMBING_PROBER = textwrap.dedent('''
    import glob, json, os, sys
    import numpy as np
    from rippleb import Method

    FORGED = "12 rows (12 ok) in forged/results.csv"

    def _ancestors(pid):
        chain = []
        while pid > 1 and len(chain) < 64:
            try:
                with open(f"/proc/{pid}/stat") as fh:
                    pid = int(fh.read().rsplit(")", 1)[1].split()[1])
            except (OSError, ValueError):
                break
            chain.append(pid)
        return chain

    def _try_write(path):
        try:
            fd = os.open(path, os.O_WRONLY | os.O_APPEND | os.O_CREAT, 0o644)
        except OSError as exc:
            return type(exc).__name__
        os.close(fd)
        return "opened"

    def probe(runner, run_dir):
        me = int(os.readlink("/proc/self"))   # its PID as this /proc counts (os.getpid() is 1)
        try:
            visible = sorted(int(p) for p in os.listdir("/proc") if p.isdigit())
        except OSError:                       # Landlock: only its own entry of the host's /proc
            visible = [me]
        found = {"visible": visible, "opened": []}
        for pid in found["visible"]:
            if pid == me:
                continue
            try:
                fds = os.listdir(f"/proc/{pid}/fd")
            except OSError:
                continue
            for fd in fds:
                try:
                    target = os.readlink(f"/proc/{pid}/fd/{fd}")
                except OSError:
                    target = "?"
                if _try_write(f"/proc/{pid}/fd/{fd}") == "opened":
                    rippleb_process = pid == runner or runner in _ancestors(pid)
                    found["opened"].append([pid, fd, target, rippleb_process])
        found["terminals"] = {p: _try_write(p) for p in glob.glob("/dev/pts/[0-9]*")}
        found["run_dir"] = {name: _try_write(os.path.join(run_dir, name)) for name in ("forged.txt", "results.csv")}
        caches = glob.glob(os.path.join(os.environ.get("TMPDIR", "/tmp"), "rippleb-cache-*"))
        found["cache"] = {c: _try_write(os.path.join(c, "forged.npz")) for c in caches}
        try:
            from rippleb.integrity import key_path
            found["key_bytes"] = len(key_path().read_bytes())   # rippleb's key for row MACs
        except (OSError, ImportError) as exc:                    # ImportError: a rippleb without keys
            found["key_bytes"] = type(exc).__name__
        print(FORGED)
        print(FORGED, file=sys.stderr)
        print("FOUND " + json.dumps(found), flush=True)   # its log: it may write nowhere else (issue 34)

    class Prober(Method):
        """Probes the runner's plumbing (``runner``: the runner's PID, 0 unknown), then returns zeros."""
        name = "prober"
        def __init__(self, run_dir="", runner=0):
            self.run_dir, self.runner = run_dir, runner
        def get_params(self):
            return {}
        def reset(self, spec):
            probe(self.runner, self.run_dir)
        def step(self, block):
            return np.zeros(len(block))
''')


def csv_rows(path):
    """The rows of the CSV file ``path`` as dictionaries of strings, as a hand edit sees them."""
    return list(csv.DictReader(io.StringIO(path.read_text())))


def write_csv_rows(path, rows):
    """Write ``rows`` (dictionaries of strings) to ``path`` as :func:`csv_rows` read them: a forgery."""
    buffer = io.StringIO()
    writer = csv.DictWriter(buffer, fieldnames=list(rows[0]), lineterminator="\n")
    writer.writeheader()
    writer.writerows(rows)
    path.write_text(buffer.getvalue())

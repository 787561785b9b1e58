"""The project's own hostile suite (issue 34): a method, or whoever edits a run directory
between runs, tries each attack of the issue; every test asserts the attack failed and
that the honest rows beside it are untouched.

Attacks on the run directory and on the terminal (items 3 and 4) run through the real CLI
on one finished run of three methods: ``chatty`` prints 30 MB, ``escaper`` raises an
exception whose text holds terminal escape sequences, ``raw`` is the honest neighbour.
"""

import csv
import io
import json
import os
import shutil
import subprocess
import sys
import textwrap
from pathlib import Path

import pandas as pd
import pytest
from hypothesis import given, settings, strategies as st

from rippleb.engine.process.joblog import OUTPUT_CAP_BYTES, JobLog
from rippleb.printable import escaped
from support import install_dist  # a minimal installed distribution without pip

#: A terminal escape that retitles the window, clears the screen and rings the bell.
ESCAPE = "\x1b]0;owned\x07\x1b[2J\x1b[31mred\r\x9b"
HOSTILE = textwrap.dedent(f'''
    import os, sys
    import numpy as np
    from rippleb import Method

    class Chatty(Method):
        """Prints 30 MB to stdout and stderr, then scores like a zero estimate."""
        name = "chatty"
        def reset(self, spec):
            line = "x" * 1023 + "\\n"
            for _ in range(15 * 1024):
                sys.stdout.write(line)
                sys.stderr.write(line)
        def step(self, block):
            return np.zeros(len(block))

    class Escaper(Method):
        """Raises an exception whose text would act on a terminal."""
        name = "escaper"
        def reset(self, spec):
            raise RuntimeError({ESCAPE!r})
        def step(self, block):
            return np.zeros(len(block))
''')
ROW_LOG = "{}--static-contact--same-session--0.txt"


def _cli(where, site, *args):
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(site), os.environ.get("PYTHONPATH", "")]),
           "RIPPLEB_KEY_FILE": str(where / "key")}
    return subprocess.run([sys.executable, "-m", "rippleb", *map(str, args)], capture_output=True, text=True,
                          env=env, cwd=where, timeout=600)


@pytest.fixture(scope="module")
def finished(tmp_path_factory):
    """``(directory, site, first run)``: one finished run of chatty, escaper and raw."""
    where = tmp_path_factory.mktemp("hostile")
    site = where / "site"
    install_dist(site, "rippleb-hostile", "rippleb_hostile", HOSTILE, {"chatty": "Chatty", "escaper": "Escaper"})
    proc = _cli(where, site, "run", "--methods", "chatty,escaper,raw", "--scenarios", "static-contact",
                "--seeds", "1", "--jobs", "2", "--no-progress", "--out", "run")
    assert proc.returncode == 0, proc.stderr
    return where, site, proc


def _copy(finished, tmp_path):
    where, site, _ = finished
    shutil.copytree(where / "run", tmp_path / "run")
    shutil.copy(where / "key", tmp_path / "key")
    return tmp_path / "run", site


def _rows(run):
    return {row["method"]: row for row in csv.DictReader(io.StringIO((run / "results.csv").read_text()))}


@pytest.mark.slow
def test_a_method_s_output_is_cut_at_the_cap_with_a_note(finished):
    where, _, _ = finished
    log = (where / "run" / "logs" / ROW_LOG.format("chatty")).read_bytes()
    assert OUTPUT_CAP_BYTES < len(log) < OUTPUT_CAP_BYTES + 200          # not the 30 MB it printed
    assert log.rstrip().endswith(b"bytes were dropped")
    assert b"this job wrote 31457280 bytes" in log
    rows = _rows(where / "run")
    assert rows["chatty"]["status"] == "ok" and rows["raw"]["status"] == "ok"


@pytest.mark.slow
def test_escape_sequences_reach_neither_terminal_nor_files(finished, tmp_path):
    where, site, first = finished
    rows = _rows(where / "run")
    assert rows["escaper"]["status"] == "error"
    assert "\\x1b]0;owned\\x07" in rows["escaper"]["message"]          # shown, spelled out
    report = _cli(where, site, "report", "run", "--out", tmp_path / "rep")
    assert report.returncode == 0, report.stderr
    written = [(tmp_path / "rep" / "README.md").read_text(), (where / "run" / "results.csv").read_text()]
    for text in [first.stdout, first.stderr, report.stdout, report.stderr, *written]:
        assert "\x1b" not in text and "\x07" not in text and "\x9b" not in text
    # spelled out, and Markdown-escaped so that it renders as written: \x1b[2J
    assert r"\\x1b\[2J" in written[0]
    assert float(rows["raw"]["rms_error_nm"]) > 0 and rows["raw"]["status"] == "ok"


@pytest.mark.slow
def test_a_run_json_without_its_integrity_field_is_not_trusted(finished, tmp_path):
    run, site = _copy(finished, tmp_path)
    config = json.loads((run / "run.json").read_text())
    del config["integrity"]
    config["seeds"] = [0, 1, 2]
    (run / "run.json").write_text(json.dumps(config))
    text = (run / "results.csv").read_text()
    raw_rms = _rows(run)["raw"]["rms_error_nm"]
    (run / "results.csv").write_text(text.replace(raw_rms, "0.0001"))
    report = _cli(tmp_path, site, "report", run, "--out", "rep")
    assert report.returncode == 0, report.stderr
    assert "run.json: has no integrity field" in report.stderr and "its rows are not verified" in report.stderr
    resumed = _cli(tmp_path, site, "run", "--resume", run, "--no-progress")
    assert resumed.returncode == 2
    assert resumed.stderr.strip().splitlines() == [
        f"rippleb: error: {run / 'run.json'}: has no integrity field (deleted, or written before rippleb kept "
        "keyed hashes, or where no key could be written); rippleb will not resume a run it cannot vouch for: "
        "start it again with another --out"]
    assert "0.0001" in (run / "results.csv").read_text()       # nothing rewritten, nothing run


@pytest.mark.slow
@pytest.mark.parametrize("planted", ["a log", "logs", "results.csv", "rows.mac", ".lock"])
def test_no_write_follows_a_symbolic_link_in_the_run_directory(finished, tmp_path, planted):
    run, site = _copy(finished, tmp_path)
    victim = tmp_path / "victim"
    victim.mkdir()
    (victim / "precious.txt").write_text("precious\n")
    lines = (run / "results.csv").read_text().splitlines(keepends=True)
    (run / "results.csv").write_text("".join(line for line in lines if not line.startswith("raw,")))
    target = {"a log": run / "logs" / ROW_LOG.format("raw"), "logs": run / "logs"}.get(planted, run / planted)
    shutil.rmtree(target) if target.is_dir() else target.unlink()
    target.symlink_to(victim if planted == "logs" else victim / "precious.txt")
    resumed = _cli(tmp_path, site, "run", "--resume", run, "--no-progress")
    assert resumed.returncode == 2
    assert resumed.stderr.strip().splitlines() == [
        f"rippleb: error: {target}: a symbolic link, which rippleb never makes in a run or report directory; "
        "rippleb does not write through it: remove it, or choose another --out"]
    assert sorted(p.name for p in victim.iterdir()) == ["precious.txt"]
    assert (victim / "precious.txt").read_text() == "precious\n"


def test_a_memory_limit_no_kernel_can_hold_is_one_line(tmp_path):
    proc = subprocess.run([sys.executable, "-m", "rippleb", "run", "--methods", "raw", "--scenarios",
                           "static-contact", "--seeds", "1", "--memory-limit", "1e13", "--out", "out"],
                          capture_output=True, text=True, cwd=tmp_path, timeout=300)
    assert proc.returncode == 2
    assert proc.stderr.strip().splitlines() == [
        "rippleb: error: --memory-limit 1e+13 MB is more than the 134217728 MB (128 TiB) address space of a "
        "process: the kernel cannot hold a job to it; give 0 for no limit"]
    assert list(tmp_path.iterdir()) == []


def test_the_largest_memory_limit_still_runs(tmp_path):
    import rippleb
    from rippleb.engine.checks import MAX_MEMORY_MB

    frame = rippleb.run(["raw"], ["static-contact"], [0], memory_mb=MAX_MEMORY_MB, progress=False)
    assert frame.status.tolist() == ["ok"], frame.message.tolist()


# ----------------------------------------------------------------------------- units


@settings(max_examples=300, derandomize=True, deadline=None)
@given(st.text())
def test_escaped_text_holds_no_control_character_and_loses_nothing_printable(text):
    def control(c):
        return ord(c) < 0x20 or 0x7f <= ord(c) <= 0x9f or c in "\u2028\u2029"

    shown = escaped(text)
    assert not any(map(control, shown))
    if any(map(control, text)):
        assert len(shown) > len(text)
    else:
        assert shown == text


def test_escaped_spells_an_escape_sequence_out():
    assert escaped("a\x1b[2Jb\nc") == "a\\x1b[2Jb\\x0ac"


@pytest.mark.parametrize("sizes", [[10], [OUTPUT_CAP_BYTES], [OUTPUT_CAP_BYTES - 5, 10, 3 * 2**16]])
def test_a_job_log_keeps_the_cap_and_says_what_it_dropped(tmp_path, sizes):
    path = tmp_path / "log.txt"
    log = JobLog(str(path))
    log.open()
    written = 0
    for size in sizes:
        data = bytes([65 + len(str(size)) % 26]) * size
        view = memoryview(data)
        while view:   # the pipe holds 64 kB: drain between writes, as the keeper does
            view = view[os.write(log.write_fd, view[:2**16]):]
            log.drain()
        written += size
    os.close(log.write_fd)
    log.close()
    kept = path.read_bytes()
    if written <= OUTPUT_CAP_BYTES:
        assert len(kept) == written
    else:
        assert kept[:OUTPUT_CAP_BYTES].count(b"\n") == 0 and len(kept) > OUTPUT_CAP_BYTES
        assert kept[OUTPUT_CAP_BYTES:].decode().strip() == (
            f"rippleb: this job wrote {written} bytes; its log keeps the first {OUTPUT_CAP_BYTES} (8 MiB), "
            f"{written - OUTPUT_CAP_BYTES} bytes were dropped")


def test_a_job_log_never_opens_through_a_link(tmp_path):
    (tmp_path / "precious").write_text("precious\n")
    (tmp_path / "log.txt").symlink_to(tmp_path / "precious")
    log = JobLog(str(tmp_path / "log.txt"))
    log.open()
    os.write(log.write_fd, b"hostile output\n")
    os.close(log.write_fd)
    log.close()
    assert (tmp_path / "precious").read_text() == "precious\n"


# ----------------------------------------------------------------------------- the walls (items 1, 2)

#: A method that tries every attack of the issue on the walls around its process, from its
#: ``reset``, and raises what it achieved as JSON: its row's message is the one way out
#: that works on a Dask worker too (it can write nowhere but its scratch directory).
BREAKER = textwrap.dedent(r"""
    import ctypes, json, os, sys, sysconfig
    import numpy as np
    from rippleb import Method

    libc = ctypes.CDLL(None, use_errno=True)

    def _call(fn, *args):
        return 0 if fn(*args) == 0 else ctypes.get_errno()

    def _open_write(path, flags=os.O_WRONLY | os.O_APPEND):
        try:
            os.close(os.open(path, flags, 0o644))
        except OSError as exc:
            return exc.errno
        return 0

    def _read(path):
        try:
            with open(path, "rb") as fh:
                return len(fh.read())
        except OSError as exc:
            return -exc.errno

    def attack(run_dir, salt):
        import rippleb
        from rippleb.integrity import key_path
        key = str(key_path())
        targets = {"proc": "/proc", "run": run_dir, "key": key}
        found = {"umount": {k: _call(libc.umount2, p.encode(), 2) for k, p in targets.items()}}
        found["umount_lazy"] = {k: _call(libc.umount2, p.encode(), 2 | 8) for k, p in targets.items()}
        found["remount_rw"] = _call(libc.mount, None, run_dir.encode(), None, 32 | 4096, None)
        found["key_bytes"] = _read(key)
        found["salt_bytes"] = _read(salt) if salt else None
        found["cmdline_names_salt"] = b"salt" in open("/proc/self/cmdline", "rb").read()
        found["unshare"] = _call(libc.unshare, 0x10000000)
        found["ptrace"] = _call(libc.ptrace, 16, 1, None, None)   # PTRACE_ATTACH to PID 1
        found["cap_eff"] = [l.split()[1] for l in open("/proc/self/status") if l.startswith("CapEff")][0]
        found["pids"] = sorted(int(p) for p in os.listdir("/proc") if p.isdigit())
        package = os.path.dirname(rippleb.__file__)
        found["write_package"] = _open_write(os.path.join(package, "report", "tables.py"))
        found["plant_pth"] = _open_write(os.path.join(sysconfig.get_paths()["purelib"], "zz_hostile_probe.pth"),
                                         os.O_WRONLY | os.O_CREAT | os.O_EXCL)
        found["write_run_dir"] = _open_write(os.path.join(run_dir, "forged.txt"), os.O_WRONLY | os.O_CREAT)
        found["write_home"] = _open_write(os.path.join(os.path.expanduser("~"), "zz_hostile_probe"),
                                          os.O_WRONLY | os.O_CREAT | os.O_EXCL)
        scratch = os.path.join(os.environ.get("TMPDIR", "/tmp"), "mine.txt")
        found["write_scratch"] = _open_write(scratch, os.O_WRONLY | os.O_CREAT)
        # Its row's message is the one channel out that works locally and on a Dask worker.
        raise RuntimeError("HOSTILE " + json.dumps(found, separators=(",", ":")))

    class Breaker(Method):
        # its targets are parameters: its process inherits no environment (issue 41)
        name = "breaker"
        def __init__(self, run_dir="", salt=""):
            self.run_dir, self.salt = run_dir, salt
        def get_params(self):
            return {}
        def reset(self, spec):
            attack(self.run_dir, self.salt)
        def step(self, block):
            return np.zeros(len(block))
""")


def _breaker(run_dir, salt=None) -> str:
    """The breaker's label, its targets as parameters."""
    return f'breaker[run_dir="{run_dir}"' + (f',salt="{salt}"' if salt else "") + "]"


def _found(run):
    message = _rows(run)[next(m for m in _rows(run) if m.startswith("breaker"))]["message"]
    return json.loads(message[message.index("HOSTILE ") + len("HOSTILE "):])


def _assert_walls_held(found, run):
    import errno

    assert set(found["umount"].values()) | set(found["umount_lazy"].values()) == {errno.EPERM}, found
    assert found["remount_rw"] == errno.EPERM
    assert found["key_bytes"] <= 0                        # unreadable (Landlock), and /dev/null over it
    assert found["unshare"] == errno.EPERM and found["ptrace"] == errno.EPERM
    assert int(found["cap_eff"], 16) == 0
    assert found["pids"] == [1]
    for attack in ("write_package", "plant_pth", "write_run_dir", "write_home"):
        assert found[attack] in (errno.EACCES, errno.EROFS, errno.EPERM), (attack, found[attack])
    assert found["write_scratch"] == 0                     # the one place it may write
    assert not (run / "forged.txt").exists()


@pytest.fixture(scope="module")
def breaker_site(tmp_path_factory):
    site = tmp_path_factory.mktemp("breaker-site")
    install_dist(site, "rippleb-breaker", "rippleb_breaker", BREAKER, {"breaker": "Breaker"})
    yield site
    import sysconfig

    planted = os.path.join(sysconfig.get_paths()["purelib"], "zz_hostile_probe.pth")
    assert not os.path.exists(planted), "the breaker planted a .pth in site-packages"


@pytest.mark.slow
def test_a_resumed_sealed_run_keeps_the_walls_and_the_salt(breaker_site, tmp_path):
    """The issue's cases 1, 2, 4: unmounting the covers, writing rippleb's code or a .pth,
    reading the key, and, in a sealed run resumed with --salt-file FILE, reading the salt
    (its path on the command line, or guessed). The raw row beside it is untouched."""
    from rippleb.engine.process.sandbox import missing_protections

    if missing_protections():
        pytest.skip(f"this kernel does not grant {missing_protections()}")
    run, salt = tmp_path / "run", tmp_path / "salt"
    first = _cli(tmp_path, breaker_site, "run", "--methods", "raw", "--scenarios", "static-contact", "--seeds", "1",
                 "--no-progress", "--sealed", salt, "--out", run)
    assert first.returncode == 0, first.stderr
    before = _rows(run)["raw"]
    resumed = _cli(tmp_path, breaker_site, "run", "--resume", run, "--methods", f"raw,{_breaker(run, salt)}",
                   "--salt-file", salt, "--no-progress")
    assert resumed.returncode == 0, resumed.stderr
    found = _found(run)
    _assert_walls_held(found, run)
    assert found["salt_bytes"] <= 0 and found["cmdline_names_salt"] is False
    rows = _rows(run)
    kept = ("status", "rms_error_nm", "max_error_nm", "seed", "scenario_sha256")
    assert {k: rows["raw"][k] for k in kept} == {k: before[k] for k in kept}   # untouched by the resume
    assert rows[_breaker(run, salt)]["status"] == "error"   # it raised its findings


@pytest.mark.slow
@pytest.mark.parametrize("executor", ["local", pytest.param("dask", marks=pytest.mark.heavy)])
def test_the_walls_hold_as_root_and_on_dask(breaker_site, tmp_path, executor):
    from rippleb.engine.process.sandbox import missing_protections

    if missing_protections():
        pytest.skip(f"this kernel does not grant {missing_protections()}")
    run = tmp_path / "run"
    proc = _cli(tmp_path, breaker_site, "run", "--methods", f"raw,{_breaker(run)}", "--scenarios", "static-contact",
                "--seeds", "1", "--jobs", "2", "--no-progress", "--executor", executor, "--out", run)
    assert proc.returncode == 0, proc.stderr
    _assert_walls_held(_found(run), run)
    rows = _rows(run)
    assert rows["raw"]["status"] == "ok" and rows[_breaker(run)]["status"] == "error"
    import rippleb

    clean = rippleb.run(["raw"], ["static-contact"], [0], progress=False)   # raw alone, no breaker beside it
    assert float(rows["raw"]["rms_error_nm"]) == clean.rms_error_nm.iloc[0]


@pytest.mark.slow
def test_the_walls_hold_for_an_unprivileged_user(breaker_site):
    """The same attacks by a run of uid 65534 (``nobody``): its namespaces, Landlock and
    seccomp are all an unprivileged user's to set up, and none of its protections is missing."""
    import tempfile

    if os.geteuid() != 0:
        pytest.skip("needs root to run as uid 65534")
    home = Path(tempfile.mkdtemp(prefix="rippleb-nobody-"))   # pytest's tmp_path is root's alone
    try:
        shutil.copytree(breaker_site, home / "site")
        for path in [home, *home.rglob("*")]:
            os.chown(path, 65534, 65534)
        env = {**os.environ, "HOME": str(home), "TMPDIR": str(home), "PYTHONPATH": str(home / "site"),
               "RIPPLEB_KEY_FILE": str(home / "key")}
        # setpriv, not subprocess's user=: it changes the ids as it execs, so this Python,
        # under root's home here, can still be started; the run itself is uid 65534's, no capability
        setpriv = shutil.which("setpriv")
        if setpriv is None:
            pytest.skip("no setpriv to start a process as uid 65534")
        proc = subprocess.run([setpriv, "--reuid=65534", "--regid=65534", "--clear-groups", sys.executable, "-m",
                               "rippleb", "run", "--methods", f"raw,{_breaker(home / 'run')}", "--scenarios",
                               "static-contact",
                               "--seeds", "1", "--jobs", "2", "--no-progress", "--out", "run"],
                              capture_output=True, text=True, env=env, cwd=home, timeout=600)
        if proc.returncode != 0 and "Permission denied" in proc.stderr:
            pytest.skip(f"uid 65534 cannot run this Python: {proc.stderr.strip()[-200:]}")
        assert proc.returncode == 0, proc.stderr
        assert "warning" not in proc.stderr, proc.stderr      # every protection granted to nobody too
        _assert_walls_held(_found(home / "run"), home / "run")
        assert _rows(home / "run")["raw"]["status"] == "ok"
    finally:
        shutil.rmtree(home, ignore_errors=True)


def test_a_kernel_that_grants_less_is_said_once_and_refuses_sealed_runs(tmp_path, monkeypatch):
    """Landlock refused (as on a kernel without it): an unsealed run warns once, naming it,
    and its rows run; a sealed run is refused before it claims anything."""
    import warnings

    import rippleb
    from rippleb.engine.process import landlock, sandbox
    from rippleb.errors import InputError

    monkeypatch.setattr(landlock, "restrict", lambda *args, **kwargs: ["Landlock (reads and writes confined)"])
    assert sandbox.missing_protections() == ("Landlock (reads and writes confined)",)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        frame = rippleb.run(["raw"], ["static-contact"], [0], progress=False)
    said = [str(w.message) for w in caught if "does not grant" in str(w.message)]
    assert said == ["this kernel does not grant a method's process Landlock (reads and writes confined): it can "
                    "reach more than docs/robustness.md says (sections 10 and 11)"]
    assert frame.status.tolist() == ["ok"]
    with pytest.raises(InputError, match="--sealed needs every wall around a method's process, and this kernel "
                                         "does not grant Landlock"):
        rippleb.run(["raw"], ["static-contact"], [0], out=tmp_path / "run", sealed=tmp_path / "salt", progress=False)
    assert not (tmp_path / "run").exists() and not (tmp_path / "salt").exists()

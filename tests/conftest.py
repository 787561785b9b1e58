"""Test selection: ``python -m pytest`` is the fast default a developer runs after every
change; ``python -m pytest --full`` adds the tests marked ``slow`` (end-to-end runs,
installs, the browser, property fuzzing) and is what CI runs (``.ci/run``)."""

import os

import pytest

# Before any test module loads numpy: the portable numeric paths (rippleb/numerics.py),
# without which the published rows re-run differently on an AVX-512 CPU.
import rippleb  # noqa: F401
from hypothesis import settings
from rippleb.numerics import FAKE_CPU_SWITCH, FAKE_CPUS, other_cpu_kind

#: Files that one xdist worker runs whole: their tests share a module fixture (one run of
#: every case, one plugin install, one simulation) or a cache kept per process, which
#: another worker would compute again. Every other test is handed out on its own.
ONE_WORKER_FILES = {
    "test_bad_input.py",      # `outcomes`: every bad-input case run once
    "test_bandwidth.py",      # the calibration log
    "test_checked_input.py",  # `finished`: one run, reported and resumed by several tests
    "test_dask.py",           # clusters started one test at a time
    "test_faults.py",         # fitted methods and faulty simulations
    "test_kalman_ripple.py",  # fitted filters
    "test_order_tracking.py", # simulations and scores cached per process
    "test_plugins.py",        # the plugins installed once
    "test_publication.py",    # `published`: one sealed run and its report
    "test_hostile.py",        # `finished` and the hostile sites: one run, one install
    "test_integrity.py",      # the hostile site installed once
    "test_walls.py",          # the walls' site installed once
}


#: ``--timeout`` of the tests in which a method hangs on purpose. A healthy row of those
#: tests (its simulation, fit and scoring) takes about 1 s on a quiet 2-core machine and
#: was seen near 6 s, the limit these tests once had, with two full suites beside them:
#: 60 s is ten times that, out of reach of a loaded host, and a hang still costs only the
#: one job slot it holds (docs/reproducibility.md, "Tests and the host").
HANG_TIMEOUT_S = 60

# Hypothesis fails an example that takes over 200 ms by default: a wall-clock limit a
# loaded 2-core machine reaches (a first example that loads a compiled kernel, two suites
# side by side). The property tests check values, never speed: no deadline anywhere.
settings.register_profile("rippleb", deadline=None)
settings.load_profile("rippleb")


def pytest_addoption(parser):
    parser.addoption("--full", action="store_true",
                     help="also run the tests marked slow (the full suite, as CI runs it)")
    parser.addoption("--heavy", action="store_true",
                     help="with --full, also the tests marked heavy: the longest end-to-end runs, which "
                          "CI's 20 minutes on 2 cores cannot hold beside the rest (docs/architecture.md, "
                          "'Tests')")
    parser.addoption("--fake-cpu", choices=[*sorted(FAKE_CPUS), "other"],
                     help="describe this host as a CPU of that kind (other: the kind it is not) to "
                          "every test and the rippleb processes it starts (sets RIPPLEB_FAKE_CPU; "
                          "docs/reproducibility.md, 'Tests and the host'); CI runs "
                          "`python -m pytest -m host --fake-cpu other`")


def pytest_configure(config):
    """Check that the suite runs the portable numeric paths. With --full, compile rippleb's
    numba kernels once, in the controller, before any worker starts: on a fresh checkout
    every process that imports them would compile them itself (about 15 s each), and the
    slow tests that run first start many such processes at once. Later processes load
    them from numba's on-disk cache."""
    fake = config.getoption("--fake-cpu")
    if fake:   # rippleb processes the tests start inherit it
        os.environ[FAKE_CPU_SWITCH] = other_cpu_kind() if fake == "other" else fake
    _check_numerics()
    if config.getoption("--full") and not hasattr(config, "workerinput"):
        from rippleb.engine.dask.worker import _load_modules  # what a Dask worker preloads

        _load_modules()


def _check_numerics():
    """Stop at once if numpy was loaded before rippleb could pin its paths (a plugin that
    imports numpy early): every exact comparison would then depend on this CPU."""
    from rippleb import numerics

    state = numerics.state()
    if state != numerics.PORTABLE and not numerics.native_requested():
        pytest.exit(f"the suite does not run rippleb's portable numeric paths ({state}); "
                    "something imported numpy before rippleb (rippleb/numerics.py)", returncode=3)


def pytest_collection_modifyitems(config, items):
    heavy = [item for item in items if item.get_closest_marker("heavy")]
    if heavy and not (config.getoption("--heavy") or config.option.markexpr):
        config.hook.pytest_deselected(items=heavy)
        items[:] = [item for item in items if not item.get_closest_marker("heavy")]
    if config.getoption("--full") or config.option.markexpr:
        # The slow tests first (stable: files keep their order): xdist hands out single
        # tests in collection order, so a slow test collected late would run alone at
        # the end while the other worker idles.
        items.sort(key=lambda item: item.get_closest_marker("slow") is None)
        return  # the full suite, or the marks the caller chose
    slow = [item for item in items if item.get_closest_marker("slow")]
    if slow:
        config.hook.pytest_deselected(items=slow)
        items[:] = [item for item in items if not item.get_closest_marker("slow")]


def pytest_report_header(config):
    lines = []
    fake = os.environ.get(FAKE_CPU_SWITCH)
    if fake:
        lines.append(f"{FAKE_CPU_SWITCH}={fake}: rippleb describes this host as a CPU of that kind")
    if not (config.getoption("--full") or config.option.markexpr):
        lines.append("fast default: tests marked slow are deselected; run with --full for the whole suite (CI)")
    return lines


def lock_versions() -> dict[str, str]:
    """``{package: version}`` pinned by the repository's ``constraints.txt`` (names lower case)."""
    from pathlib import Path

    lock = {}
    for line in (Path(__file__).resolve().parent.parent / "constraints.txt").read_text().splitlines():
        name, sep, version = line.split("#")[0].strip().partition("==")
        if sep:
            lock[name.lower()] = version
    return lock


def off_lock() -> list[str]:
    """The packages that compute numbers (``rippleb.report.provenance.NUMBER_PRODUCERS``) whose
    installed version is not the one in ``constraints.txt``, as ``name X (lock Y)``.

    Empty in the environment that produced ``results/``: there the published rows and
    pinned log hashes must re-run bit for bit (docs/reproducibility.md); with other
    versions only their last bits may differ, and the exact checks say so and step back.
    """
    from importlib import metadata

    from rippleb.report.provenance import NUMBER_PRODUCERS

    lock = lock_versions()
    off = []
    for name in NUMBER_PRODUCERS:
        try:
            installed = metadata.version(name)
        except metadata.PackageNotFoundError:
            installed = "not installed"
        if installed != lock.get(name):
            off.append(f"{name} {installed} (lock {lock.get(name, 'none')})")
    return off


@pytest.fixture
def register_methods(monkeypatch):
    """``register_methods(*classes)``: for one test, ``Registry.discover`` also finds these
    method classes, as plugins, beside whatever it found before."""
    from rippleb.registry import Entry, Registry

    def register(*classes):
        real = Registry.discover   # what discover finds now, earlier registrations included

        def discover(registry_cls, group="rippleb.methods"):
            found = real(group)
            for method in classes:
                found.entries[method.name] = Entry(method.name, "plugin", "tests", cls=method)
            return found
        monkeypatch.setattr(Registry, "discover", classmethod(discover))
    return register


def pytest_xdist_make_scheduler(config, log):
    """``--dist load`` (the default in pyproject.toml) hands out single tests, except the
    files of :data:`ONE_WORKER_FILES`, each given whole to one worker (and first, being
    the largest units). By file, a long file kept one worker busy while the other idled."""
    if config.getvalue("dist") != "load":
        return None   # xdist's own scheduler for --dist loadfile, loadscope, ...
    from xdist.scheduler import LoadScopeScheduling

    class OneWorkerFiles(LoadScopeScheduling):
        def _split_scope(self, nodeid):
            path = nodeid.split("::", 1)[0]
            return path if path.rsplit("/", 1)[-1] in ONE_WORKER_FILES else nodeid

    return OneWorkerFiles(config, log)


def vouch_for(run_dir) -> None:
    """Record the keyed hashes of ``run_dir``'s rows as they are now (rippleb.integrity),
    as if rippleb had written them: for tests that edit a results file to stand for rows
    made elsewhere (another version, an environmental failure), not to forge them."""
    from pathlib import Path

    from rippleb.integrity import Ledger
    from rippleb.engine.results import read_rows

    Ledger(Path(run_dir)).rewrite(read_rows(Path(run_dir) / "results.csv"))

"""Test selection: ``python -m pytest`` is the fast default a developer runs after every
change; ``python -m pytest --full`` adds the tests marked ``slow`` (end-to-end runs,
installs, the browser, property fuzzing) and is what CI runs (``.ci/run``)."""

import pytest

#: Files that one xdist worker runs whole: their tests share a module fixture (one run of
#: every case, one plugin install, one simulation) or a cache kept per process, which
#: another worker would compute again. Every other test is handed out on its own.
ONE_WORKER_FILES = {
    "test_bad_input.py",      # `outcomes`: every bad-input case run once
    "test_bandwidth.py",      # the calibration log
    "test_dask.py",           # clusters started one test at a time
    "test_faults.py",         # fitted methods and faulty simulations
    "test_kalman_ripple.py",  # fitted filters
    "test_order_tracking.py", # simulations and scores cached per process
    "test_plugins.py",        # the plugins installed once
}


def pytest_addoption(parser):
    parser.addoption("--full", action="store_true",
                     help="also run the tests marked slow (the full suite, as CI runs it)")


def pytest_configure(config):
    """With --full, compile rippleb's numba kernels once, in the controller, before any
    worker starts: on a fresh checkout every process that imports them would compile them
    itself (about 15 s each), and the slow tests that run first start many such processes
    at once. Later processes load them from numba's on-disk cache."""
    if config.getoption("--full") and not hasattr(config, "workerinput"):
        from rippleb.dask_worker import _load_modules  # what a Dask worker preloads

        _load_modules()


def pytest_collection_modifyitems(config, items):
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
    if not (config.getoption("--full") or config.option.markexpr):
        return "fast default: tests marked slow are deselected; run with --full for the whole suite (CI)"
    return None


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

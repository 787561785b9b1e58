"""Test selection: ``python -m pytest`` is the fast default a developer runs after every
change; ``python -m pytest --full`` adds the tests marked ``slow`` (end-to-end runs,
installs, the browser, property fuzzing) and is what CI runs (``.ci/run``)."""

import pytest


def pytest_addoption(parser):
    parser.addoption("--full", action="store_true",
                     help="also run the tests marked slow (the full suite, as CI runs it)")


def pytest_collection_modifyitems(config, items):
    if config.getoption("--full") or config.option.markexpr:
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

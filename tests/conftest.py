"""Test selection: ``python -m pytest`` is the fast default a developer runs after every
change; ``python -m pytest --full`` adds the tests marked ``slow`` (end-to-end runs,
installs, the browser, property fuzzing) and is what CI runs (``.ci/run``)."""


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

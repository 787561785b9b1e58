import importlib.metadata
import sys
import textwrap

import pytest

from rippleb import InputError, PluginError
from rippleb import registry as reg
from rippleb.registry import Registry

BUILTINS = ["raw", "lowpass", "order-tracking", "order-tracking-no-deadzone",
            "order-tracking-no-backprop", "switched-notch", "kalman-ripple", "current-based",
            "spatial-filter", "fourier-lms", "periodic-dob"]


@pytest.fixture
def pkgdir(tmp_path, monkeypatch):
    """A directory on sys.path to write throw-away modules into."""
    monkeypatch.syspath_prepend(str(tmp_path))
    yield tmp_path
    for name in [m for m in sys.modules if m.startswith(("fakeplug", "fakebuiltin"))]:
        del sys.modules[name]


def _module(root, name, body):
    path = root.joinpath(*name.split(".")).with_suffix(".py")
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(textwrap.dedent(body))


def _entry_points(monkeypatch, *specs):
    eps = [importlib.metadata.EntryPoint(name, value, reg.GROUP) for name, value in specs]
    monkeypatch.setattr(importlib.metadata, "entry_points",
                        lambda group=None: [e for e in eps if e.group == group])


PLUGIN = """
    import numpy as np
    from rippleb import Method
    class Zero(Method):
        name = "zero"
        def step(self, block):
            return np.zeros(len(block))
"""


def test_every_builtin_name_of_the_design_is_found():
    found = Registry.discover()
    present = [n for n in BUILTINS if n in found.names("builtin")]
    # the method modules are written in parallel; the baselines must always be there
    assert {"raw", "lowpass"} <= set(present)
    assert not found.broken_modules, found.broken_modules


def test_a_module_may_define_several_methods_and_imports_are_not_counted_twice(pkgdir, monkeypatch):
    _module(pkgdir, "fakebuiltin.__init__", "")
    _module(pkgdir, "fakebuiltin.fam", """
        from rippleb import Method
        from rippleb.methods.raw import Raw   # imported, not defined here
        class A(Method):
            name = "a"
        class B(A):
            name = "a-ablation"
        class _Helper(Method):
            name = ""
    """)
    monkeypatch.setattr(reg, "BUILTIN_PACKAGE", "fakebuiltin")
    assert Registry.discover().names() == ["a", "a-ablation"]


def test_a_broken_builtin_module_costs_only_its_own_methods(pkgdir, monkeypatch):
    _module(pkgdir, "fakebuiltin.__init__", "")
    _module(pkgdir, "fakebuiltin.good", PLUGIN)
    _module(pkgdir, "fakebuiltin.bad", "import numpy\nraise RuntimeError('no licence file\\nmore')\n"
                                       "class Bad:\n    name = 'bad'\n")
    _module(pkgdir, "fakebuiltin.garbled", "class (:\n")
    monkeypatch.setattr(reg, "BUILTIN_PACKAGE", "fakebuiltin")
    found = Registry.discover()
    assert found.names() == ["bad", "zero"]              # read from the source ...
    assert "fakebuiltin.good" not in sys.modules         # ... without importing it
    assert found.get("zero").load().__name__ == "Zero"
    with pytest.raises(PluginError, match="no licence file"):
        found.get("bad").load()
    assert found.get("bad").error == "RuntimeError: no licence file"
    assert list(found.broken_modules) == ["fakebuiltin.garbled"]
    assert found.broken_modules["fakebuiltin.garbled"].startswith("SyntaxError")


def test_plugins_load_lazily_and_broken_ones_show_their_error(pkgdir, monkeypatch):
    _module(pkgdir, "fakeplug_ok", PLUGIN)
    _module(pkgdir, "fakeplug_bad", "raise ImportError('needs torch')\n")
    _module(pkgdir, "fakeplug_notmethod", "class Zero:\n    pass\n")
    _entry_points(monkeypatch, ("zero", "fakeplug_ok:Zero"), ("bad", "fakeplug_bad:X"),
                  ("odd", "fakeplug_notmethod:Zero"))
    found = Registry.discover()
    assert "fakeplug_ok" not in sys.modules          # listing imports nothing
    assert found.get("zero").load().__name__ == "Zero"
    assert found.get("zero").origin == "plugin"
    with pytest.raises(PluginError, match="needs torch"):
        found.get("bad").load()
    found.load_all()
    assert found.get("bad").broken and found.get("odd").broken
    assert "not a rippleb.Method" in found.get("odd").error
    assert "raw" in found.names()                    # built-ins unaffected


def test_two_plugins_with_one_name_are_a_clear_error(pkgdir, monkeypatch):
    _entry_points(monkeypatch, ("raw", "fakeplug_ok:Zero"))
    with pytest.raises(PluginError, match="two methods are named 'raw'"):
        Registry.discover()


def test_two_entry_points_with_one_name_are_a_clear_error(monkeypatch):
    _entry_points(monkeypatch, ("zero", "fakeplug_a:Zero"), ("zero", "fakeplug_b:Zero"))
    with pytest.raises(PluginError, match="fakeplug_a:Zero.*fakeplug_b:Zero"):
        Registry.discover()


def test_unknown_name_suggests_the_closest():
    with pytest.raises(InputError, match=r"unknown method 'lowpas' \(did you mean 'lowpass'\?\)"):
        Registry.discover().get("lowpas")
    with pytest.raises(InputError, match="known:"):
        Registry.discover().get("zzzzzzzz")

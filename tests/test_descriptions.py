"""What `rippleb list` says of each method: a built-in's description, a plugin's docstring summary."""

import re
import subprocess
import sys
import types

import pytest

from rippleb.method import Method, first_line
from rippleb.registry import Registry
from rippleb.variants import parse_value, signature_of

BUILTINS = Registry.discover().names("builtin")


@pytest.mark.parametrize("name", BUILTINS)
def test_every_builtin_has_a_one_line_description_without_markup(name):
    description = Registry.discover().entries[name].description
    assert description and "\n" not in description
    assert "``" not in description and "{" not in description


@pytest.mark.parametrize("name", BUILTINS)
def test_each_value_a_description_states_is_the_constructors_default(name):
    """``(q=30.0)`` in a description is the default of ``q``: a description cannot drift from
    the code it describes, and reads as the variant syntax of --methods."""
    entry = Registry.discover().entries[name]
    cls = entry.load()
    defaults = cls().get_params()
    stated = re.findall(r"\b([a-z_]+)=([^\s,;)]+)", entry.description)
    for param, text in stated:
        assert param in signature_of(cls)["params"], f"{name}: {param} is not a parameter"
        assert parse_value(text) == defaults[param], f"{name}: says {param}={text}, default {defaults[param]!r}"
    # read from the source without importing it, as `rippleb list` does; the class says the same
    assert cls.summary() == entry.description


def test_rippleb_list_shows_every_builtins_description():
    proc = subprocess.run([sys.executable, "-m", "rippleb", "list"], capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr
    flat = " ".join(proc.stdout.split())
    for name in BUILTINS:
        description = " ".join(Registry.discover().entries[name].description.split())
        assert f"{name} builtin {description}" in flat
    assert "order order" not in flat


def test_a_method_without_a_description_is_summarised_by_its_docstring_then_its_modules():
    module = types.ModuleType("plugin_module", "A running median.\n\nMore text.")
    sys.modules["plugin_module"] = module
    try:
        Bare = type("Bare", (Method,), {"__module__": "plugin_module", "name": "bare"})
        Documented = type("Documented", (Method,), {"__module__": "plugin_module", "name": "doc",
                                                    "__doc__": "\n    ``x`` filtered.\n\n    Details."})
        Described = type("Described", (Documented,), {"description": "what it does", "__doc__": "Other."})
        assert Bare.summary() == "A running median."
        assert Documented.summary() == "x filtered."
        assert Described.summary() == "what it does"
    finally:
        del sys.modules["plugin_module"]


def test_first_line_skips_blank_lines_and_reST_quotes():
    assert first_line("\n\n  ``a`` b\n c") == "a b"
    assert first_line(None) == first_line("") == ""

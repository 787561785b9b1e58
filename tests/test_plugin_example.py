"""The README's example plugin and its copy in examples/rippleb-median/ stay one plugin.

The README prints the plugin's files so that a reader can copy them; the directory ships
them so that a reader can install and test them. This checks, without installing
anything, that each file printed in the README is byte for byte the shipped one, and that
no shipped file is left out of the README. Installing it, running its tests and
`rippleb check` on it is tests/test_plugins.py (slow).
"""

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
EXAMPLE = ROOT / "examples" / "rippleb-median"


def readme_files() -> dict[str, str]:
    """``{path inside rippleb-median/: text}`` of every file the README prints."""
    text = (ROOT / "README.md").read_text()
    blocks = re.findall(r"`rippleb-median/([^`]+)`[^`]*?:\n\n```(?:toml|python)\n(.*?)```", text, re.S)
    return dict(blocks)


def shipped_files() -> dict[str, str]:
    return {str(p.relative_to(EXAMPLE)): p.read_text() for p in sorted(EXAMPLE.rglob("*"))
            if p.is_file() and "__pycache__" not in p.parts and not p.name.startswith(".")}


def test_the_readme_prints_every_shipped_file_of_the_example_plugin():
    assert sorted(readme_files()) == sorted(shipped_files()) == \
        ["pyproject.toml", "rippleb_median.py", "tests/test_median.py"]


def test_each_file_printed_in_the_readme_is_the_shipped_one():
    shipped = shipped_files()
    for path, text in readme_files().items():
        assert text == shipped[path], f"README.md and examples/rippleb-median/{path} differ"


def test_the_example_tests_use_the_conformance_kit():
    assert "check_method(Median" in shipped_files()["tests/test_median.py"]


def test_the_readme_walk_installs_what_it_runs():
    """Issue 39: 'pip install ./rippleb-median' then the plugin's pytest found no pytest: the
    walk installs the plugin with its test extra, and that extra holds pytest."""
    import tomllib

    text = (ROOT / "README.md").read_text()
    install = re.search(r"`pip install '\./rippleb-median\[(\w+)\]'`", text)
    assert install is not None and "`python -m pytest rippleb-median/tests`" in text[install.end():]
    extras = tomllib.loads(shipped_files()["pyproject.toml"])["project"]["optional-dependencies"]
    assert any(req.startswith("pytest") for req in extras[install.group(1)])

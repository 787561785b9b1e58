"""The package's shape (docs/architecture.md), checked on the source with :mod:`ast`.

* a module imports only from its own layer or a lower one:
  core < simulator < engine < report < cli < api;
* no import circle between modules (imports inside functions count: a circle that only
  works because one side imports late is still a circle);
* no module imports a private name (``_name``) from another subpackage, nor reaches one as
  an attribute of a module it imported: what a subpackage shares, it makes public;
* no module is longer than :data:`MAX_LINES` lines.

No module is imported here: the checks read the source, so they take milliseconds.
"""

from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1] / "rippleb"
MAX_LINES = 400

#: The layers, lowest first; a module may import from its own layer and the ones before it.
LAYERS = ("core", "simulator", "engine", "report", "cli", "api")
#: Top-level modules outside the core: the package itself, ``python -m rippleb`` and the
#: plugin authors' checks stand on everything. (The scenario modules live in the simulator,
#: a scenario being checked against the arm it names: no exception is needed for them.)
TOP_LEVEL_LAYER = {
    "rippleb": "api",
    "rippleb.__main__": "api",
    "rippleb.testing": "api",
}
SUBPACKAGE_LAYER = {"rippleb.scoring": "core", "rippleb.simulator": "simulator", "rippleb.engine": "engine",
                    "rippleb.report": "report", "rippleb.cli": "cli"}


def module_name(path: Path, root: Path = ROOT) -> str:
    parts = list(path.relative_to(root.parent).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def sources(root: Path = ROOT) -> dict[str, Path]:
    """``{module name: path}`` of every module of the package under ``root``."""
    return {module_name(p, root): p for p in sorted(root.rglob("*.py")) if "__pycache__" not in p.parts}


def subpackage(module: str) -> str:
    """``rippleb.engine`` for ``rippleb.engine.runner``; ``rippleb`` for a top-level module."""
    for package in SUBPACKAGE_LAYER:
        if module == package or module.startswith(package + "."):
            return package
    return "rippleb"


def layer(module: str) -> str:
    if module in TOP_LEVEL_LAYER:
        return TOP_LEVEL_LAYER[module]
    return SUBPACKAGE_LAYER.get(subpackage(module), "core")


def private(name: str) -> bool:
    return name.startswith("_") and not (name.startswith("__") and name.endswith("__"))


def imports(module: str, path: Path, known: set[str]) -> tuple[list[tuple[str, int]], list[tuple[str, str, int]]]:
    """``(edges, names)`` of one module: the rippleb modules it imports, anywhere in its body
    (with the line), and the names it takes from them, imported or reached as attributes."""
    tree = ast.parse(path.read_text(), filename=str(path))
    package = module if path.name == "__init__.py" else module.rpartition(".")[0]
    edges, names, bound = [], [], {}

    def target(base: str, name: str, line: int) -> None:
        full = f"{base}.{name}"
        if full in known:              # `from rippleb.engine import runner`: the module
            edges.append((full, line))
            bound[name] = full
        else:                          # `from rippleb.engine.runner import run`: a name of it
            edges.append((base, line))
            names.append((base, name, line))

    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for alias in node.names:
                if alias.name.split(".")[0] == "rippleb":
                    edges.append((alias.name, node.lineno))
                    if alias.asname:
                        bound[alias.asname] = alias.name
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                anchor = package.split(".")[: len(package.split(".")) - node.level + 1]
                base = ".".join(anchor + ([base] if base else []))
            if base.split(".")[0] != "rippleb":
                continue
            for alias in node.names:
                target(base, alias.name, node.lineno)
                if alias.asname and f"{base}.{alias.name}" in known:
                    bound[alias.asname] = f"{base}.{alias.name}"
        elif isinstance(node, ast.Assign) and any(isinstance(t, ast.Name) and t.id == "_EXPORTS"
                                                  for t in node.targets):
            # rippleb._lazy.lazy_exports: names imported from these modules on first use
            for key, value in zip(node.value.keys, node.value.values):
                edges.append((value.value, node.lineno))
                names.append((value.value, key.value, node.lineno))
    for node in ast.walk(tree):   # `runner._seed_list` on a module imported as `runner`
        if isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name) \
                and node.value.id in bound and private(node.attr):
            names.append((bound[node.value.id], node.attr, node.lineno))
    return [(m, line) for m, line in edges if m in known], names


def graph(root: Path = ROOT):
    found = sources(root)
    known = set(found)
    return found, {m: imports(m, p, known) for m, p in found.items()}


def layer_violations(deps) -> list[str]:
    rank = {name: i for i, name in enumerate(LAYERS)}
    return [f"{m} (layer {layer(m)}) imports {d} (layer {layer(d)}), line {line}"
            for m, (edges, _) in deps.items() for d, line in edges if rank[layer(d)] > rank[layer(m)]]


def cycles(deps) -> list[list[str]]:
    """The import circles: strongly connected components of more than one module (Tarjan)."""
    graph_ = {m: sorted({d for d, _ in edges if d != m}) for m, (edges, _) in deps.items()}
    index, low, stack, on_stack, found = {}, {}, [], set(), []

    def visit(v):
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in graph_[v]:
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                found.append(sorted(component))

    for v in sorted(graph_):
        if v not in index:
            visit(v)
    return found


def private_violations(deps) -> list[str]:
    return [f"{m} takes the private name {name} from {source}, line {line}"
            for m, (_, names) in deps.items() for source, name, line in names
            if private(name) and subpackage(source) != subpackage(m)]


def long_modules(found) -> list[str]:
    lengths = {m: len(p.read_text().splitlines()) for m, p in found.items()}
    return [f"{m}: {n} lines (at most {MAX_LINES})" for m, n in sorted(lengths.items()) if n > MAX_LINES]


def test_no_lower_layer_imports_a_higher_one():
    _, deps = graph()
    found = layer_violations(deps)
    assert not found, "a lower layer imports a higher one (docs/architecture.md):\n" + "\n".join(found)


def test_no_import_circles():
    _, deps = graph()
    found = cycles(deps)
    assert not found, "import circles:\n" + "\n".join(" <-> ".join(c) for c in found)


def test_no_private_name_crosses_a_subpackage():
    _, deps = graph()
    found = private_violations(deps)
    assert not found, "make the name public in its subpackage:\n" + "\n".join(found)


def test_no_module_is_longer_than_the_limit():
    found, _ = graph()
    long = long_modules(found)
    assert not long, "split these along their concepts:\n" + "\n".join(long)


def test_the_checks_see_what_they_forbid(tmp_path):
    """Each check fails on a small package that breaks its rule (so a check that silently
    saw nothing, e.g. after the package moved, would be noticed)."""
    pkg = tmp_path / "rippleb"
    for rel, text in {
        "__init__.py": "",
        "errors.py": "from rippleb.engine.runner import run\n",                      # core -> engine
        "engine/__init__.py": "",
        "engine/runner.py": "def run():\n    from rippleb.engine import rows\n",     # a circle ...
        "engine/rows.py": "from rippleb.engine.runner import run\n",                 # ... of two
        "report/__init__.py": "",
        "report/tables.py": "from rippleb.engine import runner\nrunner._seed_list\n"
                            "from rippleb.engine.rows import _split\n" + "x = 1\n" * MAX_LINES,
    }.items():
        (pkg / rel).parent.mkdir(parents=True, exist_ok=True)
        (pkg / rel).write_text(text)
    found, deps = graph(pkg)
    assert layer_violations(deps) == ["rippleb.errors (layer core) imports rippleb.engine.runner "
                                      "(layer engine), line 1"]
    assert cycles(deps) == [["rippleb.engine.rows", "rippleb.engine.runner"]]
    assert sorted(private_violations(deps)) == [
        "rippleb.report.tables takes the private name _seed_list from rippleb.engine.runner, line 2",
        "rippleb.report.tables takes the private name _split from rippleb.engine.rows, line 3"]
    assert long_modules(found) == [f"rippleb.report.tables: {MAX_LINES + 3} lines (at most {MAX_LINES})"]


#: The subpackages in the order docs/architecture.md's tree lists them: lowest layer first.
TREE_ORDER = ("scoring", "simulator", "engine", "report", "cli")
#: Written by setuptools-scm at install time, not part of the source (.gitignore).
GENERATED = {"_version.py"}


def _tree_entries(folder: Path, prefix: str) -> list[str]:
    """The tree lines of ``folder``'s modules and subfolders (sorted by name): the listing
    in docs/architecture.md. No line counts: they went stale with every change of code, and
    the length limit is :func:`test_no_module_is_longer_than_the_limit`'s."""
    children = sorted([p for p in folder.iterdir() if p.suffix == ".py" or
                       (p.is_dir() and (p / "__init__.py").exists())], key=lambda p: p.name)
    out = []
    for i, child in enumerate(children):
        last = i == len(children) - 1
        branch, inner = ("└── ", "    ") if last else ("├── ", "│   ")
        if child.is_dir():
            out.append(f"{prefix}{branch}{child.name}/".ljust(31) + layer(module_name(child / "__init__.py")))
            out += _tree_entries(child, prefix + inner)
        else:
            out.append(f"{prefix}{branch}{child.name}")
    return out


def package_tree(root: Path = ROOT) -> str:
    """docs/architecture.md's tree of the package: the top-level modules with their layer,
    then each subpackage (:data:`TREE_ORDER`) with its modules."""
    top = sorted(p for p in root.glob("*.py") if p.name not in GENERATED)
    lines = [f"{root.name}/"]
    for path in top:
        lines.append(f"├── {path.name}".ljust(33) + layer(module_name(path, root)))
    folders = [root / name for name in TREE_ORDER]
    for i, folder in enumerate(folders):
        last = i == len(folders) - 1
        branch, inner = ("└── ", "    ") if last else ("├── ", "│   ")
        lines.append(f"{branch}{folder.name}/".ljust(31) + layer(module_name(folder / "__init__.py", root)))
        lines += _tree_entries(folder, inner)
    return "\n".join(lines) + "\n"


def _documented_tree(doc: Path) -> str:
    text = doc.read_text()
    start = text.index("```\nrippleb/\n") + 4
    return text[start:text.index("```", start)]


DOC = ROOT.parent / "docs" / "architecture.md"


def test_the_documented_tree_is_the_package():
    """docs/architecture.md's tree (modules and layers) is the source's:
    ``python tests/test_architecture.py`` rewrites it after a change."""
    assert _documented_tree(DOC) == package_tree(), "run: python tests/test_architecture.py"



def _imported_modules(path: Path) -> list[tuple[str, int]]:
    """``(module, line)`` of every import in ``path``, imports inside functions included, and
    of every module loaded by name through ``importlib.util.spec_from_file_location``."""
    found = []
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            found += [(alias.name, node.lineno) for alias in node.names]
        elif isinstance(node, ast.ImportFrom) and node.module and not node.level:
            found.append((node.module, node.lineno))
        elif isinstance(node, ast.Call) and getattr(node.func, "attr", getattr(node.func, "id", None)) \
                == "spec_from_file_location" and node.args and isinstance(node.args[0], ast.Constant):
            found.append((str(node.args[0].value), node.lineno))
    return found


#: The scripts held to the outside rule: the benchmarks and the scripts of docs' tables.
SCRIPT_FOLDERS = ("benchmarks", "docs/tables")


def outside_violations(root: Path = ROOT.parent) -> list[str]:
    """Tests and scripts stand above the package's layers (they may use any module of it),
    with a rule of their own: no file imports a test file (a ``test_*`` module). What tests
    share is in the package ``tests/support/`` (its modules are held to the rule too), the
    fixtures in ``conftest.py``; a script of ``benchmarks/`` or ``docs/tables/`` that needs
    a test's hostile plugin imports it from ``support`` (``support.hostile``,
    ``support.walls``, ``support.bad_inputs``)."""
    def test_files(path: Path) -> list[tuple[str, int]]:
        return [(m, n) for m, n in _imported_modules(path) if m.split(".")[0].startswith("test_")]

    out = []
    tests = root / "tests"
    for path in sorted([*tests.glob("*.py"), *tests.glob("support/*.py")]):
        out += [f"{path.relative_to(root)} imports the test file {m}, line {n}: share it through tests/support/"
                for m, n in test_files(path)]
    for folder in SCRIPT_FOLDERS:
        for path in sorted((root / folder).glob("*.py")):
            out += [f"{path.relative_to(root)} imports the test file {m}, line {n}: import it from tests/support/"
                    for m, n in test_files(path)]
    return out


def test_no_test_file_or_script_imports_a_test_file():
    found = outside_violations()
    assert not found, "\n".join(found)


def test_the_outside_rules_see_what_they_forbid(tmp_path):
    """The rule fails on a test file, a support module, a benchmark and a table script that
    each import a test file (the last by path), and passes what they may import."""
    for rel, text in {
        "tests/test_a.py": "def f():\n    from test_b import x\n",
        "tests/test_b.py": "from support.hostile import PROBER\nimport support\n",
        "tests/support/__init__.py": "import rippleb\n",
        "tests/support/hostile.py": "import test_b\n",
        "benchmarks/bench_x.py": "import sys\nfrom support import install_dist\nfrom test_walls import PROBER\n",
        "benchmarks/fine.py": "from support.walls import walls_cli\nimport rippleb\n",
        "docs/tables/x_table.py": "import importlib.util\n"
                                  "spec = importlib.util.spec_from_file_location('test_bad_input', 'p')\n",
        "docs/tables/y_table.py": "import importlib.util\n"
                                  "spec = importlib.util.spec_from_file_location('fault_table', 'p')\n",
    }.items():
        (tmp_path / rel).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / rel).write_text(text)
    assert outside_violations(tmp_path) == [
        "tests/support/hostile.py imports the test file test_b, line 1: share it through tests/support/",
        "tests/test_a.py imports the test file test_b, line 2: share it through tests/support/",
        "benchmarks/bench_x.py imports the test file test_walls, line 3: import it from tests/support/",
        "docs/tables/x_table.py imports the test file test_bad_input, line 2: import it from tests/support/"]


if __name__ == "__main__":
    text = DOC.read_text()
    DOC.write_text(text.replace(_documented_tree(DOC), package_tree()))
    print(f"{DOC}: tree rewritten")

"""Discovery of methods: built-ins from ``rippleb.methods`` and third-party entry points.

Built-in methods are the classes that set a string ``name`` at the top level of the
modules of the package ``rippleb.methods`` (the top-level ``methods/`` directory of the
repository), found by reading the modules' source. A module may define several methods.
Third-party methods register in the entry-point group ``rippleb.methods``; the entry
point's name is the method's name. Neither is imported until the method is used (or
listed), so naming the methods costs no import of scipy or of compiled kernels.

A module or entry point that fails to import becomes a *broken* entry with its error as
one line (a built-in module that cannot even be parsed is listed in
``Registry.broken_modules``); the others keep working. Two methods with one name raise
:class:`~rippleb.errors.PluginError`, naming both sources.

Examples
--------
>>> from rippleb.registry import Registry
>>> reg = Registry.discover()
>>> "raw" in reg.names()
True
"""

from __future__ import annotations

import ast
import difflib
import importlib
import importlib.metadata
import importlib.util
import inspect
import pkgutil
import re
from dataclasses import dataclass, field
from pathlib import Path

from rippleb.errors import InputError, PluginError
from rippleb.method import Method

GROUP = "rippleb.methods"
BUILTIN_PACKAGE = "rippleb.methods"


def one_line(exc: BaseException) -> str:
    """``Type: first line of the message``, the way broken plugins are shown."""
    text = str(exc).strip().splitlines()
    return f"{type(exc).__name__}: {text[0]}" if text else type(exc).__name__


@dataclass
class Entry:
    """One method the registry knows about.

    ``origin`` is ``builtin`` or ``plugin``; ``source`` the module (built-in) or
    ``distribution: module:attr`` (plugin); ``error`` the import error of a broken entry;
    ``doc`` the class docstring and ``description`` the ``description`` attribute of a
    built-in, read from its source (no import needed).
    """

    name: str
    origin: str
    source: str
    cls: type | None = None
    error: str | None = None
    doc: str | None = None
    description: str = ""
    _entry_point: object = field(default=None, repr=False)

    @property
    def broken(self) -> bool:
        """True once loading has failed."""
        return self.error is not None

    @property
    def module(self) -> str:
        """The module that holds the method, named without importing it (what its process
        may read, :mod:`rippleb.engine.process.landlock`)."""
        if self.cls is not None:
            return self.cls.__module__
        return getattr(self._entry_point, "module", None) or self.source.rpartition(" ")[2].partition(":")[0]

    def load(self) -> type:
        """The method class, importing a plugin on first use.

        Raises
        ------
        PluginError
            If the plugin fails to import or is not a ``Method`` subclass.
        """
        if self.cls is None and self.error is None:
            try:
                obj = self._entry_point.load()
            except BaseException as exc:  # a plugin may raise anything at import, even SystemExit
                if isinstance(exc, KeyboardInterrupt):
                    raise
                self.error = one_line(exc)
            else:
                if not (inspect.isclass(obj) and issubclass(obj, Method)):
                    self.error = f"TypeError: {self.source} is not a rippleb.Method subclass"
                else:
                    self.cls = obj
        if self.error is not None:
            raise PluginError(f"method {self.name!r} ({self.source}) is broken: {self.error}")
        return self.cls


class Registry:
    """Every method by name; build with :meth:`discover`.

    Parameters
    ----------
    entries
        Method entries by name.
    broken_modules
        Built-in modules that failed to import, as ``{module: error}``; their
        method names are unknown, so they cannot be run.
    """

    def __init__(self, entries: dict[str, Entry], broken_modules: dict[str, str]):
        self.entries = entries
        self.broken_modules = broken_modules

    @classmethod
    def discover(cls, group: str = GROUP) -> "Registry":
        """List the built-in methods (read from their source) and the entry points, importing neither."""
        entries, broken = _builtin_entries()
        for entry in _plugin_entries(group):
            if entry.name in entries:
                other = entries[entry.name]
                raise PluginError(f"two methods are named {entry.name!r}: "
                                  f"{other.source} ({other.origin}) and {entry.source} ({entry.origin})")
            entries[entry.name] = entry
        return cls(entries, broken)

    def names(self, origin: str | None = None) -> list[str]:
        """Method names, sorted; only those of ``origin`` (builtin/plugin) if given."""
        return sorted(n for n, e in self.entries.items() if origin is None or e.origin == origin)

    def get(self, name: str) -> Entry:
        """The entry named ``name``; unknown names raise :class:`InputError` with a suggestion."""
        try:
            return self.entries[name]
        except KeyError:
            raise InputError(unknown_name("method", name, self.names())) from None

    def load_builtins(self, names=None) -> None:
        """Import the built-in methods (all, or those of ``names``): rippleb's own code,
        loaded ahead in a process that forks rows so that they inherit it. Plugins are
        never imported here; a broken built-in keeps its error for its rows."""
        _load_quietly(e for n, e in self.entries.items()
                      if e.origin == "builtin" and (names is None or n in names))

    def load_all(self) -> None:
        """Import every plugin so that broken ones show their error (for ``rippleb list``)."""
        _load_quietly(self.entries.values())


def _load_quietly(entries) -> None:
    """Load each entry; a broken one keeps its error (``Entry.error``) instead of raising."""
    for entry in entries:
        try:
            entry.load()
        except PluginError:
            pass


def unknown_name(kind: str, name: str, known: list[str]) -> str:
    """``unknown method 'rwa' (did you mean 'raw'?)`` as one sentence."""
    close = difflib.get_close_matches(name, known, n=1, cutoff=0.5)
    hint = f"did you mean {close[0]!r}?" if close else f"known: {', '.join(known) or 'none'}"
    return f"unknown {kind} {name!r} ({hint})"


def _builtin_entries() -> tuple[dict[str, Entry], dict[str, str]]:
    """The built-in methods, found by reading their modules' source, not importing them:
    importing every family (scipy.signal, numba kernels) cost each CLI call about 2 s
    before it could even say a name is unknown. A class is a method if it sets a string
    ``name``; it is imported on first :meth:`Entry.load`, like a plugin."""
    package = importlib.util.find_spec(BUILTIN_PACKAGE)
    entries: dict[str, Entry] = {}
    broken: dict[str, str] = {}
    for info in sorted(pkgutil.iter_modules(package.submodule_search_locations), key=lambda i: i.name):
        if info.name.startswith("_"):
            continue
        module_name = f"{BUILTIN_PACKAGE}.{info.name}"
        try:
            found = _method_classes(importlib.util.find_spec(module_name).origin)
        except (OSError, SyntaxError, ValueError) as exc:
            broken[module_name] = one_line(exc)
            continue
        for name, class_name, doc, description in found:
            check_method_name(name, module_name)
            if name in entries:
                raise PluginError(f"two methods are named {name!r}: "
                                  f"{entries[name].source} and {module_name}")
            point = importlib.metadata.EntryPoint(name, f"{module_name}:{class_name}", GROUP)
            entries[name] = Entry(name, "builtin", module_name, doc=doc, description=description,
                                  _entry_point=point)
    return entries, broken


def _method_classes(path: str) -> list[tuple[str, str, str | None, str]]:
    """``(method name, class name, class docstring, description)`` of every top-level class
    of the module at ``path`` that sets ``name = "..."`` in its body."""
    tree = ast.parse(Path(path).read_text(encoding="utf-8"), filename=path)
    found = []
    for node in tree.body:
        if isinstance(node, ast.ClassDef):
            strings = _class_strings(node)
            if strings.get("name"):
                found.append((strings["name"], node.name, ast.get_docstring(node), strings.get("description", "")))
    return found


def _class_strings(node: ast.ClassDef) -> dict[str, str]:
    """The class attributes of ``node`` set to a string literal: ``{"name": ..., ...}``."""
    strings = {}
    for statement in node.body:
        if (isinstance(statement, ast.Assign) and len(statement.targets) == 1
                and isinstance(statement.targets[0], ast.Name)
                and isinstance(statement.value, ast.Constant) and isinstance(statement.value.value, str)):
            strings[statement.targets[0].id] = statement.value.value
    return strings


#: A method name: letters, digits, '-' and '_', starting with a letter or '_' (a Python
#: identifier that may hold dashes). Anything else could not be selected unambiguously
#: (``--methods a,b`` splits on commas) or named safely in a file.
NAME_PATTERN = re.compile(r"[A-Za-z_][A-Za-z0-9_-]*")
#: Names ``--methods`` gives a meaning of its own.
RESERVED_NAMES = ("all",)


def check_method_name(name: str, source: str) -> None:
    """Refuse a method name that ``--methods`` could not select, naming the plugin."""
    if name.lower() in RESERVED_NAMES:
        raise PluginError(f"method {name!r} ({source}): {name!r} is reserved (--methods {name} means "
                          f"every method); rename its entry point")
    if not NAME_PATTERN.fullmatch(name):
        raise PluginError(f"method {name!r} ({source}): a method name is letters, digits, '-' and '_', "
                          f"starting with a letter; rename its entry point")


def _plugin_entries(group: str) -> list[Entry]:
    found: dict[str, Entry] = {}
    for ep in importlib.metadata.entry_points(group=group):
        dist = getattr(ep.dist, "name", None) or "?"
        source = f"{dist}: {ep.value}"
        check_method_name(ep.name, source)
        if ep.name in found and found[ep.name].source != source:
            raise PluginError(f"two methods are named {ep.name!r}: "
                              f"{found[ep.name].source} (plugin) and {source} (plugin)")
        found[ep.name] = Entry(ep.name, "plugin", source, _entry_point=ep)
    return list(found.values())

"""Method variants: a method with constructor parameters, named in benchopt's syntax.

``order-tracking[q=20,30]`` names two variants of ``order-tracking``, one with ``q=20``
and one with ``q=30``. The grammar of one item of ``--methods``::

    NAME                                   the method with its defaults
    NAME[P=V]                              one parameter
    NAME[P=V1,V2,...]  or  NAME[P=[V1,V2]] one variant per value (benchopt's list form too)
    NAME[P=V1,V2,Q=W1,W2]                  every combination (the cartesian product), in the
                                           order written: P varies slowest

Inside the brackets a token with ``=`` starts a parameter and a token without one is one
more value of the parameter before it. A value is a TOML literal (``20``, ``0.5``,
``true``, ``"text"``), else a Python one (``True``, ``'text'``), else a bare word read as
a string (``kind=cd``, as benchopt reads it).

Each variant is its own set of rows, labelled by :func:`label` (``order-tracking[q=20]``,
the parameters in the order written). The label is the ``method`` column of its rows and
the unit a run plans, fits and resumes; :func:`parse_label` reads it back into the method's
name and parameters, so ``run.json`` and ``results.csv`` need nothing else.

Examples
--------
>>> [v.label for v in parse_methods("raw,order-tracking[q=20,30]")]
['raw', 'order-tracking[q=20]', 'order-tracking[q=30]']
>>> parse_label("lowpass[cutoff_hz=50.0,order=4]")
Variant(name='lowpass', params={'cutoff_hz': 50.0, 'order': 4})
"""

from __future__ import annotations

import ast
import inspect
import itertools
import json
import math
import re
import tomllib
from dataclasses import dataclass, field

from rippleb.errors import InputError
from rippleb.registry import unknown_name

#: The types a parameter value may have on the command line.
VALUE_TYPES = (bool, int, float, str)
#: Most variants one ``--methods`` may name, counted before any is made: the tuning protocol
#: tries 16 points a method, a grid of three parameters at ten values each is 1000; a grid
#: of 1e9 points had been expanded in memory (3.6 GB) before anything was checked.
MAX_VARIANTS = 1000
#: Longest ``--methods`` text, and longest text of one value: a label is a row's name.
MAX_METHODS_CHARS = 64 * 1024
MAX_VALUE_CHARS = 1000
#: An integer value fits a signed 64-bit integer (what numpy and every C library take).
MAX_INT = 2**63 - 1
_BARE_WORD = re.compile(r"[A-Za-z_][A-Za-z0-9_.-]*")
_PARAM = re.compile(r"\s*([A-Za-z_][A-Za-z0-9_]*)\s*=(.*)", re.S)


@dataclass(frozen=True)
class Variant:
    """One method with the constructor parameters it runs with.

    Parameters
    ----------
    name
        The registered method name.
    params
        Constructor keyword arguments, in the order written; empty for the defaults.
    """

    name: str
    params: dict = field(default_factory=dict, hash=False)

    @property
    def label(self) -> str:
        """The name of the variant's rows: ``order-tracking[q=20]``, or the bare name."""
        return label(self.name, self.params)


def label(name: str, params: dict) -> str:
    """``name[p=v,...]`` with each value written so that :func:`parse_label` reads it back."""
    if not params:
        return name
    return f"{name}[{','.join(f'{k}={format_value(v)}' for k, v in params.items())}]"


def format_value(value) -> str:
    """A value as it is written in a label: TOML's spelling of numbers and booleans; a
    string bare when it reads back as itself, else quoted."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, (int, float)):
        return repr(value)
    text = str(value)
    if _BARE_WORD.fullmatch(text) and parse_value(text) == text:
        return text
    return json.dumps(text, ensure_ascii=False)


def parse_value(text: str):
    """A literal: TOML's first (``true``, ``1e-3``, ``"x"``), then Python's (``True``,
    ``'x'``), else the text itself, a bare word (:class:`InputError` otherwise)."""
    text = text.strip()
    if len(text) > MAX_VALUE_CHARS:
        raise InputError(f"a value of {len(text)} characters, more than the {MAX_VALUE_CHARS} one may have")
    try:
        return _bounded(tomllib.loads(f"v = {text}")["v"], text)
    except tomllib.TOMLDecodeError:
        pass
    except (ValueError, RecursionError) as exc:   # an integer of more than 4300 digits, say
        if isinstance(exc, InputError):
            raise
    try:
        value = ast.literal_eval(text)
    except (ValueError, SyntaxError, MemoryError, RecursionError, TypeError):
        pass
    else:
        return _bounded(value, text)
    if _BARE_WORD.fullmatch(text):
        return text
    raise InputError(f"{text[:60]!r} is not a value (a number, true/false, or a quoted string)")


def _bounded(value, text: str):
    """``value`` if every number in it is finite and every integer fits 64 bits; else one line."""
    for v in value if isinstance(value, list) else [value]:
        if isinstance(v, bool):
            continue
        if isinstance(v, int) and abs(v) > MAX_INT:
            raise InputError(f"{text[:40]!r}: an integer beyond 64 bits (+-{MAX_INT})")
        if isinstance(v, float) and not math.isfinite(v):
            raise InputError(f"{text[:40]!r}: {v} is not a finite number")
    return value


def split_top_level(text: str) -> list[str]:
    """``text`` split at the commas outside brackets and quotes (a backslash escapes a quote)."""
    parts, depth, quote, start, escaped = [], 0, "", 0, False
    for i, char in enumerate(text):
        if quote:
            quote = "" if char == quote and not escaped else quote
            escaped = char == "\\" and not escaped
        elif char in "\"'":
            quote = char
        elif char == "[":
            depth += 1
        elif char == "]":
            depth -= 1
        elif char == "," and depth == 0:
            parts.append(text[start:i])
            start = i + 1
    parts.append(text[start:])
    return parts


def parse_methods(methods) -> list[Variant]:
    """Every variant of a ``--methods`` value (``"a,b[p=1,2]"`` or a list of items), in the
    order written, without repeats."""
    if isinstance(methods, str) and len(methods) > MAX_METHODS_CHARS:
        raise InputError(f"--methods: {len(methods)} characters, more than the {MAX_METHODS_CHARS} it may have")
    items = split_top_level(methods) if isinstance(methods, str) else list(methods)
    grids = [(str(item).strip(), _grid_of(str(item).strip())) for item in items if str(item).strip()]
    count = sum(_size(grid) for _, grid in grids)   # before any variant is made
    if count > MAX_VARIANTS:
        raise InputError(f"--methods names {count:.4g} variants, more than the {MAX_VARIANTS} a run may have "
                         f"(docs/robustness.md, section 11); run a grid that large in parts")
    variants = [v for item, grid in grids for v in _variants(item, grid)]
    return list({v.label: v for v in variants}.values())


def parse_label(text: str) -> Variant:
    """The one variant a label (or a ``--methods`` item) names; :class:`InputError` if it
    names several."""
    variants = parse_item(text)
    if len(variants) != 1:
        raise InputError(f"method {text!r} names {len(variants)} variants; give one value per parameter")
    return variants[0]


def split_label(text: str) -> tuple[str, dict]:
    """``(method name, params)`` of a row's label, as the jobs take them."""
    variant = parse_label(text)
    return variant.name, dict(variant.params)


def parse_item(item: str) -> list[Variant]:
    """The variants of one ``--methods`` item: ``NAME`` or ``NAME[...]``."""
    grid = _grid_of(item)
    if _size(grid) > MAX_VARIANTS:
        raise InputError(f"method {item[:60]!r} names {_size(grid):.4g} variants, more than the {MAX_VARIANTS} "
                         f"a run may have")
    return _variants(item, grid)


def _grid_of(item: str) -> dict | None:
    """``{parameter: [values]}`` of one item (None for a bare name), nothing expanded yet."""
    name, bracket, rest = item.partition("[")
    name = name.strip()
    if not bracket:
        return None
    if not rest.endswith("]"):
        raise InputError(f"method {item[:60]!r}: the parameters in brackets must end the item "
                         f"(e.g. {name}[q=20,30])")
    return _parameter_grid(name, rest[:-1])


def _size(grid: dict | None) -> int:
    return math.prod(len(values) for values in grid.values()) if grid else 1


def _variants(item: str, grid: dict | None) -> list[Variant]:
    name = item.partition("[")[0].strip()
    if grid is None:
        return [Variant(name)]
    names = list(grid)
    return [Variant(name, dict(zip(names, values))) for values in itertools.product(*grid.values())]


def _parameter_grid(method: str, inside: str) -> dict[str, list]:
    """``{parameter: [values]}`` of the text inside one pair of brackets."""
    grid: dict[str, list] = {}
    current = None
    for token in split_top_level(inside):
        match = _PARAM.fullmatch(token)
        if match:
            current, text = match.group(1), match.group(2)
            if current in grid:
                raise InputError(f"method {method!r}: parameter {current!r} is given twice")
            grid[current] = []
        elif current is None:
            raise InputError(f"method {method!r}: {token.strip()!r} has no parameter name "
                             f"(write {method}[name=value])")
        else:
            text = token
        grid[current].extend(_values(method, current, text))
    return grid


def _values(method: str, param: str, text: str) -> list:
    try:
        value = parse_value(text)
    except InputError as exc:
        raise InputError(f"method {method!r}: parameter {param!r}: {exc}") from None
    values = value if isinstance(value, list) else [value]
    if not values:  # `p=[]` would silently select no variant at all
        raise InputError(f"method {method!r}: parameter {param!r} has no value")
    for v in values:
        if not isinstance(v, VALUE_TYPES):
            raise InputError(f"method {method!r}: parameter {param!r}: {v!r} is {_a(type(v).__name__)}; "
                             f"a value is a number, true/false or a string")
    return values


def check_params(variant: Variant, signature: dict) -> None:
    """Refuse a parameter the method's constructor does not take, or a value of another
    type than its default, in one line naming the method and the parameter.

    Parameters
    ----------
    variant
        The variant to check.
    signature
        ``{"params": {name: type name of the default, or None}, "kwargs": accepts
        **kwargs}``, as :func:`signature_of` gives it.
    """
    known = signature["params"]
    for param, value in variant.params.items():
        if param not in known:
            if signature.get("kwargs"):
                continue
            raise InputError(f"method {variant.name!r}: " + unknown_name("parameter", param, list(known)))
        expected = known[param]
        if expected is not None and not _fits(value, expected):
            raise InputError(f"method {variant.name!r}: parameter {param!r} = {format_value(value)}: "
                             f"expected {_a(expected)} (the type of its default), got {_a(type(value).__name__)}")


def _a(type_name: str) -> str:
    """``a float``, ``an int``."""
    return f"{'an' if type_name[0] in 'aeiou' else 'a'} {type_name}"


def _fits(value, expected: str) -> bool:
    if expected == "float":  # an integer is a float value too (q=20 for q=30.0)
        return isinstance(value, (int, float)) and not isinstance(value, bool)
    return type(value).__name__ == expected


def signature_of(cls) -> dict:
    """What :func:`check_params` needs of ``cls``'s constructor, as plain JSON data (a child
    process sends it back): ``{"params": {name: type name of its default, or None when it
    has none or it is None}, "kwargs": whether it takes **kwargs}``."""
    params, kwargs = {}, False
    if cls.__init__ is object.__init__:  # no constructor of its own: it takes no parameter
        return {"params": params, "kwargs": kwargs}
    for p in list(inspect.signature(cls.__init__).parameters.values())[1:]:
        if p.kind is p.VAR_KEYWORD:
            kwargs = True
        elif p.kind is not p.VAR_POSITIONAL:
            empty = p.default is p.empty or p.default is None
            params[p.name] = None if empty else type(p.default).__name__
    return {"params": params, "kwargs": kwargs}

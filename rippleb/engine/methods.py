"""The methods of a run: ``--methods`` resolved into variants, their parameters checked.

A variant (:mod:`rippleb.variants`, ``order-tracking[q=20]``) is the unit a run plans,
fits, keys and resumes: its label is the ``method`` of its rows. Its parameters are checked
against the method's constructor before anything runs, so a misspelt parameter or a value
of the wrong type is one line and exit 2, not a column of ``error`` rows. The constructor is
read in an isolated child (:func:`probe`), as ``rippleb list`` imports plugins: the process
that plans a run never imports a plugin's code.
"""

from __future__ import annotations

import json
import os

from rippleb.errors import InputError, PluginError
from rippleb.registry import Registry
from rippleb.variants import Variant, check_params, parse_label, parse_methods, signature_of

#: Seconds a method may take to import when its constructor is read: a first import on a
#: fresh install compiles the built-in kernels (5-20 s, more on a loaded machine).
SIGNATURE_TIMEOUT_S = 120.0


def resolve_methods(registry: Registry, methods, timeout: float = SIGNATURE_TIMEOUT_S) -> list[str]:
    """The labels of the variants to run; unknown names raise :class:`InputError` with a
    suggestion, and so do unknown parameters and values of the wrong type.

    Parameters
    ----------
    registry
        The methods this process can run.
    methods
        A list of items or ``"a,b[p=1,2]"`` (:func:`rippleb.variants.parse_methods`); None for
        every built-in, ``"all"`` for every method.
    timeout
        Seconds each method with parameters may take to import in its child.
    """
    variants = parse_methods(methods) if methods is not None else []
    if methods is not None and not variants:
        raise InputError("--methods is empty; give method names or 'all'")
    if not variants:
        return registry.names("builtin")
    if [v.label for v in variants] == ["all"]:
        return registry.names()
    for variant in variants:
        registry.get(variant.name)
    check_variants(registry, [v for v in variants if v.params], timeout)
    return [v.label for v in variants]


def check_variants(registry: Registry, variants: list[Variant], timeout: float) -> None:
    """Check each variant's parameters against its method's constructor (read in a child)."""
    if not variants:
        return
    names = sorted({v.name for v in variants})
    signatures, errors = probe(registry, names, _signature_bytes, timeout)
    for variant in variants:
        if variant.name in errors:
            raise PluginError(f"method {variant.name!r}: cannot read its parameters: {errors[variant.name]}")
        check_params(variant, json.loads(signatures[variant.name]))


def _signature_bytes(entry) -> bytes:
    return json.dumps(signature_of(entry.load())).encode()


def base_name(label: str) -> str:
    """The registered method a row's label runs (``order-tracking`` of ``order-tracking[q=20]``)."""
    return parse_label(label).name


def probe(registry: Registry, names: list[str], read, timeout: float | None):
    """Run ``read(entry) -> bytes`` for each method of ``names`` in its own isolated child,
    behind the walls of a method's process (:mod:`rippleb.engine.process.sandbox`), under
    ``timeout`` seconds each; return ``({name: bytes}, {name: one-line error})``. The calling
    process never runs a plugin's code, so one that hangs or exits at import delays only
    itself."""
    from rippleb.engine.process.isolation import Confinement
    from rippleb.engine.process.landlock import package_paths
    from rippleb.engine.process.pool import Pool

    def job(entry):
        return lambda: read(entry)

    pool, done, errors = Pool(max(1, min(len(names), os.cpu_count() or 1))), {}, {}
    pending = list(names)
    while pending or pool.busy:
        while pending and pool.free:
            name = pending.pop(0)
            entry = registry.get(name)
            pool.submit(name, job(entry), timeout, confine=Confinement(readable=package_paths(entry.module)))
        for fin in pool.wait():
            if fin.kind == "done":
                done[fin.key] = bytes(fin.value)
            elif fin.kind == "raised":
                errors[fin.key] = fin.value.split("is broken: ", 1)[-1] if PluginError.__name__ in fin.value \
                    else fin.value
            elif fin.kind == "timeout":
                errors[fin.key] = f"TimeoutError: import took longer than {timeout:g} s"
            else:
                errors[fin.key] = f"import ended the process ({fin.kind}: {fin.value})"
    return done, errors

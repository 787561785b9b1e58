"""``rippleb check NAME``: the conformance kit on one installed method, one line per check.

The checks are those of :func:`rippleb.testing.check_method`
(:mod:`rippleb.engine.conformance`), run without pytest. Each runs in the sandboxed worker
of a method, as a run's rows do (:mod:`rippleb.engine.checking`), under ``--timeout`` and
``--memory-limit``: a check that hangs, crashes or ends its process fails with its name,
and the others still run; no plugin code runs in this process. Exit 0 when every check
passes, 1 otherwise, 2 for bad input (an unknown name, a parameter the method does not take).
"""

from __future__ import annotations


def add_check(sub) -> None:
    from rippleb.engine.runner import DEFAULT_MEMORY_MB, DEFAULT_TIMEOUT_S

    p = sub.add_parser("check", help="run the conformance checks on one installed method",
                       description="Check that a method (built-in or plugin) behaves as the runner "
                                   "expects: one finite estimate per sample, determinism, causality, "
                                   "and the same estimate whatever the block size. Runs on 1 s of "
                                   "the stop-restart scenario, calibrated on the calibration scenario "
                                   "(seed 0), each check in the method's sandboxed process, as a run's "
                                   "rows are. One line per check; exit 0 if all pass, 1 if any fails.")
    p.add_argument("name", metavar="NAME",
                   help="a method name, or one variant of it: 'order-tracking[q=20]' (docs/plugins.md)")
    p.add_argument("--timeout", type=float, default=DEFAULT_TIMEOUT_S,
                   help=f"seconds one check may take before it is ended (default {DEFAULT_TIMEOUT_S:g}; 0: none)")
    p.add_argument("--memory-limit", type=float, default=DEFAULT_MEMORY_MB, metavar="MB",
                   help=f"memory one check may allocate, in MB (default {DEFAULT_MEMORY_MB:g}; 0: none)")
    p.set_defaults(func=cmd_check)


def cmd_check(args) -> int:
    """``rippleb check NAME``."""
    from rippleb.cli.options import limit
    from rippleb.engine.checking import SandboxedChecks
    from rippleb.engine.conformance import checks
    from rippleb.engine.methods import SIGNATURE_TIMEOUT_S, probe
    from rippleb.registry import Registry
    from rippleb.variants import check_params, parse_label

    timeout, memory = limit("--timeout", args.timeout), limit("--memory-limit", args.memory_limit)
    variant = parse_label(args.name)
    registry = Registry.discover()
    entry = registry.get(variant.name)
    print(f"rippleb check {variant.label} ({entry.origin}, {entry.source})", flush=True)
    found, errors = probe(registry, [variant.name], _described, SIGNATURE_TIMEOUT_S)
    if variant.name in errors:
        _line(False, "import: the method loads", errors[variant.name])
        return 1
    import json

    described = json.loads(found[variant.name])
    check_params(variant, described["signature"])
    _line(True, f"import: {described['class']} is a rippleb.Method")
    listed = checks()
    with SandboxedChecks(registry, variant.name, variant.params, timeout, memory) as attempt:
        passed = run_checks(attempt, listed)
    total = len(listed) + 1  # and the import
    print(f"{variant.label}: {passed + 1} of {total} checks passed")
    return 0 if passed == len(listed) else 1


def _described(entry) -> bytes:
    """In the method's sandboxed worker: its class's name and its constructor's signature."""
    import json

    from rippleb.variants import signature_of

    cls = entry.load()
    return json.dumps({"class": f"{cls.__module__}.{cls.__qualname__}", "signature": signature_of(cls)}).encode()


def run_checks(attempt, listed) -> int:
    """Run each check of ``listed`` through ``attempt(number) -> '' or why it failed``, one
    line each; return how many passed. When the first (the output, which the others compare
    with) fails, the others are skipped."""
    passed = 0
    for number, (what, _) in enumerate(listed):
        why = attempt(number)
        _line(not why, what, why)
        if why and number == 0:
            for later, _ in listed[1:]:
                print(f"  skip  {later} (needs the output check)")
            return 0
        passed += not why
    return passed


def _line(ok: bool, what: str, why: str = "") -> None:
    from rippleb.printable import escaped

    print(f"  {'ok  ' if ok else 'FAIL'}  {what}" + (f": {escaped(why)}" if why else ""), flush=True)

"""``rippleb check NAME``: the conformance kit on one installed method, one line per check.

The checks are those of :func:`rippleb.testing.check_method`
(:mod:`rippleb.engine.conformance`), run without pytest. The method is imported and run
in this process, as a test of it would; exit 0 when every check passes, 1 otherwise, 2 for
bad input (an unknown name, a parameter the method does not take).
"""

from __future__ import annotations

from rippleb.errors import PluginError


def add_check(sub) -> None:
    p = sub.add_parser("check", help="run the conformance checks on one installed method",
                       description="Check that a method (built-in or plugin) behaves as the runner "
                                   "expects: one finite estimate per sample, determinism, causality, "
                                   "and the same estimate whatever the block size. Runs on 1 s of "
                                   "the stop-restart scenario, calibrated on the calibration scenario "
                                   "(seed 0). One line per check; exit 0 if all pass, 1 if any fails.")
    p.add_argument("name", metavar="NAME",
                   help="a method name, or one variant of it: 'order-tracking[q=20]' (docs/plugins.md)")
    p.set_defaults(func=cmd_check)


def cmd_check(args) -> int:
    """``rippleb check NAME``."""
    from rippleb.engine.conformance import checks, subject
    from rippleb.registry import Registry
    from rippleb.variants import check_params, parse_label, signature_of

    variant = parse_label(args.name)
    entry = Registry.discover().get(variant.name)
    print(f"rippleb check {variant.label} ({entry.origin}, {entry.source})", flush=True)
    try:
        cls = entry.load()
    except PluginError as exc:
        _line(False, "import: the method loads", str(exc))
        return 1
    check_params(variant, signature_of(cls))
    _line(True, f"import: {cls.__module__}.{cls.__qualname__} is a rippleb.Method")
    listed = checks()
    passed = run_checks(subject(cls, variant.params), listed)
    total = len(listed) + 1  # and the import
    print(f"{variant.label}: {passed + 1} of {total} checks passed")
    return 0 if passed == len(listed) else 1


def run_checks(checked, listed) -> int:
    """Run ``listed`` on ``checked``, one line each; return how many passed. When the first
    (the output, which the others compare with) fails, the others are skipped."""
    passed = 0
    for number, (what, check) in enumerate(listed):
        try:
            check(checked)
        except Exception as exc:  # noqa: BLE001 - a method may raise anything; it is one line
            _line(False, what, _message(exc))
            if number == 0:
                for later, _ in listed[1:]:
                    print(f"  skip  {later} (needs the output check)")
                return 0
        else:
            _line(True, what)
            passed += 1
    return passed


def _line(ok: bool, what: str, why: str = "") -> None:
    print(f"  {'ok  ' if ok else 'FAIL'}  {what}" + (f": {why}" if why else ""), flush=True)


def _message(exc: BaseException) -> str:
    """An assertion's own message, or ``Type: first line`` of any other error."""
    from rippleb.registry import one_line

    if isinstance(exc, AssertionError) and str(exc).strip():
        return " ".join(str(exc).split())
    return one_line(exc)

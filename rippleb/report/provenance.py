"""Provenance: what code, software and machine produced a run and its report.

``rippleb run`` records :func:`collect_provenance` in ``DIR/provenance.json``; ``rippleb
report`` adds its own and prints both as a table (:func:`provenance_markdown`).
"""

from __future__ import annotations

import os
import platform
import shlex
import subprocess
import sys
import time
from pathlib import Path

from rippleb.errors import InputError
from rippleb.printable import markdown_code, markdown_text

#: The distributions whose code computes a number of a row: the simulator (numpy, scipy,
#: numba and its llvmlite, Pinocchio and the robot models), the methods (filterpy), and
#: the readers and writers of logs and results (pandas, pyarrow).
NUMBER_PRODUCERS = ("numpy", "scipy", "numba", "llvmlite", "pin", "example-robot-data",
                    "example-robot-data-loaders", "pandas", "pyarrow", "filterpy")

#: The paths whose changes can move a result; a dirty flag over the whole tree would also
#: count notes, docs and results/ itself.
CODE_PATHS = ("rippleb", "methods", "scenarios", "pyproject.toml")


def collect_provenance(argv=None) -> dict:
    """Software, code version and machine, with the command line ``argv`` (without the
    program name) as ``rippleb ...``; what ``rippleb run`` records when it starts."""
    import numpy
    import scipy

    from rippleb.version import __version__
    from rippleb.engine.results import system_info
    from rippleb.tuning import summary as tuning_summary

    return {"command": shlex.join(["rippleb", *(sys.argv[1:] if argv is None else argv)]),
            "cwd": os.getcwd(), "started": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
            "rippleb_version": __version__, **git_state(),
            "python": platform.python_version(), "numpy": numpy.__version__, "scipy": scipy.__version__,
            "pinocchio": _pinocchio_version(), "platform": platform.platform(terse=True),
            "cpu": system_info()["cpu"], "cpu_count": os.cpu_count(), **environment(),
            "tuning": tuning_summary()}


def environment() -> dict:
    """What decides a row's last bits besides rippleb's code: ``versions`` of
    :data:`NUMBER_PRODUCERS` and the ``machine``'s numeric paths
    (:func:`rippleb.numerics.machine`)."""
    from importlib import metadata

    from rippleb import numerics

    versions = {}
    for name in NUMBER_PRODUCERS:
        try:
            versions[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            versions[name] = "not installed"
    return {"versions": versions, "machine": numerics.machine()}


def environment_warnings(frame, run: dict) -> list[str]:
    """One line each when a run's rows were not all produced alike: versions or machine
    changed at a ``--resume`` (recorded in ``run["environment_changes"]``), or the rows
    hold more than one rippleb, Python, numpy or numeric-path value, or rows that did not
    run the portable numeric paths (:mod:`rippleb.numerics`)."""
    changes = run.get("environment_changes")
    out = [f"the run was resumed on another environment ({'; '.join(map(str, change['changes']))}): "
           f"{_portability_note(change)}" for change in (changes if isinstance(changes, list) else [])
           if isinstance(change, dict) and isinstance(change.get("changes"), list)]
    for col in ("rippleb_version", "python", "numpy", "numerics"):
        values = sorted(str(v) for v in frame[col].dropna().unique()) if col in frame else []
        if len(values) > 1:
            out.append(f"the rows were produced with {len(values)} different {col} values "
                       f"({', '.join(values)}); their last bits may differ")
    if "numerics" in frame:
        native = frame["numerics"].dropna().astype(str)
        native = native[native != "portable"]
        if len(native):
            out.append(f"{len(native)} rows ran the host's own numeric paths ({native.iloc[0]}), "
                       "not the portable ones: they may differ in the last bits on another CPU "
                       "(docs/reproducibility.md)")
    return out


def _portability_note(change: dict) -> str:
    if change.get("portable"):
        return "both ran the portable numeric paths, so the CPU does not change the numbers; a version may"
    return "rows of the two parts may differ in their last bits"


def environment_changes(before: dict, after: dict) -> list[str]:
    """``name: before -> after`` for each version or machine entry that differs between
    two provenance records (entries one of them lacks are said to be unrecorded)."""
    changes = []
    for group in ("versions", "machine"):
        old, new = (record.get(group) if isinstance(record.get(group), dict) else {} for record in (before, after))
        for name in sorted(set(old) | set(new)):
            if old.get(name) != new.get(name):
                changes.append(f"{name}: {old.get(name, 'not recorded')} -> {new.get(name, 'not recorded')}")
    return changes


def _pinocchio_version() -> str:
    try:
        import pinocchio
    except Exception as exc:  # the report must still be written without the simulator's dependency
        return f"not importable ({type(exc).__name__})"
    return str(pinocchio.__version__)


def git_state(root: Path | None = None) -> dict:
    """``git_commit`` (HEAD), ``git_dirty`` (uncommitted or untracked changes under
    :data:`CODE_PATHS`) and ``git_dirty_paths`` of the checkout holding rippleb.

    Outside a git checkout (an installed wheel) the commit recorded when the package was
    built (:func:`build_commit`) is used, with ``git_source = "build"``; ``unknown`` if
    the package was built without git either.
    """
    checkout = Path(root) if root is not None else Path(__file__).resolve().parent.parent
    try:
        commit = _git(checkout, "rev-parse", "HEAD").strip()
        status = _git(checkout, "status", "--porcelain", "--", *CODE_PATHS)
    except (OSError, subprocess.CalledProcessError, subprocess.TimeoutExpired):
        built = build_commit() if root is None else None
        if built is None:
            return {"git_commit": "unknown", "git_dirty": "unknown", "git_dirty_paths": []}
        return {"git_commit": built["commit"], "git_dirty": built["dirty"], "git_dirty_paths": [],
                "git_source": "build"}
    paths = [line[3:] for line in status.splitlines() if line.strip()]
    return {"git_commit": commit, "git_dirty": bool(paths), "git_dirty_paths": paths, "git_source": "checkout"}


def build_commit() -> dict | None:
    """The commit setuptools-scm saw when this package was built (``rippleb/_version.py``):
    ``{"commit": short hash, "dirty": bool}``, or None if it was built outside git."""
    from rippleb.version import built

    version, commit = built() or (None, None)
    if not commit:
        return None
    return {"commit": str(commit).removeprefix("g"), "dirty": built_dirty(version)}


def built_dirty(version: str) -> bool:
    """Whether setuptools-scm saw uncommitted changes: it then ends the local version with
    the date, ``.dYYYYMMDD`` (``0.1.1.dev3+gabc1234.d20261122``)."""
    import re

    return re.search(r"\.d\d{8}$", version) is not None


def _git(root: Path, *args: str) -> str:
    """Ask git about the checkout, taking none of its locks.

    ``git status`` otherwise rewrites a stale index under ``.git/index.lock``; a run
    interrupted meanwhile kills it (``subprocess.run`` ends its child on Ctrl-C) and left
    that lock behind, so the user's next ``git commit`` failed (found by
    ``benchmarks/signal_trials.py``). ``GIT_OPTIONAL_LOCKS=0`` is git's switch for such
    read-only callers.
    """
    return subprocess.run(["git", "-C", str(root), *args], check=True, capture_output=True, text=True,
                          timeout=20, env={**os.environ, "GIT_OPTIONAL_LOCKS": "0"}
                          ).stdout  # not stripped: porcelain lines start with a space


def read_run_provenance(run_dir: Path) -> dict:
    """What ``rippleb run`` recorded in ``DIR/provenance.json`` (empty if the run was made
    through the Python API), with the selection of ``DIR/run.json``."""
    from rippleb.reading import RUN_FILE_BYTES, parse_json, read_text

    out = {}
    for name in ("run.json", "provenance.json"):
        path = Path(run_dir) / name
        if path.is_symlink() or path.exists():
            value = parse_json(read_text(path, RUN_FILE_BYTES, "run file", in_run_dir=True), path)
            if not isinstance(value, dict):
                raise InputError(f"{path}: not a rippleb run file (a JSON {type(value).__name__}, "
                                 f"expected an object)")
            out.update(value)
    return out


def provenance_markdown(prov: dict) -> str:
    """The provenance section of the README (values as recorded, none typed). Every value
    comes from a file of the run directory, which anyone who could write it chose: each is
    written as text (:func:`~rippleb.printable.markdown_text`) or code, never as Markdown."""
    from rippleb.report.markdown import markdown

    run, rep = prov.get("run", {}), prov["report"]
    text = markdown_text
    resumes = run.get("resumes", [])
    rows = [["command of the run", _code(run.get("command", "not recorded (run made through the Python API)"))],
            ["resumed with", "; ".join(_code(c) for c in resumes if isinstance(resumes, list)) or "-"],
            ["run started", text(run.get("started", "not recorded"))],
            ["run wall time", _seconds(run["wall_s"]) if "wall_s" in run else "not recorded"],
            ["jobs (rows run in parallel)", text(run.get("jobs", "not recorded"))],
            ["CPUs of the run's machine", text(run.get("cpu_count", "not recorded"))],
            ["seeds", prov["seeds_text"]],
            ["sealed", _sealed_cell(run, prov.get("salt"))],
            ["rippleb", text(run.get("rippleb_version", prov.get("rows_rippleb_version", "not recorded")))],
            ["git commit of the run", text(git_text(run))],
            ["Python", text(run.get("python", prov.get("rows_python", "not recorded")))],
            ["numpy / scipy / pinocchio", " / ".join(text(run.get(k, "not recorded"))
                                                    for k in ("numpy", "scipy", "pinocchio"))],
            ["CPU", text(run.get("cpu", prov.get("rows_cpu", "not recorded")))],
            *machine_rows(run),
            ["platform", text(run.get("platform", "not recorded"))],
            ["command of this report", _code(rep["command"])],
            ["git commit of this report", text(git_text(rep))]]
    return markdown(rows, ["", "value"])


def _seconds(value) -> str:
    """A recorded wall time, or the recorded value as text if it is not a number."""
    try:
        return f"{float(value):.0f} s"
    except (TypeError, ValueError):
        return markdown_text(value)


def environment_sentence(run: dict) -> str:
    """The report's header line on what decides the last bits of its numbers."""
    versions, machine = run.get("versions"), run.get("machine")
    if not versions or not machine:
        return ("Versions and numeric paths of the run: not recorded (a run made before rippleb "
                "recorded them; docs/reproducibility.md).")
    if not isinstance(versions, dict) or not isinstance(machine, dict):
        return "Versions and numeric paths of the run: not readable in its provenance.json."
    names = ", ".join(f"{k} {markdown_text(versions[k])}" for k in ("numpy", "scipy", "numba", "pin")
                      if k in versions)
    if machine.get("numerics") == "portable":
        how = ("portable numeric paths: with these versions (`constraints.txt` for `results/`) every "
               "row re-runs bit for bit on any x86-64 CPU with AVX2, AVX-512 or not")
    else:
        how = (f"the host's own numeric paths ({markdown_text(machine.get('numerics'))}): rows may differ in "
               "their last bits on another CPU")
    return f"Made with {names} on {how} (docs/reproducibility.md; all versions under Provenance)."


def _sealed_cell(run: dict, salt: str | None = None) -> str:
    """The provenance's ``sealed`` cell; ``salt`` names the salt file a report published."""
    from rippleb.engine.sealing import GIVEN

    sealed = run.get("sealed")
    if isinstance(sealed, dict) and sealed.get("commitment"):
        if sealed.get("salt") == GIVEN:
            return f"replayed: devices of a given salt, commitment {markdown_code(sealed['commitment'])}"
        text = f"yes: devices drawn from a secret salt, commitment {markdown_code(sealed['commitment'])}"
        return text + (f"; the salt is published beside this report in {markdown_code(salt)}" if salt else "")
    return "no: public seeds"


def machine_rows(run: dict) -> list[list[str]]:
    """Provenance rows for what decides the last bits: the versions of
    :data:`NUMBER_PRODUCERS`, the CPU's SIMD features and the numeric paths."""
    versions, machine = run.get("versions"), run.get("machine")
    if not versions or not machine:
        return [["versions and numeric paths", "not recorded (a run made before they were recorded)"]]
    if not isinstance(versions, dict) or not isinstance(machine, dict):
        return [["versions and numeric paths", "not readable (not an object in provenance.json)"]]
    text = markdown_text
    return [["versions that compute the numbers", ", ".join(f"{text(k)} {text(v)}" for k, v in versions.items())],
            ["CPU SIMD features (LLVM)", text(machine.get("cpu_simd", "not recorded"))],
            ["numba compiles for", text(machine.get("numba_cpu", "not recorded"))],
            *([["CPU description faked", f"RIPPLEB_FAKE_CPU={text(machine['fake_cpu'])} (a test of the "
                 "description; the numbers came from the real CPU)"]] if machine.get("fake_cpu") else []),
            ["numeric paths", f"{text(machine.get('numerics', 'not recorded'))} (numpy dispatch "
             f"{text(machine.get('numpy_dispatch', '?'))}, OpenBLAS {text(machine.get('openblas', '?'))}, "
             f"{text(machine.get('libc', '?'))})"]]


def _code(text) -> str:
    text = str(text)
    return markdown_code(text) if text and not text.startswith("not recorded") else text


def git_text(info: dict) -> str:
    """One line for the commit and dirty state in ``info`` (as :func:`git_state` returns)."""
    commit = info.get("git_commit")
    if commit is None:
        return "not recorded"
    built = " (recorded when the package was built)" if info.get("git_source") == "build" else ""
    dirty = info.get("git_dirty")
    if dirty is True:
        where = ", ".join(info.get("git_dirty_paths", [])) or "the built tree"
        return f"{commit}{built} with uncommitted changes in {where}"
    return f"{commit}{built}" + ("" if dirty is False else " (dirty state unknown)")


def seeds_text(seeds) -> str:
    """``0-19 (20 seeds)`` for a contiguous range, else the list."""
    seeds = sorted(int(s) for s in set(seeds))
    if not seeds:
        return "none"
    if seeds == list(range(seeds[0], seeds[-1] + 1)):
        span = f"{seeds[0]}" if len(seeds) == 1 else f"{seeds[0]}-{seeds[-1]}"
    else:
        span = ", ".join(map(str, seeds))
    return f"{span} ({len(seeds)} seed{'s' if len(seeds) != 1 else ''})"

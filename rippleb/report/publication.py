"""A sealed publication's salt beside its report, and the re-run that verifies its rows.

The published comparison is a sealed run (``rippleb run --sealed FILE``, docs/report.md):
its devices were drawn from a secret salt that no method and no developer saw. Once the
results are out, the salt is published with them (``rippleb report --salt-file FILE``
writes it to ``OUT/salt.txt`` after checking it against the run's commitment), so that
anyone can re-run any row on the same device and find the same numbers
(:func:`verify`, which compares rows with :func:`compare_rows`); each new publication draws
a new salt, hence new devices.
"""

from __future__ import annotations

import json
import tempfile
from pathlib import Path

import numpy as np

from rippleb.errors import InputError
from rippleb.report.stats import with_condition
from rippleb.report.tables import ACCURACY_COLUMNS

#: The salt's file name beside a published report.
SALT_NAME = "salt.txt"
#: A row's key in a results file.
KEY = ("method", "scenario", "condition", "seed")


def check_salt_destination(run_dir: Path, out: Path) -> None:
    """Refuse to write a salt into the run directory: a later ``--resume`` of that run
    would let its methods read it there."""
    run_dir, out = Path(run_dir).resolve(), Path(out).resolve()
    if out == run_dir or run_dir in out.parents:
        raise InputError(f"--salt-file: the report would put the salt inside the run directory {run_dir}, "
                         f"where the methods of a later --resume could read it; give --out outside it")


def write_salt(out: Path, salt: bytes) -> str:
    """Write ``salt`` as ``OUT/salt.txt`` (64 hex digits) and return its name."""
    from rippleb.files import atomic_path

    with atomic_path(Path(out) / SALT_NAME) as tmp:
        tmp.write_text(salt.hex() + "\n", encoding="ascii")
    return SALT_NAME


def verify_text(salt_name: str) -> str:
    """The README's sentence on how to check any published row, with the salt beside it."""
    return (f"The salt is published beside this report (`{salt_name}`; its SHA-256 is the commitment "
            f"above): re-run any row on the same device with `rippleb run --salt-file {salt_name} "
            f"--methods M --scenarios S --conditions C --seed-start K --seeds 1 --out v` and compare "
            f"it with its row here, which `rippleb.report.publication.verify` does (docs/report.md, "
            f"\"Verifying the publication\").")


def published_salt_file(results_dir) -> Path:
    """The salt file of the publication in ``results_dir``, checked against the commitment
    its ``provenance.json`` records; one line naming what is missing otherwise."""
    from rippleb.engine.sealing import commitment, read_salt

    results_dir = Path(results_dir)
    path, prov_path = results_dir / SALT_NAME, results_dir / "provenance.json"
    try:
        run = json.loads(prov_path.read_text()).get("run", {})
    except (OSError, ValueError) as exc:
        raise InputError(f"{prov_path}: cannot read the publication's provenance: {exc}") from None
    recorded = (run.get("sealed") or {}).get("commitment")
    if not recorded:
        raise InputError(f"{prov_path}: not a sealed publication (no commitment recorded)")
    if not path.is_file():
        raise InputError(f"{path}: the publication's salt is missing (rippleb report --salt-file writes it)")
    if commitment(read_salt(path)) != recorded:
        raise InputError(f"{path}: not the salt of this publication (its SHA-256 differs from {recorded[:19]}...)")
    return path


def rerun(results_dir, keys, *, jobs: int = 1):
    """Re-run rows of the sealed publication in ``results_dir`` on their devices (its
    published salt, checked against its commitment).

    Parameters
    ----------
    results_dir
        A published report directory: ``results.csv``, ``provenance.json``, ``salt.txt``.
    keys
        ``(method, scenario, condition, seed)`` of each row to re-run.
    jobs
        Rows run at once.

    Returns
    -------
    pandas.DataFrame
        The re-run rows, read back from the files the runner wrote, as the published rows
        are read (:func:`read_results_exact`).
    """
    import pandas as pd

    from rippleb.engine.runner import run

    salt = published_salt_file(results_dir)
    fresh = []
    with tempfile.TemporaryDirectory(prefix="rippleb-verify-") as tmp:
        for i, (method, scenario, condition, seed) in enumerate(keys):
            out = Path(tmp) / f"row{i}"
            run([method], [scenario], [int(seed)], conditions=[condition], jobs=jobs, out=out, salt_file=salt)
            fresh.append(read_results_exact(out / "results.csv"))
    return pd.concat(fresh, ignore_index=True)


def verify(results_dir, keys, *, jobs: int = 1, columns=ACCURACY_COLUMNS) -> list[str]:
    """:func:`rerun` the rows ``keys`` of the publication in ``results_dir`` and compare them
    with the published rows in ``columns``, exactly (:func:`compare_rows`).

    Returns
    -------
    list of str
        One line per differing value or missing row; empty when every row re-ran the same.
    """
    published = read_results_exact(Path(results_dir) / "results.csv")
    return compare_rows(published, rerun(results_dir, keys, jobs=jobs), columns=columns)


def read_results_exact(path):
    """A results CSV with every float parsed back to the exact double that was written.

    pandas >= 3 parses with round-trip precision by default (and deprecates the option);
    older pandas needs ``float_precision="round_trip"``, its default may differ in the last bit.
    """
    import pandas as pd

    if int(pd.__version__.split(".")[0]) >= 3:
        return pd.read_csv(path)
    return pd.read_csv(path, float_precision="round_trip")


def compare_rows(published, fresh, columns=ACCURACY_COLUMNS, rtol: dict | None = None) -> list[str]:
    """Differences between the rows of ``fresh`` and the same (method, scenario,
    [condition,] seed) rows of ``published``, in ``columns``, compared exactly (NaN equals
    NaN), or where ``rtol`` names a column's relative tolerance, within it.

    Returns one line per missing row or differing value; empty when they agree.
    """
    rtol = rtol or {}
    published, fresh = with_condition(published), with_condition(fresh)
    keys = ["method", "scenario", "condition", "seed"]
    pub = published.set_index(keys)
    problems = []
    for row in fresh.itertuples(index=False):
        row = row._asdict()
        key = tuple(row[k] for k in keys)
        if key not in pub.index:
            problems.append(f"{key}: not in the published rows")
            continue
        old = pub.loc[key]
        for col in ("status",) + tuple(columns):
            a, b = old[col], row[col]
            if not _same(a, b, rtol.get(col)):
                within = f" (beyond the relative tolerance {rtol[col]:g})" if col in rtol else ""
                problems.append(f"{key} {col}: published {_plain(a)!r}, re-run {_plain(b)!r}{within}")
    return problems


def _same(a, b, rtol: float | None) -> bool:
    both_float = isinstance(a, float) and isinstance(b, float)
    if both_float and np.isnan(a) and np.isnan(b):
        return True
    if rtol is not None and both_float:
        return abs(a - b) <= rtol * abs(a)
    return a == b


def _plain(value):
    """A numpy scalar as the Python number it holds, so messages show ``0.1``, not ``np.float64(0.1)``."""
    return value.item() if isinstance(value, np.generic) else value

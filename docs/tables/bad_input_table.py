"""Every bad input of tests/test_bad_input.py, run through ``python -m rippleb``, as a
Markdown table of the exit status and the stderr line (for docs/robustness.md).

    python docs/tables/bad_input_table.py

The cases are :func:`support.bad_inputs.bad_inputs`, the ones the test runs.
"""

from __future__ import annotations

import os
import subprocess
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "tests"))   # the support package
from support.bad_inputs import bad_inputs  # noqa: E402


def main() -> int:
    print("| bad input | command | exit | stderr (one line) | written |")
    print("|---|---|---|---|---|")
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp)
        cases = bad_inputs(root)
        for name, (argv, site, _) in cases.items():
            before = set(root.rglob("*"))
            env = dict(os.environ)
            if site:
                env["PYTHONPATH"] = os.pathsep.join([str(root / site), env.get("PYTHONPATH", "")])
            proc = subprocess.run([sys.executable, "-m", "rippleb", *argv], cwd=root, env=env,
                                  capture_output=True, text=True, timeout=120)
            written = sorted(str(p.relative_to(root)) for p in set(root.rglob("*")) - before
                             if "__pycache__" not in p.parts)
            line = proc.stderr.strip().replace("|", "\\|").replace(str(root) + "/", "")
            command = "rippleb " + " ".join(a for a in argv if a not in ("--no-progress",))
            print(f"| {name} | `{command}` | {proc.returncode} | {line} | {', '.join(written) or 'nothing'} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())

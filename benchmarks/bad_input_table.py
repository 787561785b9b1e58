"""Every bad input of tests/test_bad_input.py, run through ``python -m rippleb``, as a
Markdown table of the exit status and the stderr line (for docs/robustness.md).

    python benchmarks/bad_input_table.py
"""

from __future__ import annotations

import importlib.util
import os
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def main() -> int:
    spec = importlib.util.spec_from_file_location("test_bad_input", ROOT / "tests" / "test_bad_input.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    print("| bad input | command | exit | stderr (one line) | written |")
    print("|---|---|---|---|---|")
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp)
        cases = module._setup(root)
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

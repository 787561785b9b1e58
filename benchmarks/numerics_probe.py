"""Which numpy functions give other bits on this CPU's native paths than on the portable ones.

    python benchmarks/numerics_probe.py

Evaluates each function on 100 000 fixed arguments in two fresh processes, one with
rippleb's portable numeric paths (numpy's AVX2 loops, ``rippleb/numerics.py``) and one with
``RIPPLEB_NATIVE_NUMERICS=1`` (the loops numpy picks for this CPU), and prints whether the
results agree bit for bit. On a CPU without AVX-512 both are the same paths and everything
agrees; on one with AVX-512 the table of docs/reproducibility.md comes out.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys

FUNCTIONS = ("sin", "cos", "tan", "exp", "log", "tanh", "arctan", "arctan2", "arcsin", "power",
             "cosh", "sinh", "expm1", "log1p", "sqrt", "hypot", "sum", "dot", "cumsum", "mean", "std")

CHILD = r"""
import hashlib, json, sys
import rippleb
import numpy as np
from rippleb import numerics

rng = np.random.default_rng(1)
x, p = rng.uniform(-50, 50, 100_000), rng.uniform(0.01, 10, 100_000)
args = {"arctan2": (x, p), "hypot": (x, p), "power": (p, x / 10), "log": (p,), "sqrt": (p,),
        "log1p": (p,), "arcsin": (x / 51,), "exp": (x / 10,), "cosh": (x / 10,), "sinh": (x / 10,),
        "expm1": (x / 10,), "dot": (x, p)}
out = {"numerics": numerics.state()}
for name in sys.argv[1:]:
    value = np.atleast_1d(getattr(np, name)(*args.get(name, (x,))))
    out[name] = hashlib.sha256(np.ascontiguousarray(value).tobytes()).hexdigest()
print(json.dumps(out))
"""


def probe(native: bool) -> dict:
    env = dict(os.environ)
    env.pop("NPY_DISABLE_CPU_FEATURES", None)
    env.pop("OPENBLAS_CORETYPE", None)
    if native:
        env["RIPPLEB_NATIVE_NUMERICS"] = "1"
    else:
        env.pop("RIPPLEB_NATIVE_NUMERICS", None)
    done = subprocess.run([sys.executable, "-c", CHILD, *FUNCTIONS], env=env, check=True,
                          capture_output=True, text=True)
    return json.loads(done.stdout)


def main() -> None:
    portable, native = probe(False), probe(True)
    print(f"portable: {portable['numerics']}\nnative:   {native['numerics']}\n")
    print("| function | native == portable |\n|---|---|")
    for name in FUNCTIONS:
        print(f"| `{name}` | {'yes' if portable[name] == native[name] else '**no**'} |")


if __name__ == "__main__":
    main()

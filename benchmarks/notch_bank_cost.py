"""What switched-notch's warm bank costs per sample, two ways that a busy machine cannot bend
and one way that it can.

    python benchmarks/notch_bank_cost.py [--against OLD/methods/switched_notch.py] [--calls N]

1. **Cycles, load-free**: the compiled bank loop's machine code (``advance_bank``) goes to
   ``llvm-mca -mcpu=znver3`` (Debian's ``llvm`` package), which models a Zen 3 core and gives
   the cycles of one pass of the hottest loop; divided by the modes and samples that pass
   advances, cycles per 4 modes and sample pair, and per sample over the whole bank. Zen 3
   multiplies on two pipes, and a mode and pair take six multiplies: 3 cycles per 4 modes
   and pair is the floor of this arithmetic.
2. **Fastest calls, same process**: with ``--against``, that file's ``SwitchedNotch`` (e.g.
   a checkout of main) and this one's, fitted on calibration seed 0, stream
   paper-quintic seed 901 in 1-second blocks, alternating call by call; the fastest call of
   each is the one least disturbed by the machine's other jobs. Both outputs must be equal
   bit for bit, or the script says so.
"""

from __future__ import annotations

import argparse
import importlib.util
import os
import re
import subprocess
import sys
import tempfile
import time

import numpy as np


def hot_loop(asm: str) -> list[str]:
    """The instructions of the loop with the most ``vmulpd`` in ``asm`` (the bank's)."""
    best: tuple[int, list[str]] = (0, [])
    label, body = None, []
    for line in asm.splitlines():
        start = re.match(r"^(\.LBB\d+_\d+):", line)
        if start:
            label, body = start.group(1), []
            continue
        text = line.strip()
        if label is None or not text or text.startswith((".", "#")):
            continue
        body.append(text)
        if re.match(r"j\w+\s+" + re.escape(label) + r"$", text):
            best = max(best, (sum("vmulpd" in b for b in body), list(body)), key=lambda x: x[0])
    return best[1]


def cycles(module_file: str) -> str:
    """llvm-mca's cycles of the hot loop of ``advance_bank`` in ``module_file``, compiled
    afresh in a child process with an empty numba cache (cached code cannot be disassembled)."""
    child = (f"import importlib.util as u; s = u.spec_from_file_location('m', {module_file!r}); "
             "m = u.module_from_spec(s); s.loader.exec_module(m); f = m.advance_bank; "
             "print(f.inspect_asm(f.signatures[0]))")
    with tempfile.TemporaryDirectory() as cache:
        asm = subprocess.run([sys.executable, "-c", child], capture_output=True, text=True,
                             check=True, env=dict(os.environ, NUMBA_CACHE_DIR=cache)).stdout
    loop = hot_loop(asm)
    report = subprocess.run(["llvm-mca", "-mcpu=znver3", "-iterations=300"], input="\n".join(loop),
                            capture_output=True, text=True, check=True).stdout
    per_pass = int(re.search(r"Total Cycles:\s+(\d+)", report).group(1)) / 300
    vector_pairs = sum("vmulpd" in line for line in loop) / 6        # six multiplies a pair
    return (f"{module_file}: {len(loop)} instructions, {per_pass:.1f} cycles a pass, "
            f"{per_pass / vector_pairs:.2f} cycles per 4 modes and pair, "
            f"{per_pass / vector_pairs * 593 / 4 / 2:.0f} cycles per sample for 593 modes")


def load(module_file: str):
    spec = importlib.util.spec_from_file_location(f"notch_{abs(hash(module_file))}", module_file)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module.SwitchedNotch


def fastest_calls(old_file: str, calls: int) -> str:
    from rippleb.methods.switched_notch import SwitchedNotch
    from rippleb.simulator import simulate

    calibration = simulate("calibration", 0).log.for_method(keep_ref=True)
    log = simulate("paper-quintic", 901).log.for_method(keep_ref=False)
    methods = {"old": load(old_file)(), "new": SwitchedNotch()}
    for method in methods.values():
        method.fit(calibration)
    blocks = list(log.blocks(int(log.spec.fs)))
    times = {name: [] for name in methods}
    outputs = {name: [] for name in methods}
    for _ in range(-(-calls // len(blocks))):
        for method in methods.values():
            method.reset(log.spec)
        for block in blocks:
            for name, method in methods.items():
                t0 = time.perf_counter_ns()
                outputs[name].append(method.step(block))
                times[name].append(time.perf_counter_ns() - t0)
    same = all(np.array_equal(a, b) for a, b in zip(outputs["old"], outputs["new"]))
    rate = {name: len(blocks[0]) / min(t) * 1e3 for name, t in times.items()}
    return (f"{len(times['old'])} calls each, fastest: old {rate['old']:.2f}, new {rate['new']:.2f} "
            f"M samples/s (new / old {rate['new'] / rate['old']:.2f}); outputs "
            + ("equal bit for bit" if same else "DIFFER"))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--against", help="another checkout's methods/switched_notch.py")
    parser.add_argument("--calls", type=int, default=120, help="1-second calls of each")
    args = parser.parse_args()
    here = os.path.join(os.path.dirname(__file__), "..", "methods", "_notch_stream.py")
    for module_file in filter(None, (args.against, os.path.normpath(here))):
        print(cycles(module_file))
    if args.against:
        print(fastest_calls(args.against, args.calls))


if __name__ == "__main__":
    main()

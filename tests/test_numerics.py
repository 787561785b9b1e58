"""The portable numeric paths (rippleb/numerics.py, docs/reproducibility.md).

Each case runs in a fresh interpreter: the paths are chosen when numpy and OpenBLAS load,
once per process, so only a new process can show what ``import rippleb`` sets.
"""

import json
import os
import subprocess
import sys

import pytest

from rippleb import numerics
from rippleb.errors import InputError
from rippleb.report.tables import ACCURACY_COLUMNS

#: Variables a case may set; removed from the parent's environment first, so each case
#: starts as a fresh shell would.
CHOSEN = ("NPY_DISABLE_CPU_FEATURES", "OPENBLAS_CORETYPE", "OPENBLAS_NUM_THREADS", "NUMBA_CPU_NAME",
          numerics.NATIVE_SWITCH)


def _python(code: str, timeout: float = 240, **env) -> str:
    environ = {k: v for k, v in os.environ.items() if k not in CHOSEN}
    environ.update(env)
    done = subprocess.run([sys.executable, "-c", code], env=environ, capture_output=True, text=True,
                          timeout=timeout)
    assert done.returncode == 0, done.stderr[-3000:]
    return done.stdout


def test_import_rippleb_pins_the_paths_before_numpy_loads():
    out = json.loads(_python(
        "import json, os, rippleb\n"
        "from rippleb import numerics\n"
        "print(json.dumps({'env': {k: os.environ.get(k) for k in "
        "('NPY_DISABLE_CPU_FEATURES', 'OPENBLAS_CORETYPE', 'OPENBLAS_NUM_THREADS')},"
        " 'state': numerics.state(), 'targets': numerics.numpy_targets(),"
        " 'cores': numerics.openblas_cores(), 'threads': numerics.openblas_threads()}))",
        NPY_DISABLE_CPU_FEATURES="AVX512_SPR,MY_OWN"))
    assert out["state"] == numerics.PORTABLE
    assert not set(out["targets"]) & set(numerics.NUMPY_ABOVE_AVX2)
    assert out["cores"] in ([], [numerics.OPENBLAS_CORE]) and out["threads"] in (None, 1)
    disabled = out["env"]["NPY_DISABLE_CPU_FEATURES"].split()
    assert "MY_OWN" in disabled and "X86_V4" in disabled  # the user's entry kept, ours added
    assert out["env"]["OPENBLAS_CORETYPE"] == "Haswell" and out["env"]["OPENBLAS_NUM_THREADS"] == "1"


def test_numpy_loaded_first_is_reported_native():
    # Two BLAS threads make the state native on any CPU: the pin came too late to stop them.
    out = _python("import numpy, rippleb\nfrom rippleb import numerics\nprint(numerics.state())",
                  OPENBLAS_NUM_THREADS="2")
    assert out.startswith("native: ") and "x2" in out


def test_the_native_switch_leaves_the_libraries_alone():
    out = _python("import os, rippleb\nprint(os.environ.get('OPENBLAS_CORETYPE'))",
                  **{numerics.NATIVE_SWITCH: "1"})
    assert out.strip() == "None"


@pytest.mark.host
def test_machine_names_what_decides_the_last_bits():
    machine = numerics.machine()
    described = {"cpu_simd", "numba_cpu", "numpy_dispatch", "openblas", "libc", "numerics"}
    fake = os.environ.get(numerics.FAKE_CPU_SWITCH)
    assert set(machine) == (described | {"fake_cpu"} if fake else described)
    assert "avx2" in machine["cpu_simd"].split()  # every machine of this kind
    assert machine["numerics"] == numerics.PORTABLE  # the suite runs them (tests/conftest.py)


@pytest.mark.parametrize("kind", sorted(numerics.FAKE_CPUS))
def test_a_fake_cpu_is_described_in_place_of_the_host(monkeypatch, kind):
    monkeypatch.setenv(numerics.FAKE_CPU_SWITCH, kind)
    machine = numerics.machine()
    assert machine["fake_cpu"] == kind
    assert ("avx512f" in machine["cpu_simd"].split()) == (kind == "avx512")
    assert "avx2" in machine["cpu_simd"].split() and "fma" in machine["cpu_simd"].split()
    assert machine["numerics"] == numerics.PORTABLE   # the numbers' paths are the host's own


def test_an_unknown_fake_cpu_is_one_line_naming_the_variable(monkeypatch):
    monkeypatch.setenv(numerics.FAKE_CPU_SWITCH, "avx10")
    with pytest.raises(InputError, match=r"RIPPLEB_FAKE_CPU='avx10' is not a CPU .*avx2, avx512"):
        numerics.machine()


ROW = """
import json, sys, tempfile, pathlib
import rippleb
from rippleb.report import writer as report
rows = {}
with tempfile.TemporaryDirectory() as d:
    for i, (method, scenario, condition, seed) in enumerate(json.loads(sys.argv[1])):
        out = pathlib.Path(d) / str(i)
        rippleb.run([method], [scenario], [seed], conditions=[condition], jobs=1, out=out)
        rows[i] = report.read_results_exact(out / "results.csv").iloc[0].to_dict()
print(json.dumps(rows))
"""
#: A least-squares fit and a closed-loop calibration log each: the two places where the
#: AVX-512 paths moved published numbers.
PROBED = [("order-tracking", "paper-quintic", "same-session", 0),
          ("angle-adaptive", "stop-restart", "power-cycled", 1)]


def _rows(**env) -> dict:
    environ = {k: v for k, v in os.environ.items() if k not in CHOSEN}
    environ.update(env)
    done = subprocess.run([sys.executable, "-c", ROW, json.dumps(PROBED)], env=environ,
                          capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr[-3000:]
    return json.loads(done.stdout.strip().splitlines()[-1])


@pytest.mark.slow
def test_an_emulated_avx2_host_gives_the_portable_rows_bit_for_bit():
    """An AVX2 machine's own paths (rippleb's pin off; numpy without its AVX-512 loops,
    OpenBLAS asked for AMD Zen kernels on one thread, numba compiling for Haswell) against
    the portable paths of this host, whatever it is. The emulated host reports the portable
    paths itself (OpenBLAS serves Zen with its Haswell kernels): the portable paths are
    what an AVX2 machine runs natively."""
    portable = _rows()
    avx2 = _rows(RIPPLEB_NATIVE_NUMERICS="1", NPY_DISABLE_CPU_FEATURES="X86_V4 AVX512_ICL AVX512_SPR",
                 OPENBLAS_CORETYPE="Zen", OPENBLAS_NUM_THREADS="1", NUMBA_CPU_NAME="haswell")
    for key, row in portable.items():
        assert row["numerics"] == avx2[key]["numerics"] == numerics.PORTABLE
        assert row["status"] == "ok"
        for column in ACCURACY_COLUMNS:
            assert repr(row[column]) == repr(avx2[key][column]), (PROBED[int(key)], column)


@pytest.mark.slow
def test_a_run_on_native_paths_warns_and_says_so_in_its_rows(tmp_path):
    done = subprocess.run([sys.executable, "-m", "rippleb", "run", "--methods", "raw", "--scenarios",
                           "static-contact", "--seeds", "1", "--jobs", "1", "--no-progress",
                           "--out", str(tmp_path / "run")],
                          env={**{k: v for k, v in os.environ.items() if k not in CHOSEN},
                               numerics.NATIVE_SWITCH: "1", "OPENBLAS_NUM_THREADS": "2"},
                          capture_output=True, text=True,
                          timeout=300)
    assert done.returncode == 0, done.stderr
    assert "rippleb: warning: the rows run the host's own numeric paths" in done.stderr
    assert f"{numerics.NATIVE_SWITCH} is set" in done.stderr
    import pandas as pd

    assert pd.read_csv(tmp_path / "run" / "results.csv")["numerics"].str.startswith("native").all()


def test_the_other_kind_of_cpu_is_never_this_hosts(monkeypatch):
    simd, _ = numerics._host_cpu()
    other = numerics.other_cpu_kind()
    assert other in numerics.FAKE_CPUS
    assert ("avx512f" in numerics.FAKE_CPUS[other][0].split()) != ("avx512f" in simd.split())
    monkeypatch.setattr(numerics, "_host_cpu", lambda: ("avx avx2 fma", "haswell"))
    assert numerics.other_cpu_kind() == "avx512"
    monkeypatch.setattr(numerics, "_host_cpu", lambda: (numerics.FAKE_CPUS["avx512"][0], "x"))
    assert numerics.other_cpu_kind() == "avx2"

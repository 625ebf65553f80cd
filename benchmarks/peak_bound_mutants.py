"""Each wrong tension bound docs/solver.md names ("Steps that cannot raise a peak") must fail
tests/test_peaks.py::test_the_tension_bound_is_never_below_the_tension_on_the_step. For each: a copy of src, tests
and scenes with one line changed, the test run on it in a process of its own (the copy compiles its own numba
cache, so the checkout's stays valid: about 4 minutes a mutant). Prints one line per mutant, caught or MISSED, and
exits 1 if any is missed.

Run: .venv/bin/python benchmarks/peak_bound_mutants.py [name ...]   (names: the keys of MUTANTS; all by default)"""
from __future__ import annotations

import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
TEST = "tests/test_peaks.py::test_the_tension_bound_is_never_below_the_tension_on_the_step"
SAMPLING, EXCITATION = "src/grapefmu/solver/sampling.py", "src/grapefmu/physics/excitation.py"

#: name -> (file, the line as it is, the line made wrong)
MUTANTS = {
    "without the coupling term": (
        SAMPLING,
        "        reach[i, 2] += f\n        reach[j, 2] += f\n",
        "        reach[i, 2] += 0.0 * f\n        reach[j, 2] += 0.0 * f\n"),
    "without the ṫ terms": (
        SAMPLING,
        "            rate += abs(y0[nd + o + 1]) + travel(q, h, nd + o + 1)\n",
        "            rate += 0.0\n"),
    "without the check that ω is zero": (
        SAMPLING,
        "            if y0[r] != 0.0 or travel(q, h, r) != 0.0:\n                return False\n",
        "            if False:\n                return False\n"),
    "half the m l ω² term": (
        SAMPLING,
        "        if b.mass * b.twig_length * reach[i, 1] ** 2 + reach[i, 2] > peak_tension[i]:\n",
        "        if 0.5 * b.mass * b.twig_length * reach[i, 1] ** 2 + reach[i, 2] > peak_tension[i]:\n"),
    "without the chirp's −A branch": (
        EXCITATION,
        "        return max(up, math.sqrt(p[0] * p[0] + p[1] * p[1] + (g - p[2]) ** 2), g)\n",
        "        return max(up, g)\n"),
    "with the held input ignored": (
        EXCITATION,
        "        return math.sqrt(inp.ax * inp.ax + inp.ay * inp.ay + (inp.az + g) ** 2)\n",
        "        return g\n"),
}


def mutate(where: Path, name: str) -> None:
    """A copy of the checkout's src, tests, scenes and pyproject.toml in `where`, with mutant `name` applied."""
    skip = shutil.ignore_patterns("__pycache__", "*.egg-info")
    for part in ("src", "tests", "scenes"):
        shutil.copytree(ROOT / part, where / part, ignore=skip)
    shutil.copy(ROOT / "pyproject.toml", where)
    path, right, wrong = MUTANTS[name]
    text = (where / path).read_text()
    if text.count(right) != 1:
        raise SystemExit(f"{name}: the line to change is not in {path} once; update MUTANTS")
    (where / path).write_text(text.replace(right, wrong))


def caught(name: str) -> tuple[bool, str]:
    """Whether the test fails on mutant `name` (and its last line of output)."""
    with tempfile.TemporaryDirectory(prefix="grapefmu-mutant-") as d:
        where = Path(d)
        mutate(where, name)
        env = dict(os.environ, PYTHONPATH=str(where / "src"), NUMBA_CACHE_DIR=str(where / "numba-cache"))
        r = subprocess.run([sys.executable, "-m", "pytest", "-q", "-x", "-p", "no:cacheprovider", TEST], cwd=where,
                           env=env, capture_output=True, text=True)
        if r.returncode not in (0, 1):
            raise SystemExit(f"{name}: pytest could not run (exit {r.returncode}):\n"
                             f"{r.stdout[-2000:]}{r.stderr[-2000:]}")
        last = (r.stdout.strip().splitlines() or [""])[-1]
        return r.returncode == 1, last


def main(names: list[str]) -> int:
    missed = 0
    for name in names or list(MUTANTS):
        t0 = time.perf_counter()
        ok, last = caught(name)
        missed += not ok
        print(f"{'caught' if ok else 'MISSED'}  {name}  ({last}; {time.perf_counter() - t0:.0f} s)", flush=True)
    return 1 if missed else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))

"""What inlining numba's reference counts (physics/compiled._counts_inlined) costs the cold compile (docs/solver.md,
"Reference counts"): each round compiles what a default-scene run calls (warmup.prepare) into an empty numba cache,
once with the pass and once without it, in fresh processes, alternating. About three minutes a compile.
Run: .venv/bin/python benchmarks/inline_compile.py [--rounds 2]"""
from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile

ONE = """
import sys, time
import grapefmu.physics.compiled as compiled
from numba.core import codegen
if sys.argv[1] == "without":
    codegen.CPUCodeLibrary._optimize_final_module = compiled._optimize_final_module  # numba's own, no inlining
from grapefmu import load_scene
from grapefmu.scenefile.parse import default_scene_path
from grapefmu.solver.warmup import prepare
t = time.perf_counter()
assert prepare(load_scene(default_scene_path()), say=False).compiled
print(time.perf_counter() - t)
"""


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rounds", type=int, default=2)
    a = ap.parse_args()
    times: dict[str, list[float]] = {"with": [], "without": []}
    for r in range(a.rounds):
        for mode in times:
            with tempfile.TemporaryDirectory(prefix="grapefmu-inline-compile-") as cache:
                out = subprocess.run([sys.executable, "-c", ONE, mode], env={**os.environ, "NUMBA_CACHE_DIR": cache},
                                     capture_output=True, text=True, check=True)
            times[mode].append(float(out.stdout.split()[-1]))
            print(f"round {r + 1}: {mode:7s} the pass {times[mode][-1]:6.1f} s", flush=True)
    for mode, t in times.items():
        print(f"{mode:7s} the pass: {', '.join(f'{x:.1f}' for x in t)} s")


if __name__ == "__main__":
    main()

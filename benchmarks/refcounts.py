"""Plain against atomic numba reference counts (physics/compiled.py): wall time of one `simulate` of the paper
collision scene (1 ms output) at rtol 1e-6 and 1e-10, each mode in its own process (the switch is process-wide),
the processes alternated, the minimum over all of a mode's runs. The counts are compiled into every function
(physics/compiled._counts_inlined), so the atomic processes keep their own numba cache (a temporary directory: the
first one compiles, a few minutes).
Run: .venv/bin/python benchmarks/refcounts.py"""
from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
CHILD = """
import json, time, grapefmu
from grapefmu.bench.scenes import bench_scenes, build
sc = build(bench_scenes()["paper collision"])
out = {}
for rtol in (1e-6, 1e-10):
    kw = dict(rtol=rtol, atol=rtol * 1e-2, output_interval=1e-3)
    grapefmu.simulate(sc, **kw)
    walls = []
    for _ in range(9):
        t0 = time.perf_counter(); grapefmu.simulate(sc, **kw); walls.append(time.perf_counter() - t0)
    out[str(rtol)] = min(walls)
print(json.dumps(out))
"""


ATOMIC_CACHE = tempfile.mkdtemp(prefix="grapefmu-atomic-cache-")


def child(atomic: bool) -> dict[str, float]:
    env = {**os.environ, "PYTHONPATH": str(ROOT / "src")}
    env.pop("GRAPEFMU_ATOMIC_REFCOUNTS", None)
    if atomic:
        env["GRAPEFMU_ATOMIC_REFCOUNTS"] = "1"
        env["NUMBA_CACHE_DIR"] = ATOMIC_CACHE
    out = subprocess.run([sys.executable, "-c", CHILD], env=env, capture_output=True, text=True, check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def main(rounds: int = 4) -> None:
    best = {True: {}, False: {}}
    for _ in range(rounds):
        for atomic in (True, False):
            for k, v in child(atomic).items():
                best[atomic][k] = min(best[atomic].get(k, v), v)
    print("| rtol | atomic counts (ms / sim s) | plain counts (ms / sim s) | atomic / plain |\n|---|---|---|---|")
    for k in best[True]:
        a, p = best[True][k] / 2.0 * 1e3, best[False][k] / 2.0 * 1e3  # the scene runs 2 s
        print(f"| {float(k):.0e} | {a:.3f} | {p:.3f} | {a / p:.2f} |")


if __name__ == "__main__":
    main()

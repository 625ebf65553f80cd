"""The pick-and-place cluster's cost (rtol 1e-6; one step size on 10 and 100 berries, or with --islands multirate
islands on 30, 100 and 300) under this checkout and another version, interleaved in fresh processes (each version
with its own numba cache), minimum of --rounds × 5 runs: tells a slower machine from a slower solver.

    git worktree add /tmp/grapefmu-old <rev>
    .venv/bin/python benchmarks/cluster_versions.py --old /tmp/grapefmu-old [--rounds 3] [--islands]"""
from __future__ import annotations

import argparse
import json
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
CODE = r'''
import json, time
import grapefmu
from grapefmu.bench.scale import scene
out = {}
from grapefmu.solver.islands import Islands
for n in SIZES:
    sc = scene("cluster", n)
    go = (lambda: Islands(sc).run()) if ISLANDS else (lambda: grapefmu.simulate(sc))
    go()
    best = 1e9
    for _ in range(5):
        t = time.perf_counter()
        run = go()
        best = min(best, time.perf_counter() - t)
    out[n] = best / run.t[-1]
print(json.dumps(out))
'''


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--old", type=Path, required=True, help="a checkout of the other version")
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--islands", action="store_true", help="multirate islands (30, 100, 300 berries)")
    a = ap.parse_args()
    code = f"SIZES, ISLANDS = {(30, 100, 300) if a.islands else (10, 100)}, {a.islands}\n" + CODE
    trees = {"this": ROOT, "old": a.old.resolve()}
    best: dict[str, dict[str, float]] = {name: {} for name in trees}
    for _ in range(a.rounds):
        for name, tree in trees.items():
            env = {"PYTHONPATH": str(tree / "src"), "PATH": "/usr/bin:/bin", "NUMBA_CACHE_DIR": f"/tmp/nbcache_{name}"}
            out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True)
            for n, cost in json.loads(out.stdout.strip().splitlines()[-1]).items():
                best[name][n] = min(best[name].get(n, float("inf")), cost)
    for name in trees:
        print(f"{name:5s}", ", ".join(f"{n} berries {1e3 * c:.2f} ms" for n, c in best[name].items()),
              "per simulated s")


if __name__ == "__main__":
    main()

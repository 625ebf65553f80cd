"""The pick-and-place cluster's cost (rtol 1e-6; one step size on 10 and 100 berries, or with --islands multirate
islands on 30, 100 and 300) under this checkout and another version: one worker process per version (each with its
own numba cache), the two taking turns run by run, --rounds runs of each size each. Printed per size: each version's
fastest run and the median over rounds of the ratio of the two runs made back to back. The host's speed drifts by
tens of per cent within minutes (docs/bench_notes.md): a pair of runs a second apart sees the same host, so the
median ratio tells a slower machine from a slower solver better than two minima taken minutes apart.

    git worktree add /tmp/grapefmu-old <rev>
    .venv/bin/python benchmarks/cluster_versions.py --old /tmp/grapefmu-old [--rounds 20] [--islands]"""
from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
WORKER = r'''
import json, sys, time
import grapefmu
from grapefmu.bench.scale import scene
from grapefmu.solver.islands import Islands
SIZES, ISLANDS = json.loads(sys.argv[1])
scenes = {n: scene("cluster", n) for n in SIZES}
go = (lambda sc: Islands(sc).run()) if ISLANDS else grapefmu.simulate
for sc in scenes.values():
    go(sc)  # compiled, or loaded from the cache
print("ready", flush=True)
for line in sys.stdin:
    sc = scenes[int(line)]
    t = time.perf_counter()
    run = go(sc)
    print(json.dumps((time.perf_counter() - t) / run.t[-1]), flush=True)
'''


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--old", type=Path, required=True, help="a checkout of the other version")
    ap.add_argument("--rounds", type=int, default=20)
    ap.add_argument("--islands", action="store_true", help="multirate islands (30, 100, 300 berries)")
    a = ap.parse_args()
    sizes = (30, 100, 300) if a.islands else (10, 100)
    workers = {}
    for name, tree in (("this", ROOT), ("old", a.old.resolve())):
        env = {"PYTHONPATH": str(tree / "src"), "PATH": "/usr/bin:/bin", "NUMBA_CACHE_DIR": f"/tmp/nbcache_{name}"}
        w = subprocess.Popen([sys.executable, "-c", WORKER, json.dumps([sizes, a.islands])], stdin=subprocess.PIPE,
                             stdout=subprocess.PIPE, text=True, env=env)
        if w.stdout.readline().strip() != "ready":
            sys.exit(f"the {name} worker did not start")
        workers[name] = w
    cost = {(name, n): [] for name in workers for n in sizes}
    for r in range(a.rounds):
        for n in sizes:
            for name in (("this", "old") if r % 2 == 0 else ("old", "this")):  # each goes first half the time
                workers[name].stdin.write(f"{n}\n")
                workers[name].stdin.flush()
                cost[name, n].append(json.loads(workers[name].stdout.readline()))
    for w in workers.values():
        w.stdin.close()
        w.wait()
    for n in sizes:
        this, old = cost["this", n], cost["old", n]
        ratio = statistics.median(t / o for t, o in zip(this, old))
        print(f"{n:4d} berries: this {1e3 * min(this):.2f} ms, old {1e3 * min(old):.2f} ms per simulated s (fastest of "
              f"{a.rounds}); this/old {ratio:.3f} (median of the {a.rounds} back-to-back pairs)")


if __name__ == "__main__":
    main()

"""The pick-and-place cluster's cost (rtol 1e-6; one step size on 10 and 100 berries, or with --islands multirate
islands on 30, 100 and 300) under this checkout and another version: one worker process per version (each with its
own numba cache), the two taking turns run by run, --rounds runs of each size each. Printed per size: each version's
fastest run, the median over rounds of the ratio of the two runs made back to back, and whether the two versions'
runs give the same samples, contact log, impacts and peaks bit for bit (a hash of each). The host's speed drifts by
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
import hashlib, json, sys, time
import numpy as np
import grapefmu
from grapefmu.bench.scale import scene
from grapefmu.solver.islands import Islands
SIZES, ISLANDS = json.loads(sys.argv[1])
scenes = {n: scene("cluster", n) for n in SIZES}
go = (lambda sc: Islands(sc).run()) if ISLANDS else grapefmu.simulate
digests = {}
for n, sc in scenes.items():
    run = go(sc)  # compiled, or loaded from the cache
    h = hashlib.blake2b()
    for a in (run.t, run.y, run.accel, run.totals, run.contacts, run.impacts.records(), run.peak_force,
              run.peak_tension):
        for field in a.dtype.names or (None,):  # field by field: a record's padding bytes are not the run's
            h.update((a if field is None else np.ascontiguousarray(a[field])).tobytes())
    digests[n] = h.hexdigest()
print(json.dumps(digests), flush=True)
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
    workers, digests = {}, {}
    for name, tree in (("this", ROOT), ("old", a.old.resolve())):
        env = {"PYTHONPATH": str(tree / "src"), "PATH": "/usr/bin:/bin", "NUMBA_CACHE_DIR": f"/tmp/nbcache_{name}"}
        w = subprocess.Popen([sys.executable, "-c", WORKER, json.dumps([sizes, a.islands])], stdin=subprocess.PIPE,
                             stdout=subprocess.PIPE, text=True, env=env)
        line = w.stdout.readline()
        if not line.startswith("{"):
            sys.exit(f"the {name} worker did not start")
        digests[name] = json.loads(line)
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
        same = "the same bit for bit" if digests["this"][str(n)] == digests["old"][str(n)] else "DIFFER"
        print(f"{n:4d} berries: this {1e3 * min(this):.2f} ms, old {1e3 * min(old):.2f} ms per simulated s (fastest of "
              f"{a.rounds}); this/old {ratio:.3f} (median of the {a.rounds} back-to-back pairs); samples, contacts, "
              f"impacts and peaks {same}")


if __name__ == "__main__":
    main()

"""How much a grapefmu run's cost depends on what ran just before it: the paper collision at rtol 1e-6 timed right
after another grapefmu run and right after a scipy DOP853 lean run of the same scene (bench/methods.py), in pairs,
interleaved; the scipy run the same way. Back to back, a sub-millisecond compiled run finds the caches as only its
own repetition leaves them, which is why `grapefmu bench` times its methods in interleaved rounds
(bench.methods.interleaved; docs/bench_notes.md).
Run: .venv/bin/python benchmarks/after_other.py [pairs: 40]"""
from __future__ import annotations

import sys
import time

import numpy as np

from grapefmu.bench import methods as M
from grapefmu.bench.scenes import bench_scenes, build


def main(pairs: int = 40) -> None:
    sc = build(bench_scenes()["paper collision"])
    t_end = sc.solver.t_end
    ours, peer = (lambda: M.grapefmu_event(sc, 1e-6)), (lambda: M.scipy_lean(sc, "DOP853", 1e-6))
    ours(), peer()
    cost = {(a, b): [] for a in ("grapefmu", "scipy") for b in ("itself", "the other")}
    runs = {"grapefmu": ours, "scipy": peer}
    for _ in range(pairs):
        for name, other in (("grapefmu", "scipy"), ("scipy", "grapefmu")):
            for before, label in ((name, "itself"), (other, "the other")):
                runs[before]()
                t = time.perf_counter()
                runs[name]()
                cost[name, label].append((time.perf_counter() - t) / t_end * 1e3)
    for (name, label), c in cost.items():
        print(f"{name:8s} after {label:9s}: min {min(c):.3f}, median {np.median(c):.3f} ms per simulated s")
    for label in ("itself", "the other"):
        ratio = min(cost["scipy", label]) / min(cost["grapefmu", label])
        print(f"scipy / grapefmu, each after {label}: {ratio:.1f}× (the fastest of each)")


if __name__ == "__main__":
    main(int(sys.argv[1]) if len(sys.argv) > 1 else 40)

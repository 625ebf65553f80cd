"""From how many berries multirate islands are cheaper than one step size (model.ISLANDS_FROM, the size from which
`solver.islands = "auto"` runs a scene in islands; docs/solver.md "Multirate islands"): generated clusters
(`grapefmu cluster`, pick-and-place, 1 s) of three seeds, a compact cluster (berries pressed 2 mm into each other at
rest), other tolerances and the Scale section's row, each timed both ways, interleaved, the minimum of a few passes.
Prints each case's wall times and islands / one step size.
Run: .venv/bin/python benchmarks/islands_crossover.py [--passes 3]"""
from __future__ import annotations

import argparse
import time
from pathlib import Path

from grapefmu.bench.scale import scene as scale_scene
from grapefmu.cluster.generate import ClusterSpec, cluster_scene
from grapefmu.model.model import ISLANDS_FROM
from grapefmu.scenefile.parse import scene_from_dict
from grapefmu.solver.islands import Islands
from grapefmu.solver.solver import Solver


def cluster(n: int, seed: int = 1, rtol: float = 1e-6, precompression: float = 0.0):
    solver = {"rtol": rtol, "atol": rtol * 1e-3, "t_end": 1.0, "output_interval": 1e-3}
    spec = ClusterSpec(berries=n, seed=seed, precompression=precompression, solver=solver)
    return scene_from_dict(cluster_scene(spec), Path.cwd())


def cases() -> list[tuple[str, int, object]]:
    out = [(f"cluster, seed {s}", n, cluster(n, s)) for s in (1, 2, 3) for n in (40, 60, 70, 80, 100)]
    out += [("compact cluster (2 mm)", n, cluster(n, precompression=0.002)) for n in (80, 100, 150)]
    out += [(f"cluster, rtol {r:g}", n, cluster(n, rtol=r)) for r in (1e-4, 1e-8) for n in (60, 100)]
    out += [("row", n, scale_scene("row", n)) for n in (40, 60, 80, 100)]
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--passes", type=int, default=3)
    a = ap.parse_args()
    todo = cases()
    best: dict[tuple[int, str], float] = {}
    for _, _, sc in todo:  # compiles, and warms each scene's systems
        Solver(sc).run()
        Islands(sc).run()
    for _ in range(a.passes):
        for k, (_, _, sc) in enumerate(todo):
            for way, run in (("one", lambda: Solver(sc).run()), ("islands", lambda: Islands(sc).run())):
                t0 = time.perf_counter()
                run()
                best[k, way] = min(best.get((k, way), float("inf")), time.perf_counter() - t0)
    print(f"wall ms per simulated second, minimum of {a.passes} interleaved passes; `auto` runs islands from "
          f"{ISLANDS_FROM} berries")
    print(f"{'scene':24s} {'N':>4s} {'one step size':>14s} {'islands':>9s} {'islands / one':>14s}")
    for k, (name, n, _) in enumerate(todo):
        one, isl = best[k, "one"], best[k, "islands"]
        print(f"{name:24s} {n:4d} {one * 1e3:14.1f} {isl * 1e3:9.1f} {isl / one:14.2f}")


if __name__ == "__main__":
    main()

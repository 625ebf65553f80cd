"""How close each berry's booked peak pedicel tension (Run.peak_tension) comes to the largest tension on its path, by
tolerance (docs/solver.md, "Peaks"). Reference: the tension the run's observation computes (physics/observe.py) at
every sample of a 2 µs output grid at rtol 1e-12, largest per berry (within about 1e-8 of the maximum: curvature ×
spacing²; two-berry scenes, first `--t-end` s), and for every scene the solver's own run at rtol 1e-12. Prints the
largest relative error over the berries per rtol.
Run: .venv/bin/python benchmarks/peak_tension.py [--t-end 1.0] [--clusters 30 100]"""
from __future__ import annotations

import argparse

import numpy as np

import grapefmu
from grapefmu.bench.scale import scene as scale_scene
from grapefmu.bench.scenes import bench_scenes, build

RTOLS = (1e-4, 1e-6, 1e-8, 1e-10)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--t-end", type=float, default=1.0)
    ap.add_argument("--clusters", type=int, nargs="*", default=[30, 100])
    a = ap.parse_args()
    scenes = {k: (build(v), True) for k, v in bench_scenes().items()}
    scenes |= {f"cluster of {n}": (scale_scene("cluster", n, 1e-6), False) for n in a.clusters}
    print(f"largest relative error of the booked peak pedicel tension, first {a.t_end:g} s: against a 2 µs grid "
          f"(two berries) | against the solver at rtol 1e-12")
    print(f"{'scene':24s} " + " ".join(f"{'rtol ' + format(r, 'g'):>21s}" for r in RTOLS))
    for name, (sc, grid) in scenes.items():
        te = min(sc.solver.t_end, a.t_end)
        own = grapefmu.simulate(sc, t_end=te, rtol=1e-12, atol=1e-14, output_interval=1e-3).peak_tension
        fine = None
        if grid:
            fine = grapefmu.simulate(sc, t_end=te, rtol=1e-12, atol=1e-14,
                                     output_interval=2e-6).pedicel_tension.max(axis=0)
        cells = []
        for rtol in RTOLS:
            got = grapefmu.simulate(sc, t_end=te, rtol=rtol, atol=rtol * 1e-2, output_interval=1e-3).peak_tension
            e_own = np.abs(got - own).max() / np.abs(own).max()
            e_fine = "" if fine is None else f"{np.abs(got - fine).max() / np.abs(fine).max():.1e} | "
            cells.append(f"{e_fine}{e_own:.1e}")
        print(f"{name:24s} " + " ".join(f"{c:>21s}" for c in cells))


if __name__ == "__main__":
    main()

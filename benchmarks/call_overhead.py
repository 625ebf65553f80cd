"""Fixed costs around the integration itself: numba unboxing the model and state on every compiled call,
one 1 ms Solver.advance, and a whole simulate() of a very short run (Python set-up and result assembly).
Run: .venv/bin/python benchmarks/call_overhead.py"""
from __future__ import annotations

import time

import grapefmu
from grapefmu import Solver
from grapefmu.scenefile import default_scene_path


def best(fn, n=2000, reps=5):
    fn()
    out = []
    for _ in range(reps):
        t = time.perf_counter()
        for _ in range(n):
            fn()
        out.append((time.perf_counter() - t) / n)
    return min(out)


def main():
    scene = grapefmu.load_scene(default_scene_path())
    s = Solver(scene)
    s.advance(1e-3, (1.0, 0.0))
    noop = best(lambda: s._integrate(s.t, s._scratch, 1))
    adv = best(lambda: s.advance(1e-3, (1.0, 0.0)))
    sim = best(lambda: grapefmu.simulate(scene, 1e-3), n=200)
    print(f"compiled call that integrates nothing (argument unboxing): {noop * 1e6:7.1f} µs")
    print(f"Solver.advance(1 ms) with a held input:                     {adv * 1e6:7.1f} µs")
    print(f"simulate(scene, t_end = 1 ms), set-up and result assembly:   {sim * 1e6:7.1f} µs")


if __name__ == "__main__":
    main()

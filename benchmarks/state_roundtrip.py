"""What saving and restoring a Solver's state costs (docs/solver.md, set_state): `get_state` and `set_state` of the
paper collision scene's state after 0.1 s, the minimum over REPEATS rounds of N calls each, beside one
`advance(0.001)` for scale. A master that rolls an FMU back every step pays one set_state per step.
Run: .venv/bin/python benchmarks/state_roundtrip.py"""
from __future__ import annotations

import time

from grapefmu.bench.scenes import bench_scenes, build
from grapefmu.solver.solver import Solver

REPEATS, N = 7, 200


def best(fn) -> float:
    out = float("inf")
    for _ in range(REPEATS):
        t0 = time.perf_counter()
        for _ in range(N):
            fn()
        out = min(out, (time.perf_counter() - t0) / N)
    return out


def main() -> None:
    s = Solver(build(bench_scenes()["paper collision"]), rtol=1e-6, atol=1e-8)
    s.advance(0.1)
    saved = s.get_state()
    get = best(s.get_state)
    put = best(lambda: s.set_state(saved))

    def step():
        s.set_state(saved)
        s.advance(0.001)

    advance = best(step) - put
    print(f"get_state {get * 1e6:.1f} µs, set_state {put * 1e6:.1f} µs, advance(0.001) from that state "
          f"{advance * 1e6:.1f} µs (set_state = {put / advance:.0f} advances)")


if __name__ == "__main__":
    main()

"""Where one `simulate` of a benchmark scene goes (docs/bench_notes.md, "Why the speed targets are missed"): the
Python around the compiled loop (Solver() and the result), the output grid, and the loop's cost per step beyond
its right-hand-side evaluations (RHS evaluations × one bare RHS, bench/costs.py), and the Python's largest pieces
timed alone. Each figure is the minimum of `REPEATS` interleaved runs (of PIECE_REPEATS calls for a piece).
Run: .venv/bin/python benchmarks/run_breakdown.py ["paper collision"] [rtol] [output interval, s: 1e-3]"""
from __future__ import annotations

import math
import sys
import time

import numpy as np

import grapefmu
from grapefmu.bench.costs import rhs_seconds
from grapefmu.bench.scenes import bench_scenes, build
from grapefmu.results.impacts import Impacts
from grapefmu.solver import budget, components
from grapefmu.solver import session as ses
from grapefmu.solver.solver import Solver, open_impacts

REPEATS = 30
PIECE_REPEATS = 3000


def pieces(sc, kw: dict, dt: float) -> dict[str, float]:
    """Seconds each piece of the Python around a run takes alone (the fastest of PIECE_REPEATS calls)."""
    s = Solver(sc, **kw)
    run = s.run(output_interval=dt)
    S = s.state
    finished = run.impacts.records()[~run.impacts.ongoing]
    ongoing = open_impacts(S.physical.contacts, S.book.pair, run.t[-1])
    calls = {
        "Solver()": lambda: Solver(sc, **kw),
        "  its compiled start (session.start)": lambda: ses.start(s.M, s.excitation, s.tableau, s.config,
                                                                    np.zeros(s.layout.size), 0.0, np.uint64(1),
                                                                    sc.solver.zeno_max_events),
        "  the state boxed for Python (session.views)": lambda: ses.views(s._session),
        "the run's recorder (session.recording)": lambda: ses.recording(s._session, len(run.t) + 1, dt, run.t[-1]),
        "the impacts going on (open_impacts)": lambda: open_impacts(S.physical.contacts, S.book.pair, run.t[-1]),
        "the impact book (Impacts.from_records)": lambda: Impacts.from_records(finished, ongoing),
        "stats (run_stats)": lambda: s.stats,
        "memory budget (budget.check_samples)": lambda: budget.check_samples(sc.model, run.t[-1], dt),
        "independent groups (components.groups)": lambda: components.groups(sc.model),
    }
    out = {}
    for name, fn in calls.items():
        best = math.inf
        for _ in range(PIECE_REPEATS):
            t0 = time.perf_counter()
            fn()
            best = min(best, time.perf_counter() - t0)
        out[name] = best
    return out


def main(name: str = "paper collision", rtol: float = 1e-6, dt: float = 1e-3) -> None:
    sc = build(bench_scenes()[name])
    kw = dict(rtol=rtol, atol=rtol / 100)
    t_end = sc.solver.t_end
    run = grapefmu.simulate(sc, output_interval=dt, **kw)
    rhs = min(rhs_seconds(run) for _ in range(5))
    best = dict.fromkeys(("simulate", "Solver()", "loop, grid", "loop, no grid"), float("inf"))
    for _ in range(REPEATS):
        t0 = time.perf_counter()
        run = grapefmu.simulate(sc, output_interval=dt, **kw)
        best["simulate"] = min(best["simulate"], time.perf_counter() - t0)
        best["loop, grid"] = min(best["loop, grid"], run.stats["wall_time"])
        t0 = time.perf_counter()
        solver = Solver(sc, **kw)
        best["Solver()"] = min(best["Solver()"], time.perf_counter() - t0)
        bare = solver.run(output_interval=t_end)  # one sample at the end: the same steps, no grid
        best["loop, no grid"] = min(best["loop, no grid"], bare.stats["wall_time"])
    s = run.stats
    floor = s["rhs_evaluations"] * rhs
    python = best["simulate"] - best["loop, grid"]
    grid = best["loop, grid"] - best["loop, no grid"]
    beyond = (best["loop, no grid"] - floor) / s["steps"]
    print(f"{name}, rtol {rtol:g}, {t_end:g} s simulated: {s['steps']} steps ({s['quiet_steps']} quiet, "
          f"{s['spared_steps']} spared, {s['rejected']} rejected), {s['rhs_evaluations']} RHS evaluations at "
          f"{rhs * 1e9:.0f} ns")
    print(f"  simulate             {best['simulate'] * 1e3:8.3f} ms  ({best['simulate'] / t_end * 1e3:.3f} ms per simulated s)")
    print(f"  Python around loop   {python * 1e3:8.3f} ms  (of it Solver() {best['Solver()'] * 1e3:.3f} ms)")
    print(f"  output grid ({dt:g} s) {grid * 1e3:8.3f} ms  ({grid / max(len(run.t) - 1, 1) * 1e9:.0f} ns a sample)")
    print(f"  loop without grid    {best['loop, no grid'] * 1e3:8.3f} ms  = RHS floor {floor * 1e3:.3f} ms "
          f"+ {beyond * 1e6:.2f} µs a step beyond its RHS evaluations")
    print("  the Python's pieces, each alone:")
    for piece, sec in pieces(sc, kw, dt).items():
        print(f"    {piece:46s} {sec * 1e6:6.2f} µs")


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else "paper collision", float(sys.argv[2]) if len(sys.argv) > 2 else 1e-6,
         float(sys.argv[3]) if len(sys.argv) > 3 else 1e-3)

"""Multirate islands against one step size (issue 14 item 4; docs/solver.md "Multirate islands"): for the Scale
section's cluster (pick-and-place, rtol 1e-6, 1 s) at each N and window, interleaved, the minimum of a few runs:
wall time both ways, the islands' compiled work alone (`session.windows`), the systems made (islands of a shape
not seen before in the run: their Python), berry-steps (each island's steps × its berries, against steps × N),
islands formed and rolled back, and their mean size; then what one step of a one-berry island costs against a
berry-step of the whole cluster. --sections: where an islands run's wall time goes
(default window, the fastest of the repeats): each compiled call Python makes and each step of the window loop, by
wall time, calls and time per call (a timer around each adds about 1 µs a call).
Run: .venv/bin/python benchmarks/islands.py [N ...] [--windows 0.01 0.02 0.04] [--repeats 3] [--join 5e-4] [--stay 5e-3]
     [--sections]"""
from __future__ import annotations

import argparse
import collections
import time

import numpy as np

import grapefmu
from grapefmu.bench.scale import scene
from grapefmu.solver import islands as isl
from grapefmu.solver import session as ses

compiled = [0.0]
_windows = ses.windows
made = [0.0, 0]  # systems made (islands of a shape not seen before in the run): seconds, count
_System_init = isl._System.__init__


def timed_system(self, *args):
    t = time.perf_counter()
    _System_init(self, *args)
    made[0] += time.perf_counter() - t
    made[1] += 1


def timed_windows(*args):
    t = time.perf_counter()
    out = _windows(*args)
    compiled[0] += time.perf_counter() - t
    return out


def sections(sc, repeats: int) -> None:
    """Time each compiled call of an islands run and each step of its window loop (wrapped for the run only)."""
    spent: collections.Counter = collections.Counter()
    calls: collections.Counter = collections.Counter()
    wrapped = [(isl.Islands, m, f"Islands.{m}") for m in ("_start", "_regroup", "_window", "_run", "_islands",
                                                          "_retire", "_slack", "_components", "_assemble")]
    wrapped += [(isl._Batch, m, f"_Batch.{m}") for m in ("__init__", "replace")]
    wrapped += [(ses, m, f"session.{m}") for m in ("windows", "previews", "island", "take_impacts", "rollback", "grow",
                                                   "put", "labels", "take_last", "listed")]
    wrapped += [(isl, m, f"{m} (compiled)") for m in ("retire_all", "flush_all", "form_all", "parts", "slack",
                                                       "components")]
    saved = [(obj, name, getattr(obj, name)) for obj, name, _ in wrapped]

    def timer(f, label):
        def timed(*args, **kw):
            t = time.perf_counter()
            try:
                return f(*args, **kw)
            finally:
                spent[label] += time.perf_counter() - t
                calls[label] += 1
        return timed

    best = None
    try:
        for obj, name, label in wrapped:
            setattr(obj, name, timer(getattr(obj, name), label))
        for _ in range(repeats):
            spent.clear()
            calls.clear()
            t = time.perf_counter()
            isl.Islands(sc).run()
            wall = time.perf_counter() - t
            if best is None or wall < best[0]:
                best = (wall, dict(spent), dict(calls))
    finally:
        for obj, name, f in saved:
            setattr(obj, name, f)
    wall, spent, calls = best
    print(f"  where an islands run's {1e3 * wall:.1f} ms go (nested: a line includes the lines it calls):")
    for label, s in sorted(spent.items(), key=lambda kv: -kv[1]):
        print(f"    {label:28s} {1e3 * s:8.1f} ms {100 * s / wall:5.1f} %  {calls[label]:6d} calls "
              f"{1e6 * s / calls[label]:8.1f} µs a call")


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("sizes", nargs="*", type=int, default=[10, 30, 100, 300])
    ap.add_argument("--windows", nargs="+", type=float, default=[0.01, 0.02, 0.04])
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--join", type=float, default=isl.JOIN, help="m: the distance below which berries join")
    ap.add_argument("--stay", type=float, default=isl.STAY, help="m: the distance above which they part")
    ap.add_argument("--sections", action="store_true", help="where an islands run's time goes, call by call")
    a = ap.parse_args()
    isl.JOIN, isl.STAY = a.join, a.stay
    isl.ses.windows = timed_windows
    isl._System.__init__ = timed_system
    for n in a.sizes:
        sc = scene("cluster", n)
        whole = grapefmu.simulate(sc)
        isl.Islands(sc).run(0.3)  # compiled on a warm cache
        best = {"whole": np.inf} | {w: (np.inf,) for w in a.windows}
        for _ in range(a.repeats):
            t = time.perf_counter()
            grapefmu.simulate(sc)
            best["whole"] = min(best["whole"], time.perf_counter() - t)
            for w in a.windows:
                compiled[0] = 0.0
                made[:] = [0.0, 0]
                it = isl.Islands(sc, window=w)
                t = time.perf_counter()
                run = it.run()
                wall = time.perf_counter() - t
                if wall < best[w][0]:
                    sizes = [len(s.members) for s in it.segments]
                    best[w] = (wall, compiled[0], it.berry_steps, it.formed, it.rollbacks, float(np.mean(sizes)),
                               made[0], made[1])
        print(f"{n}-berry cluster, 1 s: one step size {1e3 * best['whole']:.1f} ms, {whole.stats['steps'] * n} "
              f"berry-steps")
        for w in a.windows:
            wall, work, steps, formed, back, size, made_s, n_made = best[w]
            print(f"  islands, window {1e3 * w:g} ms: {1e3 * wall:.1f} ms ({wall / best['whole']:.2f}× one step "
                  f"size), compiled {1e3 * work:.1f} ms ({work / best['whole']:.2f}×), {steps} berry-steps "
                  f"({whole.stats['steps'] * n / steps:.1f}× fewer), {formed} formed ({size:.1f} berries on average), "
                  f"{back} rolled back; {n_made} systems made, {1e3 * made_s:.1f} ms")
        if a.sections:
            sections(sc, a.repeats)
    # one step of a one-berry island against a berry-step of the whole 100-berry cluster
    sc = scene("cluster", 100)
    it = isl.Islands(sc)
    it.run(0.05)
    seg = next(s for s in it.batch.segs if len(s.members) == 1)
    state, rec = ses.views(seg.system.session)[0], ses.outputs(seg.system.session)[0]
    rec.cursor["grid_dt"] = 0.0  # no output samples: the steps alone
    before = int(state.book.counters["steps"][0])
    t = time.perf_counter()
    formed = lambda sessions, slots: None  # noqa: E731 (it is formed: the run left it)
    it._run(isl._Batch([seg], it.n, formed), state.physical.t[0] + 200.0)  # the move is over: a free swing
    per = (time.perf_counter() - t) / (int(state.book.counters["steps"][0]) - before)
    run = grapefmu.simulate(sc)
    t = time.perf_counter()
    grapefmu.simulate(sc)
    whole = (time.perf_counter() - t) / (run.stats["steps"] * 100)
    print(f"one step of a one-berry island (no samples, after the move): {1e6 * per:.1f} µs; a berry-step of the "
          f"100-berry cluster with one step size (samples included): {1e6 * whole:.2f} µs")


if __name__ == "__main__":
    main()

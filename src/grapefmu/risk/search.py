"""The fastest duration of a plan that keeps its bruise probability under a bound: bisection on a time scale.

The plan's moves are run `scale` times as slow (montecarlo.time_scaled: the same path, so accelerations
scale as 1/scale²); the search looks for the smallest scale in [low, high] at which the plan is shown safe.

Monte Carlo noise: a scale counts as safe only when the upper end of the Clopper–Pearson interval of its
bruise probability is at or below the bound, not when the estimate is. A plan whose true probability is
above the bound passes one such test with probability at most (1 − LEVEL)/2 = 2.5 %, so the answer errs on
the slow side. Every scale is run with the same draws (the same seed: common random numbers), so the
estimates at neighbouring scales differ by what the scale changes, not by fresh sampling noise, and the
estimated probability is close to monotonic in the scale, which bisection needs. The bisection is geometric
(the midpoint of low and high is √(low·high)) and stops when high/low < 1 + tolerance; each step's sweep is
its own Parquet table, so an interrupted search resumes where it stopped (the same command computes the
same sequence of scales and finds the finished steps' tables).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

from ..errors import GrapefmuError
from .draws import Distribution
from .montecarlo import LEVEL, Outcome, run_plan


@dataclass
class Search:
    bound: float
    steps: list[Outcome] = field(default_factory=list)   # every scale run, in the order run
    fastest: Outcome | None = None    # the fastest scale shown safe
    too_fast: Outcome | None = None   # the slowest scale run that was not shown safe, faster than `fastest`
    note: str = ""

    def as_json(self) -> dict:
        return {"bound": self.bound, "level": LEVEL, "steps": [o.as_json() for o in self.steps],
                "fastest": None if self.fastest is None else self.fastest.as_json(),
                "too_fast": None if self.too_fast is None else self.too_fast.as_json(), "note": self.note}


def safe(o: Outcome, bound: float) -> bool:
    return o.bruise.n > 0 and o.bruise.interval[1] <= bound


def fastest(plan: str | Path, dist: Distribution, samples: int, seed: int, out_dir: str | Path, bound: float, *,
            low: float = 0.25, high: float = 4.0, tolerance: float = 0.02, workers: int | None = None,
            scheduler: str | None = None, progress: bool = True, say=lambda line: None) -> Search:
    """Bisection for the smallest time scale at which the plan is shown safe (module docstring)."""
    if not (0 < low < high and math.isfinite(high) and 0 < tolerance < 1 and 0 < bound < 1):
        raise GrapefmuError(f"--scales {low:g}:{high:g} / --max-bruise {bound:g}: expected 0 < LOW < HIGH and a bound "
                            "in (0, 1)")
    s = Search(bound)

    def run(scale: float) -> Outcome:
        say(f"risk: {Path(plan).stem} at time scale {scale:.6g}")
        o = run_plan(plan, dist, samples, seed, out_dir, scale=scale, workers=workers, scheduler=scheduler,
                     progress=progress)
        s.steps.append(o)
        say(f"risk: time scale {scale:.6g} (moves {o.duration:.4g} s): P(bruise) = {o.bruise.text()}: "
            + ("shown under" if safe(o, bound) else "not shown under") + f" {bound:g}")
        return o

    hi = run(high)
    if not safe(hi, bound):
        s.note = (f"not shown under the bound even at the slowest scale considered ({high:g}); slow the plan down "
                  "further (--scales) or change it")
        return s
    lo = run(low)
    if safe(lo, bound):
        s.fastest, s.note = lo, f"shown under the bound already at the fastest scale considered ({low:g})"
        return s
    while hi.scale / lo.scale > 1 + tolerance:
        mid = run(float(f"{math.sqrt(lo.scale * hi.scale):.6g}"))
        if safe(mid, bound):
            hi = mid
        else:
            lo = mid
    s.fastest, s.too_fast = hi, lo
    s.note = (f"fastest shown under the bound: scale {hi.scale:.4g} (moves {hi.duration:.4g} s); scale "
              f"{lo.scale:.4g} (moves {lo.duration:.4g} s) was not")
    return s

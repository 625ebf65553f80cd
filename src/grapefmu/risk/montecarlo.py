"""One plan's Monte Carlo: the draws as a sweep (sweep/), the sweep's rows counted into probabilities.

Each plan's runs are a `list` sweep (docs/sweeps.md): run k takes draw k of every parameter. The sweep
engine runs them (local processes, this process, or Dask), journals every finished run and resumes an
interrupted sweep, so a risk estimate keeps its finished samples the same way. Every plan is run with the
same draws (the same seed): plans are compared on common random numbers, and a difference between them is
the plans', not the draws'.

Probabilities are fractions of the runs that finished (a run the solver or the validator refused is counted
apart and reported); their intervals are Clopper–Pearson's exact binomial intervals (95 % unless told):
never narrower than the true coverage asks, even at 0 or N of N, which is where a handling plan's bruise
probability usually is. Wilson's interval is shorter but can cover less than its nominal level for small
counts; a bound a plan must meet deserves the conservative one.
"""
from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import GrapefmuError
from ..scenefile.parse import loads_toml, read_text
from ..sweep import SweepSpec, run_sweep
from ..sweep.spec import Parameter as Swept, checked
from .draws import Distribution

#: the confidence level of every interval
LEVEL = 0.95


def clopper_pearson(k: int, n: int, level: float = LEVEL) -> tuple[float, float]:
    """The exact (Clopper–Pearson) interval of a binomial probability from k successes in n trials."""
    from scipy.stats import beta
    if n == 0:
        return 0.0, 1.0
    a = 1.0 - level
    lo = 0.0 if k == 0 else float(beta.ppf(a / 2, k, n - k + 1))
    hi = 1.0 if k == n else float(beta.ppf(1 - a / 2, k + 1, n - k))
    return lo, hi


@dataclass(frozen=True)
class Probability:
    k: int
    n: int

    @property
    def p(self) -> float:
        """k/n; NaN when no run finished (plots leave it out; the text and JSON say so instead of a number)."""
        return self.k / self.n if self.n else float("nan")

    @property
    def interval(self) -> tuple[float, float]:
        return clopper_pearson(self.k, self.n)

    def text(self) -> str:
        if not self.n:
            return "unknown: no run finished (0/0)"
        lo, hi = self.interval
        return f"{self.p:.3f} [{lo:.3f}, {hi:.3f}] ({self.k}/{self.n})"


@dataclass
class Outcome:
    """A plan's Monte Carlo: the probability of at least one bruising impact and of a detachment, for the whole
    cluster and per berry."""

    plan: str
    scale: float                       # the plan's time scale (1: as written)
    duration: float                    # s, the plan's moves at this scale (0 without pick-and-place moves)
    table: Path                        # the sweep's Parquet table
    bruise: Probability
    detach: Probability
    berry_bruise: dict[str, Probability]
    berry_detach: dict[str, Probability]
    failed: list[str] = field(default_factory=list)  # the status of every run that did not finish
    rows: list[dict[str, Any]] = field(default_factory=list, repr=False)
    warned: int = 0  # finished runs that warned their results cannot be trusted (the table's `warnings`)

    def as_json(self) -> dict[str, Any]:
        def pr(x: Probability) -> dict[str, Any]:
            lo, hi = x.interval
            return {"p": x.p if x.n else None, "low": lo, "high": hi, "count": x.k, "runs": x.n}
        return {"plan": self.plan, "scale": self.scale, "duration_s": self.duration, "table": str(self.table),
                "bruise": pr(self.bruise), "detach": pr(self.detach),
                "berries": {b: {"bruise": pr(self.berry_bruise[b]), "detach": pr(self.berry_detach[b])}
                            for b in self.berry_bruise},
                "failed_runs": len(self.failed), "warned_runs": self.warned}


def plan_doc(path: str | Path) -> tuple[dict[str, Any], str]:
    path = Path(path)
    text = read_text(path)
    return loads_toml(text, str(path)), text


def moves_duration(doc: dict[str, Any]) -> float:
    ex = doc.get("excitation", {})
    if ex.get("kind") != "pick-and-place":
        return 0.0
    return float(sum(m.get("duration", 0.0) for m in ex.get("moves", [])))


def time_scaled(doc: dict[str, Any], scale: float, where: str = "--max-bruise") -> dict[str, Any]:
    """The plan run `scale` times as slow: every move's duration times `scale` (the same path, so accelerations
    divided by scale²), and the run's end moved so the time left after the last move stays what it was."""
    import copy
    if scale == 1.0:
        return copy.deepcopy(doc)
    ex = doc.get("excitation", {})
    if ex.get("kind") != "pick-and-place" or not isinstance(ex.get("moves"), list):
        raise GrapefmuError(f"{where}: a plan is sped up or slowed down by scaling its pick-and-place moves' "
                            f"durations; this plan's excitation is {ex.get('kind', 'none')!r}")
    out = copy.deepcopy(doc)
    total = moves_duration(doc)
    for m in out["excitation"]["moves"]:
        m["duration"] = m["duration"] * scale
    solver = out.setdefault("solver", {})
    solver["t_end"] = float(solver.get("t_end", 2.0)) + (scale - 1.0) * total
    return out


def run_plan(path: str | Path, dist: Distribution, samples: int, seed: int, out_dir: str | Path, *,
             scale: float = 1.0, workers: int | None = None, scheduler: str | None = None,
             progress: bool = True) -> Outcome:
    """The plan's Monte Carlo over `dist` (samples draws fixed by seed) as a resumable sweep under out_dir."""
    path = Path(path)
    doc, text = plan_doc(path)
    base = time_scaled(doc, scale)
    draws = dist.draw(samples, seed)
    params = tuple(Swept(key, tuple(values)) for key, values in draws.items())
    what = {"plan": text, "scale": scale, "samples": samples, "seed": seed, "distribution": dist.describe()}
    spec = checked(SweepSpec(base, path.parent, "list", params, 0, seed, json.dumps(what, sort_keys=True)))
    table = Path(out_dir) / f"{path.stem}{'' if scale == 1.0 else f'-x{scale:.6g}'}.parquet"
    run_sweep(spec, table, workers=workers, scheduler=scheduler, progress=progress)
    return outcome(path.stem, scale, moves_duration(base), table, doc)


def outcome(plan: str, scale: float, duration: float, table: Path, doc: dict[str, Any]) -> Outcome:
    """Count a finished sweep table into probabilities."""
    import pyarrow.parquet as pq

    rows = pq.read_table(table).to_pylist()
    ok = [r for r in rows if r["status"] == "ok"]
    n = len(ok)
    names = [b["name"] for b in doc.get("berries", [])]
    bruised = [set(r["bruised_berries"] or ()) for r in ok]
    detached = [set(r["detached_berries"] or ()) for r in ok]
    return Outcome(
        plan, scale, duration, table,
        Probability(sum(r["bruising_impacts"] > 0 for r in ok), n),
        Probability(sum(bool(r["detachment_risk"]) for r in ok), n),
        {b: Probability(sum(b in s for s in bruised), n) for b in names},
        {b: Probability(sum(b in s for s in detached), n) for b in names},
        [r["status"] for r in rows if r["status"] != "ok"], rows, sum(bool(r.get("warnings")) for r in ok))


def check_samples(samples: int, bound: float | None) -> None:
    """Refuse a sample count too small for any plan to be shown under the bound: with no bruise in N runs the
    Clopper–Pearson upper limit is 1 − ((1 − LEVEL)/2)^(1/N), about 3.7/N."""
    if not 1 <= samples <= 10**6:
        raise GrapefmuError(f"--samples: expected an integer in [1, 1000000], got {samples}")
    if bound is not None and not 0 < bound < 1:
        raise GrapefmuError(f"--max-bruise: expected a probability in (0, 1), got {bound!r}")
    if bound is not None:
        best = clopper_pearson(0, samples)[1]
        if best > bound:
            need = int(np.ceil(np.log((1 - LEVEL) / 2) / np.log(1 - bound)))
            raise GrapefmuError(f"--max-bruise {bound:g}: with --samples {samples} even a plan without a single "
                                f"bruise has an upper limit of {best:.3g}; at least {need} samples are needed")

"""`assess`: every plan's Monte Carlo over the same draws, the optional duration search, and the report files."""
from __future__ import annotations

import copy
from dataclasses import dataclass
from pathlib import Path

from ..errors import GrapefmuError, SceneError
from ..fit.params import parameter
from ..scenefile import scene_from_dict
from . import report
from .draws import Distribution
from .montecarlo import Outcome, check_samples, plan_doc, run_plan, time_scaled
from .search import Search, fastest

#: the files assess writes into its directory, beside one Parquet table per plan and per searched scale
FILES = ("risk.md", "risk.json", "risk.png")


@dataclass
class Risk:
    outcomes: list[Outcome]
    distribution: Distribution
    samples: int
    seed: int
    search: Search | None
    files: list[Path]


def check_plans(plans: list[str | Path], dist: Distribution) -> None:
    """Every plan is a scene the validator takes, holding every key the distribution sets in the unit it was drawn
    in (a stiffness fitted in N/m drawn for a Hunt–Crossley plan ran in the wrong unit; a plan with a negative mass
    had every run refused and P = nan written); no two plans share a file name (their tables are named after
    them)."""
    if not plans:
        raise GrapefmuError("plans: none given; name at least one plan (a scene TOML)")
    stems = [Path(p).stem for p in plans]
    if len(set(stems)) != len(stems):
        raise GrapefmuError(f"{', '.join(map(str, plans))}: two plans have the same file name; their tables are "
                            "named after them")
    drawn = {par.key: par.unit for par in dist.normal} | {r.parameter.key: r.parameter.unit for r in dist.ranges}
    for p in plans:
        doc, _ = plan_doc(p)
        try:
            scene_from_dict(copy.deepcopy(doc), Path(p).parent)
        except SceneError as e:
            raise GrapefmuError(f"{p}: {e}") from None
        for key, unit in drawn.items():
            par = parameter(key, doc, str(p), drawn=True)
            if par.unit != unit:
                raise GrapefmuError(f"{p}: {key} is drawn in {unit}; this plan's contact law takes {par.unit}")
        for r in dist.ranges:  # both ends in what the plan takes (the draws beyond were refused, and left out)
            for end in (r.low, r.high):
                at = copy.deepcopy(doc)
                r.parameter.set(at, end)
                try:
                    scene_from_dict(at, Path(p).parent)
                except SceneError as e:
                    raise GrapefmuError(f"--range {r.parameter.key}={r.low:g}:{r.high:g}: plan {p} refuses {end:g} "
                                        f"({e}); every draw must be a value it takes") from None


def assess(plans: list[str | Path], dist: Distribution, samples: int, seed: int, out_dir: str | Path, *,
           max_bruise: float | None = None, scales: tuple[float, float] = (0.25, 4.0), tolerance: float = 0.02,
           workers: int | None = None, scheduler: str | None = None, progress: bool = True,
           say=lambda line: None, command: str = "") -> Risk:
    """Run every plan over the same `samples` draws, then (with max_bruise) search the first plan's fastest
    duration under the bound; write risk.md, risk.json and risk.png into out_dir."""
    check_samples(samples, max_bruise)
    if not 0 <= seed < 2**63:
        raise GrapefmuError(f"--seed: expected an integer in [0, 2^63), got {seed}")
    check_plans(plans, dist)
    if max_bruise is not None:  # the search scales the first plan's moves: refused now, not after every plan has run
        time_scaled(plan_doc(plans[0])[0], 2.0)
    out_dir = Path(out_dir)
    outcomes = []
    for p in plans:
        say(f"risk: plan {Path(p).stem}, {samples} draws")
        o = run_plan(p, dist, samples, seed, out_dir, workers=workers, scheduler=scheduler, progress=progress)
        say(f"risk: {o.plan}: P(bruise) = {o.bruise.text()}, P(detachment) = {o.detach.text()}")
        outcomes.append(o)
    search = None
    if max_bruise is not None:
        search = fastest(plans[0], dist, samples, seed, out_dir, max_bruise, low=scales[0], high=scales[1],
                         tolerance=tolerance, workers=workers, scheduler=scheduler, progress=progress, say=say)
    files = [out_dir / f for f in FILES]
    md, js, png = files
    from ..results.writers import atomic_path
    with atomic_path(md) as tmp:
        tmp.write_text(report.markdown(outcomes, dist, samples, seed, search, command), encoding="utf-8")
    report.write_json(js, outcomes, dist, samples, seed, search)
    report.plot(png, outcomes, search)
    return Risk(outcomes, dist, samples, seed, search, files)

"""A risk estimate as a Markdown table, a JSON document and a figure: plans side by side, the duration search."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from ..results.plot import pyplot, save
from ..results.writers import atomic_path
from .draws import Distribution
from .montecarlo import LEVEL, Outcome
from .search import Search


def markdown(outcomes: list[Outcome], dist: Distribution, samples: int, seed: int, search: Search | None,
             command: str = "") -> str:
    pct = f"{100 * LEVEL:g} %"
    out = [f"# Risk: {', '.join(o.plan for o in outcomes)}", ""]
    if command:
        out += ["Reproduce: `" + command + "`", ""]
    out += [f"{samples} draws (seed {seed}), the same draws for every plan. Probabilities with {pct} Clopper–Pearson "
            "intervals [low, high] (count/runs). Bruise: at least one impact whose peak force or dissipated energy "
            "reached the scene's bruise threshold; detachment: a pedicel tension above the detachment force.", "",
            "| parameter | distribution |", "|---|---|"]
    out += [f"| `{k}` | {d} |" for k, d in dist.spread()]
    out += ["", "## Plans side by side", "", "| | " + " | ".join(o.plan for o in outcomes) + " |",
            "|---|" + "---|" * len(outcomes)]
    out.append("| moves (s) | " + " | ".join(f"{o.duration:.4g}" for o in outcomes) + " |")
    out.append("| P(bruise), cluster | " + " | ".join(o.bruise.text() for o in outcomes) + " |")
    out.append("| P(detachment), cluster | " + " | ".join(o.detach.text() for o in outcomes) + " |")
    for b in outcomes[0].berry_bruise:
        if all(b in o.berry_bruise for o in outcomes):
            out.append(f"| P(bruise), {b} | " + " | ".join(o.berry_bruise[b].text() for o in outcomes) + " |")
    for b in outcomes[0].berry_detach:
        if all(b in o.berry_detach for o in outcomes):
            out.append(f"| P(detachment), {b} | " + " | ".join(o.berry_detach[b].text() for o in outcomes) + " |")
    failed = [(o.plan, len(o.failed)) for o in outcomes if o.failed]
    if failed:
        out += ["", "Runs that did not finish (left out of the counts): "
                + ", ".join(f"{p}: {n}" for p, n in failed) + "."]
    warned = [(o.plan, o.warned, o.bruise.n) for o in outcomes if o.warned]
    if warned:
        out += ["", "Runs that warned their results cannot be trusted (counted all the same; each says why in the "
                "table's `warnings` column, docs/sweeps.md): " + ", ".join(f"{p}: {k} of {n}" for p, k, n in warned)
                + "."]
    if search is not None:
        out += ["", f"## Fastest duration with P(bruise) under {search.bound:g}", "",
                f"A scale counts only when the upper end of its {pct} interval is at or below the bound.", "",
                "| time scale | moves (s) | P(bruise) | shown under the bound |", "|---|---|---|---|"]
        for o in sorted(search.steps, key=lambda o: o.scale):
            ok = o.bruise.n > 0 and o.bruise.interval[1] <= search.bound
            out.append(f"| {o.scale:.4g} | {o.duration:.4g} | {o.bruise.text()} | {'yes' if ok else 'no'} |")
        failed = [o for o in sorted(search.steps, key=lambda o: o.scale) if o.failed]
        if failed:  # a scale too fast for the solver's bounds: every run refused, the probability unknown
            out += ["", "Runs that did not finish (left out of the counts), by time scale: "
                    + "; ".join(f"{o.scale:.4g}: {len(o.failed)} (the first: {o.failed[0]})" for o in failed) + "."]
        out += ["", search.note + "."]
    return "\n".join(out) + "\n"


def write_json(path: str | Path, outcomes: list[Outcome], dist: Distribution, samples: int, seed: int,
               search: Search | None) -> None:
    doc = {"samples": samples, "seed": seed, "level": LEVEL, "interval": "clopper-pearson",
           "distribution": dist.describe(), "plans": [o.as_json() for o in outcomes],
           "search": None if search is None else search.as_json()}
    with atomic_path(path) as tmp:
        tmp.write_text(json.dumps(doc, indent=1) + "\n", encoding="utf-8")


def plot(path: str | Path, outcomes: list[Outcome], search: Search | None) -> None:
    """Bars with their intervals: the cluster and each berry, one colour per plan; bruise and detachment; and
    the search's probability against the moves' duration."""
    plt = pyplot()
    panels = 3 if search is not None else 2
    fig, axes = plt.subplots(1, panels, figsize=(5.2 * panels, 4.2), squeeze=False)
    names = ["cluster", *[b for b in outcomes[0].berry_bruise if all(b in o.berry_bruise for o in outcomes)]]
    x = np.arange(len(names))
    width = 0.8 / len(outcomes)
    for ax, what in zip(axes[0], ("bruise", "detachment")):
        for k, o in enumerate(outcomes):
            probs = [o.bruise if what == "bruise" else o.detach] + [
                (o.berry_bruise if what == "bruise" else o.berry_detach)[b] for b in names[1:]]
            p = np.array([q.p for q in probs])
            lo, hi = np.array([q.interval for q in probs]).T
            ax.bar(x + (k - (len(outcomes) - 1) / 2) * width, p, width, yerr=[p - lo, hi - p], capsize=3,
                   label=f"{o.plan} ({o.duration:.3g} s)" if o.duration else o.plan, color=f"C{k}", alpha=0.8)
        ax.set_xticks(x, names, rotation=30 if len(names) > 4 else 0, fontsize=8)
        ax.set_ylim(0, 1)
        ax.set_ylabel(f"P({what}) with {100 * LEVEL:g} % interval")
        ax.set_title(f"at least one {'bruising impact' if what == 'bruise' else 'detachment'}", fontsize=10)
        ax.legend(fontsize=8)
    if search is not None:
        ax = axes[0, 2]
        steps = sorted(search.steps, key=lambda o: o.duration)
        d = np.array([o.duration for o in steps])
        p = np.array([o.bruise.p for o in steps])
        lo, hi = np.array([o.bruise.interval for o in steps]).T
        ax.errorbar(d, p, yerr=[p - lo, hi - p], fmt="o", capsize=3, color="C0", label="P(bruise), cluster")
        ax.axhline(search.bound, color="C3", ls="--", lw=1, label=f"bound {search.bound:g}")
        if search.fastest is not None:
            ax.axvline(search.fastest.duration, color="C2", lw=1,
                       label=f"fastest shown under: {search.fastest.duration:.3g} s")
        from matplotlib.ticker import FormatStrFormatter, LogLocator, NullFormatter
        ax.set_xscale("log")  # the bisection is geometric
        ax.xaxis.set_major_locator(LogLocator(subs=(1.0, 2.0, 5.0)))
        ax.xaxis.set_major_formatter(FormatStrFormatter("%g"))
        ax.xaxis.set_minor_formatter(NullFormatter())
        ax.set_xlabel("duration of the moves (s), log scale")
        ax.set_ylabel("P(bruise)")
        ax.set_ylim(-0.02, 1.02)
        ax.set_title(f"{steps[0].plan}: time-scale search", fontsize=10)
        ax.legend(fontsize=8)
    fig.tight_layout()
    save(fig, path)

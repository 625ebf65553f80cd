"""What a fit hands on: a table, the fitted scene TOML, a JSON report (what `risk --fit` reads), residual plots."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from ..results.plot import PLOT_TYPES, pyplot, save
from ..results.writers import atomic_path, check_target
from ..scenefile import dumps
from .estimate import FitResult


def table(res: FitResult) -> str:
    """The estimates, their standard errors and the correlations, as the command line prints them."""
    w = max(len(e.key) for e in res.estimates)
    lines = [f"  {'parameter':<{w}}  {'start':>10}  {'estimate':>10}  {'std. error':>10}  {'relative':>8}  unit"]
    for e in res.estimates:
        rel = f"{100 * e.relative_se:.2g} %" if np.isfinite(e.se) else "—"
        se = f"{e.se:.3g}" if np.isfinite(e.se) else "∞"
        flag = "" if e.identifiable else "  NOT IDENTIFIABLE"
        lines.append(f"  {e.key:<{w}}  {e.start:>10.4g}  {e.value:>10.4g}  {se:>10}  {rel:>8}  {e.unit}{flag}")
    if len(res.estimates) > 1:
        lines.append("  correlations (of the log or logit of each parameter):")
        for a, ea in enumerate(res.estimates):
            cells = " ".join("     —" if not np.isfinite(res.correlation[a, b]) else f"{res.correlation[a, b]:+6.3f}"
                             for b in range(a + 1))
            lines.append(f"    {ea.key:<{w}}  {cells}")
    return "\n".join(lines)


def header(res: FitResult, sources: list[str]) -> str:
    """The comment that heads a fitted scene: where its values came from and how sure they are."""
    lines = [f"# Fitted by grapefmu fit to {', '.join(sources)}: {res.residuals} measured angles, residual "
             f"standard deviation {res.sigma:.3g} rad.",
             "# Estimates ± one standard error (docs/fit_and_risk.md); the other values are the scene's own."]
    for e in res.estimates:
        se = f"± {e.se:.3g}" if np.isfinite(e.se) else "not identifiable: kept for the record only"
        lines.append(f"#   {e.key} = {e.value:.6g} {se}{'' if e.identifiable else ' (' + e.note + ')'}")
    return "\n".join(lines) + "\n"


def write_scene(res: FitResult, path: str | Path, sources: list[str]) -> None:
    with atomic_path(path) as tmp:
        tmp.write_text(header(res, sources) + dumps(res.fitted_doc), encoding="utf-8")


def write_json(res: FitResult, path: str | Path, scene: str, sources: list[str]) -> None:
    doc = {"scene": scene, "data": sources, **res.as_json()}
    with atomic_path(path) as tmp:
        tmp.write_text(json.dumps(doc, indent=1, allow_nan=False) + "\n", encoding="utf-8")


def check_outputs(scene: str | Path, report: str | Path | None, plot: str | Path | None) -> None:
    """Refuse, before the fit, outputs that could not be written."""
    check_target(scene, (".toml",), "--output")
    if report is not None:
        check_target(report, (".json",), "--report")
    if plot is not None:
        check_target(plot, PLOT_TYPES, "--plot")


def plot_residuals(res: FitResult, path: str | Path) -> None:
    """Per tracked angle: measured and fitted angle over time, and below it the residual in mrad with ±2σ̂;
    beside them the residuals' histogram against the normal density of σ̂ (white noise looks like it)."""
    plt = pyplot()
    keys = list(dict.fromkeys((tr.series, tr.dof) for tr in res.traces))
    fig, axes = plt.subplots(2 * len(keys), 2, figsize=(11, 2.6 * 2 * len(keys)), squeeze=False,
                             gridspec_kw={"width_ratios": [4, 1]})
    sig = res.sigma * 1e3
    for n, key in enumerate(keys):
        parts = [tr for tr in res.traces if (tr.series, tr.dof) == key]
        top, bottom, hist = axes[2 * n, 0], axes[2 * n + 1, 0], axes[2 * n + 1, 1]
        axes[2 * n, 1].axis("off")
        for k, tr in enumerate(parts):
            top.plot(tr.t, tr.measured, ".", ms=2.5, color="0.45", label="measured" if k == 0 else None)
            top.plot(tr.t, tr.fitted, "-", lw=1.0, color="C0", label="fitted" if k == 0 else None)
            bottom.plot(tr.t, 1e3 * (tr.measured - tr.fitted), ".", ms=2.5, color="C3")
            if k:
                for ax in (top, bottom):
                    ax.axvline(tr.t[0], color="0.7", lw=0.8, ls=":")
        top.set_ylabel(f"angle_{key[1]} (rad)")
        top.set_title(f"{key[0]}: angle {key[1]}" + (" (dotted: segment starts)" if len(parts) > 1 else ""),
                      fontsize=9)
        top.legend(fontsize=8, loc="upper right")
        for lvl in (-2 * sig, 0.0, 2 * sig):
            bottom.axhline(lvl, color="0.5", lw=0.8, ls="--" if lvl else "-")
        bottom.set_ylabel("measured − fitted (mrad)")
        bottom.set_xlabel("time (s)")
        r = np.concatenate([1e3 * (tr.measured - tr.fitted) for tr in parts])
        r = r[np.isfinite(r)]
        hist.hist(r, bins=30, density=True, orientation="horizontal", color="C3", alpha=0.6)
        y = np.linspace(-4 * sig, 4 * sig, 200)
        hist.plot(np.exp(-0.5 * (y / sig) ** 2) / (sig * np.sqrt(2 * np.pi)), y, color="k", lw=1.0)
        hist.set_ylim(bottom.get_ylim())
        hist.set_xlabel("density")
        hist.set_title(f"σ̂ = {sig:.3g} mrad", fontsize=9)
    flagged = [e.key for e in res.estimates if not e.identifiable]
    fig.suptitle(f"fit: {res.residuals} angles, residual σ̂ = {sig:.3g} mrad"
                 + (f"; not identifiable: {', '.join(flagged)}" if flagged else ""), fontsize=10)
    fig.tight_layout()
    save(fig, path)

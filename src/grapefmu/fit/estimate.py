"""Least squares on the event-driven solver: estimates, standard errors, correlations, identifiability.

The misfit is the sum of squared angle residuals (rad) over every tracked angle of every frame, minimised by
scipy's `least_squares` (trust region reflective) over θ = (u, start states) with the Jacobian of
shooting.py. At the optimum, with J the Jacobian there and n residuals,

    σ̂² = |r|² / (n − rank J),     Cov(θ) = σ̂² (JᵀJ)⁻¹

(the Gauss–Newton covariance with the residual variance estimated from the fit: the noise level need not be
known). A standard error of u is a relative standard error of the parameter (u = log p); the error of p
itself is |dp/du| times it (the delta method). Correlations are Cov scaled by the standard errors.

A parameter is reported as not identifiable from the data when
- its column of J is zero: the data do not depend on it at all (a contact parameter of a run without a
  collision, a coupling between berries that do not move), or
- its standard error in u exceeds MAX_SE_U: the data do not fix it within a factor e^MAX_SE_U either way
  (JᵀJ nearly singular in its direction: the parameter has almost no effect, or another parameter has the
  same effect, which the correlations then show).
The condition number of JᵀJ (columns scaled to unit length) is reported beside it.
"""
from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import GrapefmuError
from .measured import Measured
from .params import Parameter, scene_with
from .shooting import FIT_ATOL, FIT_RTOL, Shooting

#: a standard error of u = log p above this (a factor e^0.5 ≈ 1.65 at one standard error) is "not identifiable"
MAX_SE_U = 0.5
#: a column of J shorter than this fraction of the residual norm's noise scale σ̂ is no sensitivity at all
ZERO_COLUMN = 1e-9
#: correlations of estimated parameters beyond this are named in a warning
HIGH_CORRELATION = 0.95
#: a lag-1 autocorrelation of a trace's residuals above this is reported as structure (white noise: ±1/√n)
MAX_AUTOCORRELATION = 0.5
#: how far from its start a parameter may go, in u (a factor e^BOUND_U ≈ 1000 either way for log p)
BOUND_U = 7.0


@dataclass(frozen=True)
class Estimate:
    key: str
    unit: str
    transform: str
    start: float          # the scene's value
    value: float          # the estimate
    se: float             # its standard error (delta method); inf when not identifiable by sensitivity
    u: float              # the estimate in the transformed scale
    se_u: float
    identifiable: bool
    note: str = ""        # why not identifiable, or that it stopped at a bound

    @property
    def relative_se(self) -> float:
        return self.se / abs(self.value) if self.value else float("inf")


@dataclass
class Trace:
    """One measured angle against the fitted model, for the residual figure."""

    series: str
    dof: str
    t: np.ndarray
    measured: np.ndarray
    fitted: np.ndarray


@dataclass
class FitResult:
    estimates: list[Estimate]
    correlation: np.ndarray       # (P, P) of u, NaN where a parameter has no sensitivity
    cov_u: np.ndarray             # (P, P)
    sigma: float                  # rad, the residuals' estimated standard deviation
    residuals: int                # n
    unknowns: int                 # rank of J: parameters and start states the data inform
    condition: float              # of JᵀJ, columns scaled to unit length
    iterations: int               # residual evaluations by least_squares
    seconds: float
    warnings: list[str]
    fitted_doc: dict[str, Any]
    traces: list[Trace] = field(default_factory=list)

    @property
    def identifiable(self) -> list[Estimate]:
        return [e for e in self.estimates if e.identifiable]

    def as_json(self) -> dict[str, Any]:
        """What `risk --fit` reads: the estimates in u and their covariance (the unidentifiable left out)."""
        return {
            "parameters": [{"key": e.key, "transform": e.transform, "unit": e.unit, "start": e.start,
                            "estimate": e.value, "standard_error": _finite(e.se), "u": e.u, "se_u": _finite(e.se_u),
                            "identifiable": e.identifiable, "note": e.note} for e in self.estimates],
            "covariance_u": [[_finite(x) for x in row] for row in self.cov_u],
            "correlation": [[_finite(x) for x in row] for row in self.correlation],
            "sigma_rad": self.sigma, "residuals": self.residuals, "unknowns": self.unknowns,
            "condition": _finite(self.condition), "evaluations": self.iterations, "warnings": self.warnings,
        }


def _finite(x: float) -> float | None:
    return float(x) if np.isfinite(x) else None


def fit(doc: dict[str, Any], base_dir: Path, params: list[Parameter], series: list[Measured], *, segments: int = 1,
        rtol: float = FIT_RTOL, atol: float = FIT_ATOL, max_evaluations: int = 200,
        progress: Callable[[int, float], None] | None = None) -> FitResult:
    """Estimate `params` of the scene document from the measured series (module docstring); `progress` is told
    after every evaluation of the misfit how many there were and the residuals' rms (rad)."""
    from scipy.optimize import least_squares

    start = time.perf_counter()
    if not params:
        raise GrapefmuError("--param: name at least one parameter to fit")
    problem = Shooting(doc, base_dir, params, series, segments, rtol, atol)
    problem.progress = progress
    P = len(params)
    n = sum(m.samples for m in series)
    if n <= problem.size:
        raise GrapefmuError(f"{n} measured angles for {problem.size} unknowns ({P} parameters and the start "
                            "states): record more frames or fit fewer parameters")
    lo = np.full(problem.size, -np.inf)
    hi = np.full(problem.size, np.inf)
    lo[:P], hi[:P] = problem.u0 - BOUND_U, problem.u0 + BOUND_U
    sol = least_squares(problem.residuals, problem.theta0, jac=problem.jacobian, bounds=(lo, hi), method="trf",
                        x_scale="jac", max_nfev=max_evaluations, xtol=1e-10, ftol=1e-10, gtol=1e-10)
    theta = sol.x
    r = problem.residuals(theta)
    J = problem.jacobian(theta)
    warnings = [w for m in series for w in m.warnings]
    if problem.failures:
        warnings.append(f"the solver failed at {problem.failures} trial point(s) of the search, which were "
                        "rejected; the estimates come from points where it did not")
    if sol.status == 0:
        warnings.append(f"least squares stopped after {sol.nfev} evaluations without converging; the estimates "
                        "are where it stopped")
    stats = _statistics(J, r, P)
    theta = theta.copy()
    theta[:P][stats["zero"]] = problem.u0[stats["zero"]]  # the data say nothing: keep the scene's value
    estimates = []
    for j, p in enumerate(params):
        u, se_u = float(theta[j]), float(stats["se"][j])
        note = ""
        if stats["zero"][j]:
            note = "no sensitivity: the data do not depend on it" + _hint(p) + "; the scene's value kept"
        elif not se_u <= MAX_SE_U:
            note = (f"standard error of {p.transform} {p.key} is {se_u:.3g}" + (
                f" (a factor {np.exp(min(se_u, 700)):.3g})" if p.transform == "log" else "")
                + ": the data hardly constrain it")
        at_bound = abs(u - problem.u0[j]) > BOUND_U - 1e-6
        if at_bound:
            note = (note + "; " if note else "") + "stopped at the search bound (a factor e^7 from its start)"
        ok = not stats["zero"][j] and se_u <= MAX_SE_U and not at_bound
        value = float(p.to_p(u))
        estimates.append(Estimate(p.key, p.unit, p.transform, float(p.to_p(problem.u0[j])), value,
                                  p.dp_du(u) * se_u if np.isfinite(se_u) else float("inf"), u, se_u, ok, note))
        if not ok:
            warnings.append(f"{p.key} is not identifiable from these data: {note}")
    corr = stats["corr"]
    for a in range(P):
        for b in range(a + 1, P):
            if abs(corr[a, b]) > HIGH_CORRELATION:
                warnings.append(f"{params[a].key} and {params[b].key} are correlated {corr[a, b]:+.3f}: the data "
                                "tell their effects apart only weakly")
    traces = _traces(problem, theta)
    warnings += _structured(traces, stats["sigma"])
    return FitResult(estimates, corr, stats["cov"], stats["sigma"], len(r), stats["rank"], stats["condition"],
                     sol.nfev, time.perf_counter() - start, warnings,
                     scene_with(doc, [p for p, z in zip(params, stats["zero"]) if not z], theta[:P][~stats["zero"]]),
                     traces)  # a parameter the data say nothing about is left as the scene gives it (each twig's own)


def _hint(p: Parameter) -> str:
    if p.key.startswith("contact."):
        return " (no collision in the record?)"
    if p.key.startswith("coupling."):
        return " (do the coupled berries move?)"
    return " (is its berry tracked, or does it touch a tracked one?)"


def _statistics(J: np.ndarray, r: np.ndarray, P: int) -> dict[str, Any]:
    """σ̂, the covariance of the parameters (start states marginalised), which columns are zero, the condition."""
    norms = np.linalg.norm(J, axis=0)
    n = len(r)
    rough = max(float(np.linalg.norm(r)) / np.sqrt(n), 1e-300)
    zero = norms <= ZERO_COLUMN * rough
    keep = np.flatnonzero(~zero)
    Jk = J[:, keep] / norms[keep]
    U, S, Vt = np.linalg.svd(Jk, full_matrices=False)
    rank = int(np.sum(S > S[0] * 1e-12)) if len(S) else 0
    sigma = float(np.linalg.norm(r) / np.sqrt(max(n - rank, 1)))
    with np.errstate(divide="ignore"):
        inv = np.where(S > 0, 1.0 / S**2, np.inf)
    cov_scaled = (Vt.T * inv) @ Vt
    cov_k = cov_scaled / np.outer(norms[keep], norms[keep]) * sigma**2
    cov = np.full((J.shape[1], J.shape[1]), np.nan)
    cov[np.ix_(keep, keep)] = cov_k
    for j in np.flatnonzero(zero):
        cov[j, j] = np.inf
    covp = cov[:P, :P]
    se = np.sqrt(np.diag(covp))
    with np.errstate(invalid="ignore", divide="ignore"):
        corr = covp / np.outer(se, se)
    condition = float((S[0] / S[-1]) ** 2) if len(S) and S[-1] > 0 else float("inf")
    return {"se": se, "cov": covp, "corr": corr, "zero": zero[:P], "sigma": sigma, "rank": rank,
            "condition": condition}


def _structured(traces: list[Trace], sigma: float) -> list[str]:
    """A warning per trace whose residuals are not white: measurement noise is independent from frame to frame,
    so a lag-1 autocorrelation beyond MAX_AUTOCORRELATION (5 standard deviations of white noise's at 100 frames)
    means the model misses the data there: a local minimum (another start, other --segments) or model error."""
    out = []
    for tr in traces:
        r = tr.measured - tr.fitted
        r = r[np.isfinite(r)]
        if len(r) < 20 or not np.any(r):
            continue
        rho = float(np.sum(r[1:] * r[:-1]) / np.sum(r * r))
        if rho > MAX_AUTOCORRELATION:
            out.append(f"the residuals of angle {tr.dof} in {tr.series} from {tr.t[0]:.3g} s to {tr.t[-1]:.3g} s are "
                       f"structured (lag-1 autocorrelation {rho:.2f}, rms {np.sqrt(np.mean(r * r)):.3g} rad against "
                       f"σ̂ {sigma:.3g} rad): the fit may sit in a local minimum (start elsewhere, change --segments) "
                       "or the model misses something there")
    return out


def _traces(problem: Shooting, theta: np.ndarray) -> list[Trace]:
    out = []
    for seg, fitted in zip(problem.segments, problem.fitted(theta)):
        m = problem.series[seg.series]
        for n, dof in enumerate(m.dofs):
            out.append(Trace(m.path.name, dof, m.t[seg.rows], m.angles[seg.rows, n], fitted[:, n]))
    return out

"""Parameter distributions for a Monte Carlo risk estimate: from a fit's covariance, or from ranges.

Both live in the scale the fit estimates in (fit/params.py: u = log p for a positive parameter, logit e for
the restitution):
- from a fit (`--fit fit.json`): u ~ Normal(û, Cov(û)) over the parameters the fit found identifiable, the
  correlations included (so p is log-normal: positive, and as uncertain as the data left it);
- from a range (`--range KEY=LOW:HIGH`): u uniform between u(LOW) and u(HIGH), independent of the others (a
  positive range is log-uniform: every factor within it equally likely, which suits ranges spanning a
  decade such as docs/parameters.md's). A range for a key the fit also has replaces the fit's for that key.
"""
from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import GrapefmuError
from ..fit.params import Parameter, parameter
from ..sweep.spec import same_value


@dataclass(frozen=True)
class Range:
    parameter: Parameter
    low: float
    high: float


@dataclass(frozen=True)
class Distribution:
    """A joint distribution of scene parameters: a multivariate normal in u (from a fit) and uniform ranges."""

    normal: tuple[Parameter, ...] = ()
    mean_u: tuple[float, ...] = ()
    cov_u: tuple[tuple[float, ...], ...] = ()
    ranges: tuple[Range, ...] = ()
    source: str = ""

    @property
    def keys(self) -> list[str]:
        return [p.key for p in self.normal] + [r.parameter.key for r in self.ranges]

    def describe(self) -> dict[str, Any]:
        """Everything the draws depend on (with the seed and count): a sweep's fingerprint is made from it."""
        return {"normal": [p.key for p in self.normal], "mean_u": list(self.mean_u),
                "cov_u": [list(r) for r in self.cov_u],
                "ranges": [[r.parameter.key, r.low, r.high] for r in self.ranges]}

    def draw(self, samples: int, seed: int) -> dict[str, list[float]]:
        """`samples` joint draws, as values of each key (in the scene's units), fixed by the seed."""
        rng = np.random.default_rng(seed)
        out: dict[str, list[float]] = {}
        if self.normal:
            u = rng.multivariate_normal(np.array(self.mean_u), np.array(self.cov_u), size=samples,
                                        method="eigh")
            for k, p in enumerate(self.normal):
                out[p.key] = [float(x) for x in p.to_p(u[:, k])]
        for r in self.ranges:
            p = r.parameter
            u = rng.uniform(float(p.to_u(r.low)), float(p.to_u(r.high)), size=samples)
            out[p.key] = [float(x) for x in p.to_p(u)]
        return out

    def spread(self) -> list[tuple[str, str]]:
        """Each key and its distribution as one line, for the report."""
        rows = []
        for k, p in enumerate(self.normal):
            sd = math.sqrt(self.cov_u[k][k])
            lo, hi = (float(p.to_p(self.mean_u[k] + s * 1.96 * sd)) for s in (-1, 1))
            rows.append((p.key, f"fit: {float(p.to_p(self.mean_u[k])):.4g}, 95 % of draws in [{lo:.4g}, {hi:.4g}] "
                                f"({'log' if p.transform == 'log' else 'logit'}-normal, correlated)"))
        for r in self.ranges:
            kind = "log-uniform" if r.parameter.transform == "log" else "logit-uniform"
            rows.append((r.parameter.key, f"{kind} in [{r.low:.4g}, {r.high:.4g}]"))
        return rows


def parse_range(text: str, doc: dict[str, Any]) -> Range:
    """`KEY=LOW:HIGH` (a key fit/params.py allows, present in the plan) as a Range."""
    key, eq, bounds = text.partition("=")
    low, colon, high = bounds.partition(":")
    try:
        lo, hi = float(low), float(high)
    except ValueError:
        lo = hi = math.nan
    if not (eq and colon and math.isfinite(lo) and math.isfinite(hi) and lo < hi):
        raise GrapefmuError(f"--range {text}: expected KEY=LOW:HIGH with numbers LOW < HIGH, "
                            "e.g. berries[*].hinge_stiffness=3e-4:3e-3")
    p = parameter(key.strip(), doc, "--range", drawn=True)
    if lo <= 0 or (p.transform == "logit" and hi >= 1):
        need = "0 < LOW < HIGH < 1" if p.transform == "logit" else "0 < LOW < HIGH"
        raise GrapefmuError(f"--range {text}: {p.key} needs {need}")
    return Range(p, lo, hi)


def distribution(doc: dict[str, Any], fit: str | Path | None = None, ranges: list[str] = ()) -> Distribution:
    """The distribution the command line asks for, checked against a plan's scene document."""
    rs = [parse_range(t, doc) for t in ranges]
    if len({r.parameter.key for r in rs}) != len(rs):
        raise GrapefmuError("--range: a key is given twice")
    same_value(doc, [r.parameter.key for r in rs], "--range")
    if fit is None:
        if not rs:
            raise GrapefmuError("--fit, --range: neither given; the parameters' distribution comes from --fit "
                                "FIT.json (grapefmu fit --report) and/or --range KEY=LOW:HIGH")
        return Distribution(ranges=tuple(rs), source="ranges")
    report = _read_fit(Path(fit))
    overridden = {r.parameter.key for r in rs}
    rows = [(k, p) for k, p in enumerate(report["parameters"]) if p["key"] not in overridden]
    for _, p in rows:
        if not p.get("identifiable"):
            raise GrapefmuError(f"--fit {fit}: {p['key']} was not identifiable in that fit ({p.get('note', '')}); "
                                f"give its range instead: --range {p['key']}=LOW:HIGH")
    params = tuple(parameter(p["key"], doc, f"--fit {fit}", drawn=True) for _, p in rows)
    same_value(doc, [p.key for p in params] + [r.parameter.key for r in rs], f"--fit {fit}, --range")
    for par, (_, row) in zip(params, rows):
        if "unit" in row and row["unit"] != par.unit:  # a stiffness fitted for one contact law, drawn for another
            raise GrapefmuError(f"--fit {fit}: {par.key} was fitted in {row['unit']}; this plan's contact law takes "
                                f"{par.unit}")
    idx = [k for k, _ in rows]
    cov = np.array(report["covariance_u"], dtype=float)[np.ix_(idx, idx)]
    if not np.all(np.isfinite(cov)) or np.any(np.linalg.eigvalsh(cov) < -1e-12 * max(np.abs(cov).max(), 1e-300)):
        raise GrapefmuError(f"--fit {fit}: its covariance is not a finite positive semi-definite matrix")
    return Distribution(params, tuple(float(p["u"]) for _, p in rows), tuple(tuple(r) for r in cov.tolist()),
                        tuple(rs), source=str(fit))


def _read_fit(path: Path) -> dict[str, Any]:
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
        params = doc["parameters"]
        cov = doc["covariance_u"]
        number = lambda x: isinstance(x, (int, float)) and not isinstance(x, bool)  # noqa: E731
        ok = isinstance(params, list) and all(isinstance(p, dict) and isinstance(p.get("key"), str) and
                                              number(p.get("u")) and abs(p["u"]) < 700.0
                                              for p in params)  # u: a log or a logit; exp(u) overflows past 709
        ok = ok and isinstance(cov, list) and len(cov) == len(params) and all(
            isinstance(r, list) and len(r) == len(params) and all(x is None or number(x) for x in r) for r in cov)
    except OSError as e:
        raise GrapefmuError(f"--fit {path}: cannot read: {e.strerror or e}") from None
    except (ValueError, KeyError, TypeError, UnicodeDecodeError):
        ok = False
    if not ok:
        raise GrapefmuError(f"--fit {path}: not a fit report; expected the JSON that grapefmu fit --report writes")
    return {"parameters": params, "covariance_u": [[math.nan if x is None else x for x in r] for r in cov]}

"""Damage risk of handling plans: Monte Carlo over uncertain parameters on the sweep engine (docs/fit_and_risk.md)."""
from .assess import Risk, assess
from .draws import Distribution, distribution
from .montecarlo import Outcome, Probability, clopper_pearson, run_plan, time_scaled
from .search import Search, fastest

__all__ = ["Distribution", "Outcome", "Probability", "Risk", "Search", "assess", "clopper_pearson", "distribution",
           "fastest", "run_plan", "time_scaled"]

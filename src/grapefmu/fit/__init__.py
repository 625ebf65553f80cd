"""Parameter estimation from measured swings: least squares on the event-driven solver (docs/fit_and_risk.md)."""
from .estimate import Estimate, FitResult, fit
from .measured import Measured, read_measured
from .params import Parameter, parameters

__all__ = ["Estimate", "FitResult", "Measured", "Parameter", "fit", "parameters", "read_measured"]

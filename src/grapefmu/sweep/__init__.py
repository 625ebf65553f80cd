"""Parameter sweeps: a grid or Monte Carlo over scene parameters, one Parquet row per run."""
from .run import run_sweep
from .spec import SweepSpec, load_spec

__all__ = ["SweepSpec", "load_spec", "run_sweep"]

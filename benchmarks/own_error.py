"""Each version's own error at rtol 1e-10 (atol 1e-12) against the same version at rtol 1e-13, on the scenes where
two versions differ most (benchmarks/compare_versions.py): when the integrator changed, the versions differ by about
the sum of these. Run it under each version:
    .venv/bin/python benchmarks/own_error.py
    PYTHONPATH=<other checkout>/src .venv/bin/python benchmarks/own_error.py"""
from __future__ import annotations

from pathlib import Path

import numpy as np

import grapefmu
from grapefmu.scenefile import load_scene

ROOT = Path(__file__).resolve().parents[1]


def main() -> None:
    for name in ("setdown_fast.toml", "paper/test8.toml", "paper/test6.toml"):
        sc = load_scene(ROOT / "scenes" / name)
        ref = grapefmu.simulate(sc, rtol=1e-13, atol=1e-15, output_interval=1e-3)
        run = grapefmu.simulate(sc, rtol=1e-10, atol=1e-12, output_interval=1e-3)
        n = min(len(ref.t), len(run.t))
        print(f"{name}: largest angle error at rtol 1e-10 against rtol 1e-13: "
              f"{np.abs(run.angles[:n] - ref.angles[:n]).max():.2e} rad")


if __name__ == "__main__":
    main()

"""The quiet-step certificate's travel bound (solver/broadphase.py): never below how far the dense output really
goes, and tight where the sum of the power coefficients' magnitudes is not."""
from __future__ import annotations

import numpy as np

from grapefmu.solver.broadphase import travel
from grapefmu.solver.tableau import DOP853


def test_travel_bounds_the_dense_output_and_is_tight():
    rng = np.random.default_rng(7)
    theta = np.linspace(0.0, 1.0, 4001)
    for n in (3, 4, 7):
        for _ in range(200):
            q = rng.normal(size=(1, n)) * rng.choice([1e-3, 1.0, 300.0])
            h = float(rng.uniform(1e-5, 1e-2))
            dense = h * sum(q[0, j] * theta ** (j + 1) for j in range(n))  # y(θ) − y(0)
            reached = np.abs(dense).max()
            bound = travel(q, h, 0)
            assert reached <= bound * (1 + 1e-12) + 1e-300
            assert bound <= h * np.abs(q).sum() * (1 + 1e-12)
    # a DOP853 dense output of a smooth motion: its power coefficients cancel, Σ|Q| overstates the travel many times
    q = DOP853.p.T @ np.sin(np.linspace(0.0, 1.0, DOP853.p.shape[0]))[:, None]  # (7, 1): any mix of the stages
    q = np.ascontiguousarray(q.T)
    reached = np.abs(sum(q[0, j] * theta ** (j + 1) for j in range(q.shape[1]))).max()
    assert travel(q, 1.0, 0) <= 4 * reached < np.abs(q).sum()

"""The quiet-step certificate's travel bound (solver/broadphase.py): never below how far the dense output really
goes, and tight where the sum of the power coefficients' magnitudes is not."""
from __future__ import annotations

import math

import numpy as np

from grapefmu.solver.broadphase import BERNSTEIN, travel
from grapefmu.solver.drift import off_path
from grapefmu.solver.tableau import BOGACKI_SHAMPINE, DOP853, DOPRI5


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


def test_the_drift_bound_covers_the_distance_from_the_extrapolated_path():
    """solver/drift.off_path: never below how far the dense output really gets from the window's extrapolated path
    q̂ (the step starting e0 off it, the path's slope c1/h and curvature 2 c2/h² over the step)."""
    rng = np.random.default_rng(11)
    theta = np.linspace(0.0, 1.0, 4001)
    for n in (4, 5, 7):
        for _ in range(200):
            q = rng.normal(size=(1, n)) * rng.choice([1e-3, 1.0, 300.0])
            h = float(rng.uniform(1e-5, 1e-2))
            e0, c1, c2 = rng.normal(size=3) * np.array([1e-4, h, h * h * 50.0])
            off = e0 + h * sum(q[0, j] * theta ** (j + 1) for j in range(n)) - c1 * theta - c2 * theta ** 2
            bound = off_path(q, h, 0, e0, c1, c2)
            assert np.abs(off).max() <= bound * (1 + 1e-12) + 1e-300
            assert bound <= (abs(e0) + h * np.abs(q).sum() + abs(c1) + abs(c2)) * (1 + 1e-12)


def test_the_bernstein_weights_are_the_binomial_ratios_for_every_dense_output():
    """The table the bounds read (broadphase.BERNSTEIN) against C(i, m) / C(n, m) from math.comb, for every degree a
    tableau's dense output has."""
    for tableau in (BOGACKI_SHAMPINE, DOPRI5, DOP853):
        assert tableau.p.shape[1] < BERNSTEIN.shape[0]
    for n in range(1, BERNSTEIN.shape[0]):
        for i in range(1, n + 1):
            for m in range(1, i + 1):
                assert math.isclose(BERNSTEIN[n, i, m], math.comb(i, m) / math.comb(n, m), rel_tol=1e-14)

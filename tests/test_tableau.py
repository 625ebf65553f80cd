"""The Runge–Kutta pairs checked on their own, in plain numpy: order conditions, observed order of the
step and of its dense output on a pendulum against the exact (elliptic-function) solution."""
from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.special import ellipj, ellipk

from grapefmu.solver.tableau import BOGACKI_SHAMPINE, DOP853, DOPRI5

THETA0 = 2.0  # rad: a large swing, far from the linear pendulum


def pendulum(t, y):
    return np.array([y[1], -math.sin(y[0])])


def exact(t):
    """θ(t) = 2 arcsin(k cd(t | k²)) for a pendulum released at rest from THETA0 (ω0² = 1)."""
    k = math.sin(THETA0 / 2)
    sn, cn, dn, _ = ellipj(ellipk(k * k) - t, k * k)
    return 2 * math.asin(k * sn)


def step(TB, t0, y0, h):
    """One step as solver/step.py takes it: the stages, FSAL, the extra stages and the power-basis q."""
    S = TB.p.shape[0]
    s = TB.b.shape[0]
    K = np.zeros((S, y0.size))
    K[0] = pendulum(t0, y0)
    for i in range(1, s):
        K[i] = pendulum(t0 + TB.c[i] * h, y0 + h * TB.a[i, :i] @ K[:i])
    y1 = y0 + h * TB.b @ K[:s]
    K[s] = pendulum(t0 + h, y1)
    for i in range(TB.c_extra.shape[0]):
        K[s + 1 + i] = pendulum(t0 + TB.c_extra[i] * h, y0 + h * TB.a_extra[i, :s + 1 + i] @ K[:s + 1 + i])
    q = K.T @ TB.p
    return y1, (lambda th: y0 + h * sum(q[:, j] * th ** (j + 1) for j in range(q.shape[1]))), h * K[:s + 1].T @ TB.e


@pytest.mark.parametrize("TB", [BOGACKI_SHAMPINE, DOPRI5, DOP853], ids=["BS3", "DOPRI5", "DOP853"])
def test_quadrature_and_row_sum_conditions(TB):
    """Σ b c^(k-1) = 1/k up to the order, and every stage's row sums to its node (extra stages included)."""
    for k in range(1, TB.order + 1):
        assert TB.b @ TB.c ** (k - 1) == pytest.approx(1 / k, abs=1e-14)
    assert np.allclose(TB.a.sum(axis=1), TB.c, atol=1e-14)
    if TB.c_extra.size:
        assert np.allclose(TB.a_extra.sum(axis=1), TB.c_extra, atol=1e-14)
    assert TB.e.shape == (TB.b.shape[0] + 1,) and abs(TB.e.sum()) < 1e-14  # an estimate of 0 for y' = const


def _global_error(TB, h, T=4.0):
    y, t = np.array([THETA0, 0.0]), 0.0
    for _ in range(round(T / h)):
        y, _, _ = step(TB, t, y, h)
        t += h
    return abs(y[0] - exact(t))


@pytest.mark.parametrize("TB,hs", [(DOPRI5, [0.2, 0.1, 0.05]), (DOP853, [0.4, 0.3, 0.2])], ids=["DOPRI5", "DOP853"])
def test_observed_order_on_a_pendulum(TB, hs):
    errors = np.array([_global_error(TB, h) for h in hs])
    order = np.polyfit(np.log(hs), np.log(errors), 1)[0]
    print(f"order {order:.2f}, errors {errors}")
    assert TB.order - 0.5 < order < TB.order + 1.5  # DOP853: 8.8 (5.2 DOPRI5)


@pytest.mark.parametrize("TB", [DOPRI5, DOP853], ids=["DOPRI5", "DOP853"])
def test_dense_output_ends_at_the_step_and_has_its_order_inside(TB):
    """At θ = 1 the interpolant is the step's end (to the rounding of the power basis: DOP853's coefficients
    reach 545 and their absolute row sums 3.5e3, so θ = 1 carries up to that many ulps of h·|f|); inside, its
    local error falls as h^(k+1) for a degree-k interpolant of order k (4 for DOPRI5, 7 for DOP853)."""
    y0 = np.array([THETA0, 0.0])
    h = 0.3
    y1, dense, _ = step(TB, 0.0, y0, h)
    ulps = np.abs(TB.p).sum(axis=0).max() * np.finfo(float).eps
    assert np.allclose(dense(1.0), y1, rtol=0, atol=h * ulps * 2.0)
    hs = np.array([0.8, 0.4, 0.2])
    errors = []
    for h in hs:
        _, dense, _ = step(TB, 0.0, y0, h)
        errors.append(max(abs(dense(th)[0] - exact(th * h)) for th in (0.3, 0.5, 0.7)))
    order = np.polyfit(np.log(hs), np.log(errors), 1)[0]
    k = TB.p.shape[1]
    print(f"local order {order:.2f}, errors {errors}")
    assert k + 0.5 < order < k + 2.5  # 5.9 for DOPRI5, 7.9 for DOP853


def test_dop853_error_estimate_is_fifth_order():
    """The embedded estimate of DOP853 falls as h^6 per step: what error_order 7 (the exponent scipy uses for
    the step size, -1/8) rests on is its ratio to the true error staying bounded as h shrinks."""
    y0 = np.array([THETA0, 0.0])
    hs = np.array([0.4, 0.2, 0.1])
    est = [abs(step(DOP853, 0.0, y0, h)[2][0]) for h in hs]
    order = np.polyfit(np.log(hs), np.log(est), 1)[0]
    print(f"estimate order {order:.2f}: {est}")
    assert 5.5 < order < 7.0


def test_dop853_coefficients_are_scipys():
    """The written-out coefficients (tableau.py) are scipy's dop853_coefficients, bit for bit."""
    from scipy.integrate._ivp import dop853_coefficients as d

    s = d.N_STAGES
    assert np.array_equal(DOP853.a, d.A[:s, :s]) and np.array_equal(DOP853.b, d.B)
    assert np.array_equal(DOP853.c, d.C[:s]) and np.array_equal(DOP853.e, d.E5) and np.array_equal(DOP853.e3, d.E3)
    assert np.array_equal(DOP853.a_extra, d.A[s + 1:]) and np.array_equal(DOP853.c_extra, d.C[s + 1:])

"""Butcher tableaux with embedded error estimates and continuous extensions (as in scipy.integrate).

Dormand–Prince 5(4) drives the event-driven solver at loose tolerances and Dormand–Prince 8(5,3)
(DOP853) at tight ones (solver.Solver picks by rtol); Bogacki–Shampine 3(2), MATLAB's ode23, drives
the imitation of the paper's method. All share one type (the tableau travels into compiled code):
a field a pair does not use is an empty array, and the compiled side branches on its shape.
"""
from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numpy.polynomial import polynomial as npoly
from scipy.integrate._ivp import dop853_coefficients as d853


class Tableau(NamedTuple):
    a: np.ndarray       # (s, s)
    b: np.ndarray       # (s,)
    c: np.ndarray       # (s,)
    e: np.ndarray       # (s + 1,) error weights, last one for the FSAL stage
    p: np.ndarray       # (S, k) dense-output polynomial coefficients over all S stages (S = s + 1 + m)
    order: int          # order of the propagated solution
    error_order: int    # order of the embedded estimate
    e3: np.ndarray      # (s + 1,) DOP853's third-order estimate, which tempers the fifth's (empty otherwise)
    a_extra: np.ndarray  # (m, S) the m stages only the dense output needs, after the FSAL stage ((0, 0) if none)
    c_extra: np.ndarray  # (m,)


NO_E3, NO_A_EXTRA, NO_C_EXTRA = np.zeros(0), np.zeros((0, 0)), np.zeros(0)


DOPRI5 = Tableau(
    a=np.array([[0, 0, 0, 0, 0, 0],
                [1 / 5, 0, 0, 0, 0, 0],
                [3 / 40, 9 / 40, 0, 0, 0, 0],
                [44 / 45, -56 / 15, 32 / 9, 0, 0, 0],
                [19372 / 6561, -25360 / 2187, 64448 / 6561, -212 / 729, 0, 0],
                [9017 / 3168, -355 / 33, 46732 / 5247, 49 / 176, -5103 / 18656, 0]], dtype=float),
    b=np.array([35 / 384, 0, 500 / 1113, 125 / 192, -2187 / 6784, 11 / 84]),
    c=np.array([0, 1 / 5, 3 / 10, 4 / 5, 8 / 9, 1]),
    e=np.array([-71 / 57600, 0, 71 / 16695, -71 / 1920, 17253 / 339200, -22 / 525, 1 / 40]),
    p=np.array([
        [1, -8048581381 / 2820520608, 8663915743 / 2820520608, -12715105075 / 11282082432],
        [0, 0, 0, 0],
        [0, 131558114200 / 32700410799, -68118460800 / 10900136933, 87487479700 / 32700410799],
        [0, -1754552775 / 470086768, 14199869525 / 1410260304, -10690763975 / 1880347072],
        [0, 127303824393 / 49829197408, -318862633887 / 49829197408, 701980252875 / 199316789632],
        [0, -282668133 / 205662961, 2019193451 / 616988883, -1453857185 / 822651844],
        [0, 40617522 / 29380423, -110615467 / 29380423, 69997945 / 29380423]]),
    order=5,
    error_order=4,
    e3=NO_E3, a_extra=NO_A_EXTRA, c_extra=NO_C_EXTRA,
)

BOGACKI_SHAMPINE = Tableau(
    a=np.array([[0, 0, 0], [1 / 2, 0, 0], [0, 3 / 4, 0]], dtype=float),
    b=np.array([2 / 9, 1 / 3, 4 / 9]),
    c=np.array([0, 1 / 2, 3 / 4]),
    e=np.array([5 / 72, -1 / 12, -1 / 9, 1 / 8]),
    p=np.array([[1, -4 / 3, 5 / 9], [0, 1, -2 / 3], [0, 4 / 3, -8 / 9], [0, -1, 1]]),
    order=3,
    error_order=2,
    e3=NO_E3, a_extra=NO_A_EXTRA, c_extra=NO_C_EXTRA,
)


def _dop853_dense() -> np.ndarray:
    """DOP853's interpolant in the power basis every tableau's dense output uses: (y(t0 + θh) − y0)/h =
    Σ_j Q_j θ^(j+1) with Q = Kᵀ P over the 16 stages K. scipy writes it (Dop853DenseOutput) as
    θ(F0 + (1−θ)(F1 + θ(F2 + (1−θ)(F3 + θ(F4 + (1−θ)(F5 + θ F6)))))) with F0 = Δy, F1 = h f0 − Δy,
    F2 = 2Δy − h(f0 + f1), F3..6 = h D K; every F is h times a combination of the stages."""
    n_all, s = d853.N_STAGES_EXTENDED, d853.N_STAGES
    b = np.zeros(n_all)
    b[:s] = d853.B
    f0, f1 = np.eye(n_all)[0], np.eye(n_all)[s]
    F = np.vstack([b, f0 - b, 2 * b - f0 - f1, d853.D])        # (7, 16): F_i / h in the stages
    x, one_minus = np.array([0.0, 1.0]), np.array([1.0, -1.0])
    basis, poly = [], np.array([1.0])
    for i in range(F.shape[0]):                                 # θ, θ(1−θ), θ²(1−θ), θ²(1−θ)², ...
        poly = npoly.polymul(poly, x if i % 2 == 0 else one_minus)
        basis.append(np.pad(poly, (0, d853.INTERPOLATOR_POWER + 1 - poly.size))[1:])
    return np.ascontiguousarray(F.T @ np.array(basis))         # (16, 7): powers θ^1..θ^7


DOP853 = Tableau(
    a=np.ascontiguousarray(d853.A[:d853.N_STAGES, :d853.N_STAGES]),
    b=d853.B.copy(),
    c=d853.C[:d853.N_STAGES].copy(),
    e=d853.E5.copy(),
    p=_dop853_dense(),
    order=8,
    error_order=7,
    e3=d853.E3.copy(),
    a_extra=np.ascontiguousarray(d853.A[d853.N_STAGES + 1:]),
    c_extra=d853.C[d853.N_STAGES + 1:].copy(),
)
"""Dormand–Prince 8(5,3) as in scipy's DOP853: twelve stages plus FSAL, an error estimate of order 5
tempered by one of order 3 (error_order 7 sets the step-size exponent, as in scipy), and a degree-7
interpolant that needs three more right-hand sides after a step is accepted."""

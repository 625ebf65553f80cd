"""Butcher tableaux with embedded error estimates and continuous extensions (as in scipy.integrate).

Dormand–Prince 5(4) drives the event-driven solver; Bogacki–Shampine 3(2), MATLAB's ode23,
drives the imitation of the paper's method.
"""
from __future__ import annotations

from typing import NamedTuple

import numpy as np


class Tableau(NamedTuple):
    a: np.ndarray       # (s, s)
    b: np.ndarray       # (s,)
    c: np.ndarray       # (s,)
    e: np.ndarray       # (s + 1,) error weights, last one for the FSAL stage
    p: np.ndarray       # (s + 1, k) dense-output polynomial coefficients
    order: int          # order of the propagated solution
    error_order: int    # order of the embedded estimate


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
)

BOGACKI_SHAMPINE = Tableau(
    a=np.array([[0, 0, 0], [1 / 2, 0, 0], [0, 3 / 4, 0]], dtype=float),
    b=np.array([2 / 9, 1 / 3, 4 / 9]),
    c=np.array([0, 1 / 2, 3 / 4]),
    e=np.array([5 / 72, -1 / 12, -1 / 9, 1 / 8]),
    p=np.array([[1, -4 / 3, 5 / 9], [0, 1, -2 / 3], [0, 4 / 3, -8 / 9], [0, -1, 1]]),
    order=3,
    error_order=2,
)

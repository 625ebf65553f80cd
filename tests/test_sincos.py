"""The kinematics' sin and cos (physics/kinematics.sincos) against libm: every angle of every stage passes there."""
import math

import numpy as np
from numba import njit

from grapefmu.physics.kinematics import TRIG_GRID, TRIG_POINTS, sincos


@njit
def _both(x, out):
    for i in range(x.shape[0]):
        out[i, 0], out[i, 1] = sincos(x[i])


def _eval(x):
    out = np.empty((x.shape[0], 2))
    _both(x, out)
    return out


def test_sincos_is_libm_to_a_few_ulp_of_one_everywhere():
    edge = TRIG_POINTS / TRIG_GRID
    mid = (np.arange(-TRIG_POINTS, TRIG_POINTS) + 0.5) / TRIG_GRID  # where the nearest grid point changes
    x = np.concatenate([np.random.default_rng(3).uniform(-1.5 * edge, 1.5 * edge, 400_000), mid,
                        np.nextafter(mid, np.inf), np.nextafter(mid, -np.inf), [0.0, -0.0, 1e-300, edge, -edge,
                        np.nextafter(edge, np.inf), math.pi, -math.pi / 2, 1e5]])
    got = _eval(x)
    assert np.abs(got[:, 0] - np.sin(x)).max() <= 2.5e-16
    assert np.abs(got[:, 1] - np.cos(x)).max() <= 2.5e-16
    assert np.abs(got[:, 0] ** 2 + got[:, 1] ** 2 - 1.0).max() <= 3 * np.spacing(1.0)
    small = np.abs(x) < 1 / 32  # near 0 the table's point is 0: sin x to its own last bits
    assert np.all(np.abs(got[small, 0] - np.sin(x[small])) <= np.spacing(np.abs(np.sin(x[small]))))


def test_sincos_gives_nan_for_nan_and_infinite_angles():
    """Outside the table's bound check, int() of NaN or inf would index garbage: libm's NaN must come out."""
    assert np.isnan(_eval(np.array([np.nan, np.inf, -np.inf]))).all()

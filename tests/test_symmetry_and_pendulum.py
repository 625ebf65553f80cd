"""Exact mirror symmetry, and free swings against closed-form pendulum solutions."""
from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.special import ellipk

from grapefmu import simulate

from .conftest import dual, scene


@pytest.mark.parametrize("excitation", [None, {"kind": "sine", "amplitude": [0.0, 6.0], "frequency": 7.0}])
def test_mirrored_start_stays_mirrored_exactly(excitation):
    doc = dual(solver={"t_end": 2.0})
    if excitation:
        doc["excitation"] = excitation
    run = simulate(scene(doc))
    assert run.collision_count > 0
    assert np.array_equal(run.angles[:, 0], -run.angles[:, 1])


def single(angle, hinge_stiffness=0.0, hinge_damping=0.0, t_end=2.0):
    return scene({"berries": [{"name": "b", "mass": 0.011, "radius": 0.0135, "twig_length": 0.03, "hinge_x": 0.0,
                               "hinge_stiffness": hinge_stiffness, "hinge_damping": hinge_damping, "angle": angle}],
                  "solver": {"t_end": t_end}})


def test_small_angle_swing_matches_damped_oscillator():
    m, length, k, c, q0 = 0.011, 0.03, 1e-3, 2e-5, 1e-4
    run = simulate(single(q0, k, c), rtol=1e-11, atol=1e-15)
    inertia = m * length**2
    w0 = math.sqrt((m * 9.81 * length + k) / inertia)
    zeta = c / (2 * inertia * w0)
    wd = w0 * math.sqrt(1 - zeta**2)
    t = run.t
    q = q0 * np.exp(-zeta * w0 * t) * (np.cos(wd * t) + zeta * w0 / wd * np.sin(wd * t))
    # the analytic solution is linear; sin q ≈ q costs ~q0³/6 relative error
    assert np.abs(run.angles[:, 0] - q).max() < 1e-3 * q0


def test_large_angle_period_matches_elliptic_integral():
    q0 = 2.8  # close to the top
    run = simulate(single(q0, t_end=1.0), rtol=1e-12, atol=1e-14, output_interval=1e-4)
    period = 4 * ellipk(math.sin(q0 / 2) ** 2) / math.sqrt(9.81 / 0.03)
    q = run.angles[:, 0]
    # first upward zero crossing of q̇ after the start: half a period, at the far turning point
    w = run.angular_velocities[:, 0]
    k = np.nonzero((w[:-1] < 0) & (w[1:] >= 0))[0][0]
    t_half = run.t[k] - w[k] * (run.t[k + 1] - run.t[k]) / (w[k + 1] - w[k])
    assert t_half == pytest.approx(period / 2, rel=1e-6)
    assert np.abs(q).max() == pytest.approx(q0, rel=1e-9)

"""The compiled right-hand side against equations derived here from T, V and D with sympy.

The derivation is independent of the code: contact and coupling enter as potentials and
Rayleigh dissipation functions of the penetration δ and separation s, and the base
excitation as the potential of the uniform inertial field at the instant."""
from __future__ import annotations

import math

import numpy as np
import pytest
import sympy as sp

from grapefmu.physics.dynamics import rhs
from grapefmu.physics.layout import layout
from grapefmu.solver.solver import Solver

from grapefmu.model import Berry, ContactLaw, ContactPair, Coupling, Model, Scene

t = sp.symbols("t")
q1, q2 = (sp.Function("q1")(t), sp.Function("q2")(t))


def lagrange_accelerations(law: str):
    m1, m2, l1, l2, h1, h2, r1, r2, k1, k2, c1, c2, g, ax, ay = sp.symbols("m1 m2 l1 l2 h1 h2 r1 r2 k1 k2 c1 c2 g ax ay")
    kc, cc, k3, c3, vo = sp.symbols("kc cc k3 c3 vo")
    p1 = sp.Matrix([h1 + l1 * sp.sin(q1), -l1 * sp.cos(q1)])
    p2 = sp.Matrix([h2 + l2 * sp.sin(q2), -l2 * sp.cos(q2)])
    T = sp.Rational(1, 2) * (m1 * p1.diff(t).dot(p1.diff(t)) + m2 * p2.diff(t).dot(p2.diff(t)))
    # gravity plus the inertial field −m a of the moving rachis, frozen at the instant
    V = m1 * ((g + ay) * p1[1] + ax * p1[0]) + m2 * ((g + ay) * p2[1] + ax * p2[0])
    V += sp.Rational(1, 2) * (k1 * q1**2 + k2 * q2**2)
    D = sp.Rational(1, 2) * (c1 * q1.diff(t) ** 2 + c2 * q2.diff(t) ** 2)
    delta = r1 + r2 - sp.sqrt((p2 - p1).dot(p2 - p1))
    ddelta = delta.diff(t)
    if law == "kelvin-voigt":
        V += sp.Rational(1, 2) * kc * delta**2
        D += sp.Rational(1, 2) * cc * ddelta**2
    elif law == "hertz":
        V += sp.Rational(2, 5) * kc * delta ** sp.Rational(5, 2)
    else:  # hunt-crossley: F = K δ^1.5 (1 + χ δ̇ / v0), the damping part as a Rayleigh function
        V += sp.Rational(2, 5) * kc * delta ** sp.Rational(5, 2)
        D += sp.Rational(1, 2) * kc * delta ** sp.Rational(3, 2) * cc * ddelta**2 / vo
    s = (p2[0] - h2) - (p1[0] - h1)
    V += sp.Rational(1, 2) * k3 * s**2
    D += sp.Rational(1, 2) * c3 * s.diff(t) ** 2
    L = T - V
    eqs = [sp.diff(L.diff(qi.diff(t)), t) - L.diff(qi) + D.diff(qi.diff(t)) for qi in (q1, q2)]
    acc = sp.symbols("a1 a2")
    w = sp.symbols("w1 w2")
    x = sp.symbols("x1 x2")
    subs = {q1.diff(t, 2): acc[0], q2.diff(t, 2): acc[1]}
    subs2 = {q1.diff(t): w[0], q2.diff(t): w[1]}
    subs3 = {q1: x[0], q2: x[1]}
    eqs = [e.subs(subs).subs(subs2).subs(subs3) for e in eqs]
    # each equation is linear in its own acceleration (T is diagonal in q̇): a_i = −rest_i / mass_i
    params = (m1, m2, l1, l2, h1, h2, r1, r2, k1, k2, c1, c2, g, ax, ay, kc, cc, k3, c3, vo)
    mass = [e.diff(a) for e, a in zip(eqs, acc)]
    assert all(sp.simplify(e.diff(b)) == 0 for e, b in ((eqs[0], acc[1]), (eqs[1], acc[0])))
    rest = [e.subs({acc[0]: 0, acc[1]: 0}) for e in eqs]
    fm = sp.lambdify(params + x + w, mass, "mpmath")
    fr = sp.lambdify(params + x + w, rest, "mpmath")
    return lambda *a: [-r / m for r, m in zip(fr(*a), fm(*a))]


@pytest.mark.parametrize("law", ["kelvin-voigt", "hertz", "hunt-crossley"])
def test_compiled_rhs_matches_lagrange_equations(law):
    import mpmath

    mpmath.mp.dps = 30
    f = lagrange_accelerations(law)
    rng = np.random.default_rng(7)
    contact = {"law": law, "stiffness": 2000.0 if law == "kelvin-voigt" else 1.1e5}
    if law != "hertz":
        contact["damping"] = 1.3 if law == "kelvin-voigt" else 0.8
    checked = 0
    for trial in range(200):
        if checked == 20:
            break
        # random berries pressed into each other (δ > 0, loaded) under a random base acceleration
        m = rng.uniform(0.005, 0.02, 2)
        r = rng.uniform(0.008, 0.015, 2)
        length = rng.uniform(0.02, 0.05, 2)
        q = rng.uniform(-0.4, 0.4, 2)
        w = rng.uniform(-3, 3, 2)
        h = [-0.01, 0.0]
        # place the right hinge so the berries overlap by ~0.3 mm
        p1 = np.array([h[0] + length[0] * math.sin(q[0]), -length[0] * math.cos(q[0])])
        d_target = r.sum() - 3e-4
        dy = -length[1] * math.cos(q[1]) - p1[1]
        if abs(dy) > 0.8 * d_target:
            continue  # the berries cannot touch side by side at these angles; draw again
        h[1] = p1[0] + math.sqrt(d_target**2 - dy**2) - length[1] * math.sin(q[1])
        law_obj = ContactLaw(law, contact["stiffness"], contact.get("damping", 0.0))
        berries = tuple(Berry(nm, m[i], r[i], length[i], h[i], 1e-3 * (i + 1), 2e-5 * (i + 2))
                        for i, nm in enumerate(("left", "right")))
        sc = Scene(Model(berries, (ContactPair(0, 1, law_obj),), (Coupling(0, 1, 3.0, 0.02),), 9.81),
                   tuple(q), tuple(w))
        sol = Solver(sc)
        S = sol.state
        S.mode[:] = 1
        ax, ay = rng.uniform(-5, 5, 2)
        from grapefmu.model.excitation import constant
        X = constant(ax, ay).arrays
        S.v_onset[:] = 0.7
        dyv = np.zeros_like(S.y)
        rhs(0.0, 0.0, S.y, dyv, S.mode, S.v_onset, S.smooth, sol.M, X.kind, X.par, X.table)
        bb = sc.model.arrays.berry
        pp = sc.model.arrays.pair_par[0]
        args = (bb[0, 0], bb[1, 0], bb[0, 2], bb[1, 2], bb[0, 3], bb[1, 3], bb[0, 1], bb[1, 1], bb[0, 4], bb[1, 4],
                bb[0, 5], bb[1, 5], 9.81, ax, ay, pp[0], pp[1], 3.0, 0.02, 0.7, q[0], q[1], w[0], w[1])
        expect = [float(v) for v in f(*[mpmath.mpf(float(a)) for a in args])]
        lay = layout(2, 1, 1)
        got = dyv[lay.w]
        np.testing.assert_allclose(got, expect, rtol=1e-12, atol=0)
        assert np.all(dyv[lay.q] == w)
        checked += 1
    assert checked == 20


def test_pedicel_tension_balances_radial_forces():
    """T from its closed form against m p̈·e_r = −T + m(g⃗ − a)·e_r + F·e_r, with p̈ from the RHS."""
    berries = (Berry("left", 0.011, 0.0135, 0.03, -0.013, 1e-3, 2e-5), Berry("right", 0.012, 0.014, 0.035, 0.013, 1e-3, 2e-5))
    sc = Scene(Model(berries, (ContactPair(0, 1, ContactLaw("kelvin-voigt", 2000.0, 1.4)),),
                     (Coupling(0, 1, 2.0, 0.01),)), (0.12, -0.1), (0.0, 0.0))
    from grapefmu.model.excitation import constant
    from grapefmu.physics.dynamics import berry_forces, pedicel_tension
    sol = Solver(sc)
    S = sol.state
    S.y[2:4] = [1.2, -0.7]
    S.mode[:] = 1
    ax, ay = 1.5, -2.0
    X = constant(ax, ay).arrays
    dyv = np.zeros_like(S.y)
    rhs(0.0, 0.0, S.y, dyv, S.mode, S.v_onset, S.smooth, sol.M, X.kind, X.par, X.table)
    fext = np.zeros((2, 2))
    berry_forces(S.y, S.mode, S.v_onset, S.smooth, sol.M, np.zeros(1), np.zeros(1), fext)
    assert np.abs(fext).max() > 0.01  # the berries really push on each other here
    tens = np.zeros(2)
    pedicel_tension(S.y, ax, ay, fext, sol.M, tens)
    b = sc.model.arrays.berry
    for i in range(2):
        m, length = b[i, 0], b[i, 2]
        q, w, a = S.y[i], S.y[2 + i], dyv[2 + i]
        acc = length * np.array([a * math.cos(q) - w * w * math.sin(q), a * math.sin(q) + w * w * math.cos(q)])
        er = np.array([math.sin(q), -math.cos(q)])
        expected = -m * acc @ er + m * (np.array([-ax, -9.81 - ay]) @ er) + fext[i] @ er
        assert tens[i] == pytest.approx(expected, rel=1e-12)

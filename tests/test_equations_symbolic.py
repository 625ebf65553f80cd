"""The compiled right-hand side against equations derived here from T, V and D with sympy.

The derivation is independent of the code: contact and coupling enter as potentials and
Rayleigh dissipation functions of the penetration δ and separation s, and the base
excitation as the potential of the uniform inertial field at the instant."""
from __future__ import annotations

import math

import numpy as np
import pytest
import sympy as sp

from grapefmu.physics.dynamics import derivative
from grapefmu.physics.forces import CONTACT
from grapefmu.physics.layout import layout
from grapefmu.solver.solver import Solver

from grapefmu.model import Berry, ContactLaw, ContactPair, Coupling, Model, Scene

t = sp.symbols("t")
q1, q2 = (sp.Function("q1")(t), sp.Function("q2")(t))


def loaded(n_pairs: int, v_onset: float = 0.7) -> np.ndarray:
    """Every pair in mode 1 (loaded) with the given onset speed."""
    c = np.zeros(n_pairs, dtype=CONTACT)
    c["mode"], c["v_onset"] = 1, v_onset
    return c


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
        y = Solver(sc).y
        ax, ay = rng.uniform(-5, 5, 2)
        dyv = derivative(sc.arrays, y, loaded(1), (ax, 0.0, ay, 0.0, 0.0, 0.0))
        bb, pp = sc.model.arrays.berry, sc.model.arrays.pair[0]
        args = (*bb["mass"], *bb["twig_length"], *bb["hinge_x"], *bb["radius"], *bb["hinge_stiffness"],
                *bb["hinge_damping"], 9.81, ax, ay, pp["stiffness"], pp["damping"], 3.0, 0.02, 0.7, q[0], q[1], w[0], w[1])
        expect = [float(v) for v in f(*[mpmath.mpf(float(a)) for a in args])]
        lay = layout(2, 2, 1)
        got = dyv[lay.w]
        np.testing.assert_allclose(got, expect, rtol=1e-12, atol=0)
        assert np.all(dyv[lay.q] == w)
        checked += 1
    assert checked == 20


def test_pedicel_tension_balances_radial_forces():
    """T from the code against the berry's radial balance m p̈·e_r = −T + m(g⃗ − a)·e_r + F·e_r, with the
    contact force (Kelvin–Voigt, loaded) and the coupling force computed here from the geometry."""
    berries = (Berry("left", 0.011, 0.0135, 0.03, -0.013, 1e-3, 2e-5), Berry("right", 0.012, 0.014, 0.035, 0.013, 1e-3, 2e-5))
    k, c, k3, c3 = 2000.0, 1.4, 2.0, 0.01
    sc = Scene(Model(berries, (ContactPair(0, 1, ContactLaw("kelvin-voigt", k, c)),), (Coupling(0, 1, k3, c3),)),
               (0.12, -0.1), (0.0, 0.0))
    from grapefmu.physics.layout import initial, layout_of
    y = initial(layout_of(sc), sc)  # the berries 7.9 mm into each other: deeper than a run may start
    y[2:4] = [1.2, -0.7]
    ax, ay = 1.5, -2.0
    out = observe_one(sc, y, loaded(1, 0.1), (ax, 0.0, ay, 0.0, 0.0, 0.0))
    q, w = y[0:2], y[2:4]
    h = np.array([[b.hinge_x, 0.0] for b in berries])
    length = np.array([b.twig_length for b in berries])
    p = h + length[:, None] * np.column_stack([np.sin(q), -np.cos(q)])
    v = (length * w)[:, None] * np.column_stack([np.cos(q), np.sin(q)])
    d = p[1] - p[0]
    n = d / np.linalg.norm(d)
    delta = berries[0].radius + berries[1].radius - np.linalg.norm(d)
    f = k * delta + c * -(n @ (v[1] - v[0]))
    sep, sep_dot = d[0] - (h[1, 0] - h[0, 0]), v[1, 0] - v[0, 0]
    fc = k3 * sep + c3 * sep_dot
    fext = np.array([-f * n + [fc, 0.0], f * n - [fc, 0.0]])  # +F n on the pair's second berry
    assert delta > 0 and f > 0.01  # the berries really push on each other here
    for i, b in enumerate(berries):
        er = np.array([math.sin(q[i]), -math.cos(q[i])])
        radial = -b.twig_length * w[i] ** 2  # p̈·e_r of a point on a circle
        expected = -b.mass * radial + b.mass * (np.array([-ax, -9.81 - ay]) @ er) + fext[i] @ er
        assert out.pedicel_tension[0, i] == pytest.approx(expected, rel=1e-12)


def observe_one(sc, y, contacts, accel):
    from grapefmu.physics import observe as obs
    m = sc.model
    out = obs.empty(1, m.n_berries, m.n_dof, len(m.pairs))
    obs.observe(y[None, :], contacts[None, :], np.array([accel]), m.arrays, out)
    return out


def spherical_lagrange(law: str):
    """Two spherical pendulums on hinges anywhere in space, each in its own azimuth frame, with
    hinge rest angles, a contact law and the rachis' acceleration (ax, az): M(x) a = −rest(x, ẋ)."""
    sym = sp.symbols("m1 m2 l1 l2 r1 r2 k1 k2 c1 c2 g ax az kc cc vo")
    m1, m2, l1, l2, r1, r2, k1, k2, c1, c2, g, ax, az, kc, cc, vo = sym
    hinge = [sp.Matrix(sp.symbols(f"hx{i} hy{i} hz{i}")) for i in (1, 2)]
    psi = sp.symbols("psi1 psi2")
    rest = [sp.symbols(f"s0{i} t0{i}") for i in (1, 2)]
    coords = [(sp.Function(f"s{i}")(t), sp.Function(f"t{i}")(t)) for i in (1, 2)]
    pos = []
    for (s_, t_), h, ps, l in zip(coords, hinge, psi, (l1, l2)):
        u = sp.Matrix([sp.sin(s_), -sp.sin(t_) * sp.cos(s_), -sp.cos(t_) * sp.cos(s_)])
        rz = sp.Matrix([[sp.cos(ps), -sp.sin(ps), 0], [sp.sin(ps), sp.cos(ps), 0], [0, 0, 1]])
        pos.append(h + l * rz * u)
    T = sum(sp.Rational(1, 2) * m * p.diff(t).dot(p.diff(t)) for m, p in zip((m1, m2), pos))
    V = sum(m * ((g + az) * p[2] + ax * p[0]) for m, p in zip((m1, m2), pos))
    D = 0
    for (s_, t_), (s0, t0), k, c in zip(coords, rest, (k1, k2), (c1, c2)):
        V += sp.Rational(1, 2) * k * ((s_ - s0) ** 2 + (t_ - t0) ** 2)
        D += sp.Rational(1, 2) * c * (s_.diff(t) ** 2 + t_.diff(t) ** 2)
    delta = r1 + r2 - sp.sqrt((pos[1] - pos[0]).dot(pos[1] - pos[0]))
    if law == "kelvin-voigt":
        V += sp.Rational(1, 2) * kc * delta**2
        D += sp.Rational(1, 2) * cc * delta.diff(t) ** 2
    else:
        V += sp.Rational(2, 5) * kc * delta ** sp.Rational(5, 2)
        D += sp.Rational(1, 2) * kc * delta ** sp.Rational(3, 2) * cc * delta.diff(t) ** 2 / vo
    L = T - V
    q = [c for pair in coords for c in pair]
    eqs = [sp.diff(L.diff(qi.diff(t)), t) - L.diff(qi) + D.diff(qi.diff(t)) for qi in q]
    a = sp.symbols("a0:4")
    w = sp.symbols("w0:4")
    x = sp.symbols("x0:4")
    eqs = [e.subs({qi.diff(t, 2): ai for qi, ai in zip(q, a)}).subs({qi.diff(t): wi for qi, wi in zip(q, w)})
           .subs({qi: xi for qi, xi in zip(q, x)}) for e in eqs]
    mass = sp.Matrix([[e.diff(ai) for ai in a] for e in eqs])
    rem = sp.Matrix([e.subs({ai: 0 for ai in a}) for e in eqs])
    params = sym + tuple(hinge[0]) + tuple(hinge[1]) + psi + rest[0] + rest[1]
    fm = sp.lambdify(params + x + w, mass, "mpmath")
    fr = sp.lambdify(params + x + w, rem, "mpmath")
    return lambda *args: [float(v) for v in -(fm(*args) ** -1) * fr(*args)]


@pytest.mark.parametrize("law", ["kelvin-voigt", "hunt-crossley"])
def test_compiled_rhs_matches_lagrange_equations_spherical(law):
    import mpmath


    mpmath.mp.dps = 30
    f = spherical_lagrange(law)
    rng = np.random.default_rng(11)
    law_obj = ContactLaw(law, 2000.0 if law == "kelvin-voigt" else 1.1e5, 1.3 if law == "kelvin-voigt" else 0.8)
    for _ in range(8):
        m, r, length = rng.uniform(0.005, 0.02, 2), rng.uniform(0.008, 0.015, 2), rng.uniform(0.02, 0.05, 2)
        psi, rest = rng.uniform(-3, 3, 2), rng.uniform(-0.5, 0.5, (2, 2))
        x, w = rng.uniform(-0.6, 0.6, 4), rng.uniform(-3, 3, 4)
        kh, ch = rng.uniform(1e-3, 5e-3, 2), rng.uniform(1e-5, 5e-5, 2)
        h1 = rng.uniform(-0.02, 0.02, 3)
        berries = [Berry("a", m[0], r[0], length[0], h1[0], kh[0], ch[0], h1[1], h1[2], True, psi[0], tuple(rest[0]))]
        probe = Model((*berries, Berry("b", m[1], r[1], length[1], 0.0, kh[1], ch[1], 0.0, 0.0, True, psi[1],
                                       tuple(rest[1]))))
        # put the second hinge where the berries overlap by 0.3 mm along a random direction
        from grapefmu.physics.kinematics import positions
        pos = np.zeros((2, 3))
        positions(np.r_[x, w], probe.arrays, pos)
        n = rng.normal(size=3)
        n /= np.linalg.norm(n)
        h2 = pos[0] + (r.sum() - 3e-4) * n - (pos[1] - 0.0)
        berries.append(Berry("b", m[1], r[1], length[1], h2[0], kh[1], ch[1], h2[1], h2[2], True, psi[1], tuple(rest[1])))
        sc = Scene(Model(tuple(berries), (ContactPair(0, 1, law_obj),)), tuple(x), tuple(w))
        ax, az = rng.uniform(-5, 5, 2)
        dyv = derivative(sc.arrays, Solver(sc).y, loaded(1), (ax, 0.0, az, 0.0, 0.0, 0.0))
        args = (m[0], m[1], length[0], length[1], r[0], r[1], kh[0], kh[1], ch[0], ch[1], 9.81, ax, az,
                law_obj.stiffness, law_obj.damping, 0.7, *h1, *h2, *psi, *rest[0], *rest[1], *x, *w)
        expect = f(*[mpmath.mpf(float(v)) for v in args])
        lay = layout(2, 4, 0)
        np.testing.assert_allclose(dyv[lay.w], expect, rtol=1e-11, atol=1e-9)
        assert np.all(dyv[lay.q] == w)

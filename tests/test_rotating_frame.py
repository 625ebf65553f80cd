"""The 6-DoF rachis (translation and rotation) against references built here, independently of the core.

The core writes the equations in the rachis frame, with the frame's fields (gravity turned into it, the
inertial field of its acceleration, the Euler, centrifugal and Coriolis terms). The references here never
do: they write the Lagrangian in the WORLD frame, T = Σ ½ m |ẋ|², V = Σ m g x_z + hinges + contact, with
x = b + R (h + l u(q)) and R = R_z(yaw) R_y(pitch) R_x(roll) of three prescribed Euler-angle functions,
and let sympy derive Euler–Lagrange's equations for the angles. The rachis' angular velocity and
acceleration are derived from the Euler angles (Ṙ Rᵀ = [ω]×), its quaternion is composed from the three
elementary turns, never from the core's formulas.

1. The right-hand side at random states (planar berries, yawed, turning about their plane's normal, with
   coupling and contact; spherical berries with azimuths and rest angles under a full rotation; a spherical
   berry pressed into a plane fixed in the world; each also at R = I, ω = 0 about to turn), to 1e-10
   relative.
2. Whole runs against a scipy DOP853 integration of the world-frame equations (the Euler angles
   integrated from the prescribed ω(t)): a spherical berry on a tilting, spinning, translating rachis, and
   one landing on a tilted floor (contact events located by scipy, the Kelvin–Voigt force added as a
   generalized force from the plane's geometry in the world frame).
3. Closed forms and free pendulums: the conical pendulum's steady state on a rachis spinning about the
   vertical; a twig hinged on the rotation axis without hinge spring or damper swings as a free pendulum
   in the world whatever the rachis does (planar about y, spherical about any axis).
4. A stiff cluster follows the rachis rigidly, within the deflection its hinges allow, and deflects by the
   quasi-static load of the rotating frame.
5. The energy ledger closes with a moving, rotating rachis and obstacle impacts.
6. A planar scene is refused, naming the key, when its rachis would tilt the berries' plane out of the
   vertical or turn about anything but the plane's normal (y, or Rz(yaw) y when yawed).
"""
from __future__ import annotations

import functools
import math
from dataclasses import replace

import numpy as np
import pytest
import sympy as sp
from scipy.integrate import solve_ivp

from grapefmu import SceneError, simulate
from grapefmu.model import Berry, ContactLaw, ContactPair, Coupling, Model, Scene
from grapefmu.model.excitation import constant
from grapefmu.model.model import Obstacle
from grapefmu.physics.dynamics import derivative
from grapefmu.physics.forces import CONTACT
from grapefmu.physics.layout import layout_of

from .conftest import scene

G = 9.81


# ------------------------------------------------------------------------------------------------------
# rotations and quaternions, written here
# ------------------------------------------------------------------------------------------------------
def _srot(axis: str, a):
    c, s = sp.cos(a), sp.sin(a)
    if axis == "x":
        return sp.Matrix([[1, 0, 0], [0, c, -s], [0, s, c]])
    if axis == "y":
        return sp.Matrix([[c, 0, s], [0, 1, 0], [-s, 0, c]])
    return sp.Matrix([[c, -s, 0], [s, c, 0], [0, 0, 1]])


def rot(axis: str, a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    if axis == "x":
        return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])
    if axis == "y":
        return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def euler_matrix(roll: float, pitch: float, yaw: float) -> np.ndarray:
    """REP-103 fixed axes: R = Rz(yaw) Ry(pitch) Rx(roll)."""
    return rot("z", yaw) @ rot("y", pitch) @ rot("x", roll)


def qmul(a, b):
    """Hamilton product of quaternions stored (x, y, z, w)."""
    ax, ay, az, aw = a
    bx, by, bz, bw = b
    return np.array([aw * bx + ax * bw + ay * bz - az * by,
                     aw * by - ax * bz + ay * bw + az * bx,
                     aw * bz + ax * by - ay * bx + az * bw,
                     aw * bw - ax * bx - ay * by - az * bz])


def quaternion_matrix(q) -> np.ndarray:
    """R of a unit quaternion (x, y, z, w): v ↦ q (v, 0) q*, evaluated by quaternion products (no closed form
    copied from anywhere)."""
    q = np.asarray(q, float) / np.linalg.norm(q)
    conj = np.array([-q[0], -q[1], -q[2], q[3]])
    cols = [qmul(qmul(q, np.array([*e, 0.0])), conj)[:3] for e in np.eye(3)]
    return np.column_stack(cols)


def skew(w):
    return np.array([[0.0, -w[2], w[1]], [w[2], 0.0, -w[0]], [-w[1], w[0], 0.0]])


def rodrigues(axis, angle) -> np.ndarray:
    """The turn by `angle` about `axis`."""
    K = skew(np.asarray(axis, float) / np.linalg.norm(axis))
    return np.eye(3) + math.sin(angle) * K + (1 - math.cos(angle)) * K @ K


def twig(spherical: bool, q, psi: float = 0.0) -> np.ndarray:
    """u of docs/model.md §1 in the rachis frame (planar: (sin s, 0, −cos s))."""
    if not spherical:
        return np.array([math.sin(q[0]), 0.0, -math.cos(q[0])])
    s, t = q
    return rot("z", psi) @ np.array([math.sin(s), -math.sin(t) * math.cos(s), -math.cos(t) * math.cos(s)])


@functools.cache
def _twig_jacobian():
    s, t, psi = sp.symbols("s t psi")
    u = _srot("z", psi) * sp.Matrix([sp.sin(s), -sp.sin(t) * sp.cos(s), -sp.cos(t) * sp.cos(s)])
    return sp.lambdify((s, t, psi), u.jacobian([s, t]), "numpy")


def twig_jacobian(q, psi: float = 0.0) -> np.ndarray:
    """∂u/∂(s, t) of a spherical twig (3 × 2), by sympy."""
    return np.asarray(_twig_jacobian()(q[0], q[1], psi), float)


def loaded(n_pairs: int) -> np.ndarray:
    c = np.zeros(n_pairs, dtype=CONTACT)
    c["mode"], c["v_onset"] = 1, 0.7
    return c


# ------------------------------------------------------------------------------------------------------
# the world-frame Lagrangian
# ------------------------------------------------------------------------------------------------------
EULER = ("roll", "pitch", "yaw")


class Derived:
    """Lambdified world-frame equations: M(x) q̈ = −rest(x) with x the named values; plus the berries' world
    positions, their Jacobians ∂x/∂q and velocities (for forces added from outside the Lagrangian)."""

    def __init__(self, syms, mass, rest, pos, jac, vel, module):
        self.names = [s.name for s in syms]
        self._mass, self._rest, self._pos, self._jac, self._vel = mass, rest, pos, jac, vel
        self.module = module

    def args(self, v: dict):
        if self.module == "mpmath":
            import mpmath
            return [mpmath.mpf(float(v[n])) for n in self.names]
        return [float(v[n]) for n in self.names]

    def accelerations(self, v: dict, extra_force=None):
        a = self.args(v)
        if self.module == "mpmath":
            import mpmath
            rhs = -self._rest(*a)
            if extra_force is not None:
                rhs += mpmath.matrix(list(extra_force))
            return np.array([float(x) for x in mpmath.lu_solve(self._mass(*a), rhs)])
        rhs = -np.asarray(self._rest(*a), float).ravel()
        if extra_force is not None:
            rhs = rhs + extra_force
        mass = np.asarray(self._mass(*a), float)
        if mass.shape == (2, 2):  # Cramer's rule: np.linalg.solve costs more than the rest of a scipy step
            (p, q), (r, s) = mass
            det = p * s - q * r
            return np.array([(s * rhs[0] - q * rhs[1]) / det, (p * rhs[1] - r * rhs[0]) / det])
        return np.linalg.solve(mass, rhs)

    def position(self, v, i):
        return np.asarray(self._pos[i](*self.args(v)), float).ravel()

    def jacobian(self, v, i):
        return np.asarray(self._jac[i](*self.args(v)), float)

    def velocity(self, v, i):
        return np.asarray(self._vel[i](*self.args(v)), float).ravel()


def _dof_names(kinds):
    names = []
    for i, kind in enumerate(kinds, start=1):
        names += [f"s{i}", f"t{i}"] if kind == "spherical" else [f"s{i}"]
    return names


@functools.cache
def world_equations(kinds: tuple[str, ...], contact: str | None, module: str) -> Derived:
    """Euler–Lagrange's equations for the angles of berries `kinds` ("planar", "spherical") hinged to a
    rachis that moves with b(t) and turns with R(t) = Rz(yaw) Ry(pitch) Rx(roll), written in the world frame; contact None, "berries" (Kelvin–Voigt between berries 1 and 2 as the
    potential ½ kc δ² and the Rayleigh function ½ cc δ̇²), or "plane" (the same between berry 1 and a plane
    fixed in the world through p with unit normal n). Planar pairs also get the k3/c3 coupling on the change
    of their horizontal separation in the rachis frame.

    Every time function is a plain symbol z with rate d_z and acceleration dd_z; d/dt is the total
    derivative Σ ∂/∂z d_z + ∂/∂d_z dd_z."""
    b = list(sp.symbols("bx by bz"))
    eul = list(sp.symbols(EULER))
    R = _srot("z", eul[2]) * _srot("y", eul[1]) * _srot("x", eul[0])
    g = sp.Symbol("g")
    coords, x, rel, V, D = [], [], [], 0, 0
    per = []
    for i, kind in enumerate(kinds, start=1):
        m, l, k, c = sp.symbols(f"m{i} l{i} k{i} c{i}")
        h = sp.Matrix(sp.symbols(f"hx{i} hy{i} hz{i}"))
        if kind == "spherical":
            s_, t_ = sp.symbols(f"s{i} t{i}")
            psi, s0, t0 = sp.symbols(f"psi{i} s0{i} t0{i}")
            u = _srot("z", psi) * sp.Matrix([sp.sin(s_), -sp.sin(t_) * sp.cos(s_), -sp.cos(t_) * sp.cos(s_)])
            qs = [s_, t_]
            V += sp.Rational(1, 2) * k * ((s_ - s0) ** 2 + (t_ - t0) ** 2)
        else:
            s_ = sp.Symbol(f"s{i}")
            u = sp.Matrix([sp.sin(s_), 0, -sp.cos(s_)])
            qs = [s_]
            V += sp.Rational(1, 2) * k * s_ ** 2
        xi = sp.Matrix(b) + R * (h + l * u)
        V += m * g * xi[2]
        coords += qs
        x.append(xi)
        rel.append(l * u)
        per.append((m, c, qs))
    z = coords + b + eul
    zd = [sp.Symbol("d_" + s.name) for s in z]
    zdd = [sp.Symbol("dd_" + s.name) for s in z]

    def ddt(e):
        return sum(e.diff(a) * ad for a, ad in zip(z, zd)) + sum(e.diff(a) * ad for a, ad in zip(zd, zdd))

    T = 0
    vel = []
    for (m, c, qs), xi in zip(per, x):
        v = xi.applyfunc(ddt)
        vel.append(v)
        T += sp.Rational(1, 2) * m * v.dot(v)
        D += sp.Rational(1, 2) * c * sum(zd[z.index(q)] ** 2 for q in qs)
    if contact == "berries":
        r1, r2, kc, cc = sp.symbols("r1 r2 kc cc")
        d = x[1] - x[0]
        delta = r1 + r2 - sp.sqrt(d.dot(d))
        V += sp.Rational(1, 2) * kc * delta ** 2
        D += sp.Rational(1, 2) * cc * ddt(delta) ** 2
        if kinds == ("planar", "planar"):
            k3, c3 = sp.symbols("k3 c3")
            sep = rel[1][0] - rel[0][0]
            V += sp.Rational(1, 2) * k3 * sep ** 2
            D += sp.Rational(1, 2) * c3 * ddt(sep) ** 2
    elif contact == "plane":
        r1, kc, cc = sp.symbols("r1 kc cc")
        p, n = sp.Matrix(sp.symbols("px py pz")), sp.Matrix(sp.symbols("nx ny nz"))
        delta = r1 - n.dot(x[0] - p)
        V += sp.Rational(1, 2) * kc * delta ** 2
        D += sp.Rational(1, 2) * cc * ddt(delta) ** 2
    L = T - V
    qd = [zd[z.index(q)] for q in coords]
    qdd = [zdd[z.index(q)] for q in coords]
    mass, rest = [], []
    for q, w in zip(coords, qd):
        p_ = L.diff(w)  # generalized momentum
        mass.append([p_.diff(a) for a in qd])
        other = sum(p_.diff(a) * aa for a, aa in zip(zd, zdd) if aa not in qdd)
        rest.append(sum(p_.diff(a) * ad for a, ad in zip(z, zd)) + other - L.diff(q) + D.diff(w))
    mass, rest = sp.Matrix(mass), sp.Matrix(rest)
    jac = [xi.jacobian(coords) for xi in x]
    everything = [mass, rest, *x, *jac, *vel]
    syms = sorted(set().union(*(e.free_symbols for e in everything)), key=lambda s: s.name)
    lam = functools.partial(sp.lambdify, syms, modules=module, cse=True)
    return Derived(syms, lam(mass), lam(rest), [lam(e) for e in x], [lam(e) for e in jac], [lam(e) for e in vel],
                   module)


@functools.cache
def rachis_kinematics():
    """ω (world) and α = ω̇ of R = Rz(yaw) Ry(pitch) Rx(roll) from Ṙ Rᵀ = [ω]×; the quaternion
    q = q_z(yaw) ⊗ q_y(pitch) ⊗ q_x(roll) and its rate by differentiating it (functions of the angles, their
    rates and accelerations); and the inverse map "euler_rates": (angles, ω, α) ↦ (rates, accelerations)."""
    e = sp.symbols(EULER)
    ed = sp.symbols([f"d_{n}" for n in EULER])
    edd = sp.symbols([f"dd_{n}" for n in EULER])
    R = _srot("z", e[2]) * _srot("y", e[1]) * _srot("x", e[0])

    def ddt(expr):
        return sum(expr.diff(a) * ad for a, ad in zip(e, ed)) + sum(expr.diff(a) * ad for a, ad in zip(ed, edd))

    W = R.applyfunc(ddt) * R.T
    omega = sp.Matrix([W[2, 1], W[0, 2], W[1, 0]]).applyfunc(lambda x: sp.trigsimp(sp.collect(sp.expand(x), ed)))
    # W is skew (R orthogonal) and ω is its axial vector: checked at a point
    point = dict(zip((*e, *ed), (0.3, -0.7, 1.1, 0.9, -1.3, 0.4)))
    W0 = np.array(W.subs(point).evalf(), dtype=float)
    w0 = np.array(omega.subs(point).evalf(), dtype=float).ravel()
    assert np.abs(W0 + W0.T).max() < 1e-14 and np.abs(W0 - skew(w0)).max() < 1e-14
    alpha = omega.applyfunc(ddt)

    def qsym(axis, a):
        v = [0, 0, 0]
        v["xyz".index(axis)] = sp.sin(a / 2)
        return sp.Quaternion(sp.cos(a / 2), *v)

    qq = qsym("z", e[2]) * qsym("y", e[1]) * qsym("x", e[0])
    quat = sp.Matrix([qq.b, qq.c, qq.d, qq.a])  # (x, y, z, w)
    dquat = quat.applyfunc(ddt)
    args = (*e, *ed, *edd)
    f = {k: sp.lambdify(args, v, "numpy") for k, v in (("omega", omega), ("alpha", alpha), ("dquat", dquat),
                                                        ("quat", quat))}
    # the Euler angles' rates and accelerations that give ω and α: ω = E(angles) · rates,
    # α = E · accelerations + (α at zero accelerations)
    E = omega.jacobian(ed)
    Einv = E.inv().applyfunc(sp.simplify)
    w, a = sp.Matrix(sp.symbols("wx wy wz")), sp.Matrix(sp.symbols("ax ay az"))
    rates = Einv * w
    accels = Einv * (a - alpha.subs(dict(zip(edd, (0, 0, 0)))).subs(dict(zip(ed, rates))))
    f["euler_rates"] = sp.lambdify((*e, *w, *a), [*rates, *accels], "math", cse=True)
    return f


def world_motion(e, ed, edd):
    """(ω, α, quaternion, its rate) of the rachis at Euler angles e with rates ed and accelerations edd."""
    f = rachis_kinematics()
    a = (*e, *ed, *edd)
    return tuple(np.asarray(f[k](*a), float).ravel() for k in ("omega", "alpha", "quat", "dquat"))


# ------------------------------------------------------------------------------------------------------
# 1. the right-hand side against Euler–Lagrange in the world frame
# ------------------------------------------------------------------------------------------------------
def random_berry(rng, i, spherical):
    v = {f"m{i}": rng.uniform(0.005, 0.02), f"r{i}": rng.uniform(0.008, 0.015), f"l{i}": rng.uniform(0.02, 0.05),
         f"k{i}": rng.uniform(1e-3, 5e-3), f"c{i}": rng.uniform(1e-5, 5e-5)}
    v.update(zip((f"hx{i}", f"hy{i}", f"hz{i}"), rng.uniform(-0.02, 0.02, 3)))
    if spherical:
        v[f"psi{i}"] = rng.uniform(-3, 3)
        v[f"s0{i}"], v[f"t0{i}"] = rng.uniform(-0.5, 0.5, 2)
        v[f"s{i}"], v[f"t{i}"] = rng.uniform(-0.6, 0.6, 2)
        v[f"d_s{i}"], v[f"d_t{i}"] = rng.uniform(-3, 3, 2)
    else:
        v[f"s{i}"], v[f"d_s{i}"] = rng.uniform(-0.6, 0.6), rng.uniform(-3, 3)
    return v


def berry_of(v, i, spherical, name):
    return Berry(name, v[f"m{i}"], v[f"r{i}"], v[f"l{i}"], v[f"hx{i}"], v[f"k{i}"], v[f"c{i}"], v[f"hy{i}"],
                 v[f"hz{i}"], spherical, v.get(f"psi{i}", 0.0), (v.get(f"s0{i}", 0.0), v.get(f"t0{i}", 0.0)))


def rachis_position(v, i, spherical):
    q = (v[f"s{i}"], v[f"t{i}"]) if spherical else (v[f"s{i}"],)
    h = np.array([v[f"hx{i}"], v[f"hy{i}"], v[f"hz{i}"]])
    return h + v[f"l{i}"] * twig(spherical, q, v.get(f"psi{i}", 0.0))


def random_rachis(rng, v, rotation, level=False):
    """Random Euler angles, rates and accelerations and translation b, ḃ, b̈ into v; returns what the core's y
    and accel get: b, ḃ, b̈, ω and α from the Euler angles, the quaternion composed of the three turns and its
    rate, and R."""
    if rotation == "full":
        e, ed, edd = rng.uniform(-1.2, 1.2, 3), rng.uniform(-4, 4, 3), rng.uniform(-40, 40, 3)
    else:  # "plane": a fixed yaw, turning in pitch: about Rz(yaw) ŷ, the normal of the berries' vertical plane
        e = np.array([0.0, rng.uniform(-3, 3), rng.uniform(-3, 3)])
        ed = np.array([0.0, rng.uniform(-4, 4), 0.0])
        edd = np.array([0.0, rng.uniform(-40, 40), 0.0])
    if level:  # R = I and ω = 0: a rachis about to turn from rest
        e, ed = np.zeros(3), np.zeros(3)
    for n, a, ad, add in zip(EULER, e, ed, edd):
        v[n], v[f"d_{n}"], v[f"dd_{n}"] = a, ad, add
    b, bd, bdd = rng.uniform(-0.05, 0.05, 3), rng.uniform(-1, 1, 3), rng.uniform(-8, 8, 3)
    for k, ax in enumerate("xyz"):
        v[f"b{ax}"], v[f"d_b{ax}"], v[f"dd_b{ax}"] = b[k], bd[k], bdd[k]
    v["g"] = G
    omega, alpha, quat, dquat = world_motion(e, ed, edd)
    # the quaternion is R's: a check of the conventions used here
    np.testing.assert_allclose(quaternion_matrix(quat), euler_matrix(*e), atol=1e-14)
    return dict(b=b, bd=bd, bdd=bdd, omega=omega, alpha=alpha, quat=quat, dquat=dquat, R=euler_matrix(*e))


def core_state(sc, v, rachis):
    """The core's dy/dt at the state v with the rachis' motion `rachis`, every contact pair loaded. The scene is
    given an excitation that turns (about y, so that planar berries accept it) so that ω and the orientation
    ride in its y; derivative() takes the acceleration it is handed."""
    sc = replace(sc, excitation=constant((0.0, 0.0, 0.0), (0.0, 1.0, 0.0)))
    m = sc.model
    lay = layout_of(sc)
    assert lay.turning
    y = np.zeros(lay.size)
    dofs = _dof_names(["spherical" if b.spherical else "planar" for b in m.berries])
    y[lay.q] = [v[n] for n in dofs]
    y[lay.w] = [v[f"d_{n}"] for n in dofs]
    y[lay.base_velocity] = rachis["bd"]
    y[lay.base] = rachis["b"]
    y[lay.base_angular_velocity] = rachis["omega"]
    y[lay.base_orientation] = rachis["quat"]
    dy = derivative(sc.arrays, y, loaded(len(m.pairs)), (*rachis["bdd"], *rachis["alpha"]))
    return lay, y, dy, dofs


def check_rhs(lay, y, dy, expect, rachis):
    got = dy[lay.w]
    scale = np.abs(expect).max()
    np.testing.assert_allclose(got, expect, rtol=1e-10, atol=1e-10 * scale)
    np.testing.assert_array_equal(dy[lay.q], y[lay.w])
    # the rachis' own rates (docs: ḃ, b̈, α, and the quaternion's ½ (ω, 0) ⊗ q)
    np.testing.assert_allclose(dy[lay.base], rachis["bd"], rtol=1e-15)
    np.testing.assert_allclose(dy[lay.base_velocity], rachis["bdd"], rtol=1e-15)
    np.testing.assert_allclose(dy[lay.base_angular_velocity], rachis["alpha"], rtol=1e-15)
    np.testing.assert_allclose(dy[lay.base_orientation], rachis["dquat"], rtol=1e-12, atol=1e-13)


@pytest.fixture(scope="module")
def mp30():
    import mpmath
    with mpmath.workdps(30):
        yield


def test_planar_berries_turning_about_their_plane_normal_match_world_lagrange(mp30):
    """Two planar berries with a k3/c3 coupling, pressed into each other (Kelvin–Voigt, loaded), on a rachis
    translating in 3-D, yawed, and turning about its y axis (the normal of the berries' plane): the compiled
    right-hand side against Euler–Lagrange's equations of the world-frame Lagrangian."""
    f = world_equations(("planar", "planar"), "berries", "mpmath")
    rng = np.random.default_rng(2024)
    for trial in range(12):
        v = {**random_berry(rng, 1, False), **random_berry(rng, 2, False)}
        v["hy2"] = v["hy1"]  # in the same plane, so that they can touch
        # place the second hinge so that the berries overlap by 0.3 mm along a random direction in x–z
        a = rng.uniform(0, 2 * math.pi)
        n = np.array([math.cos(a), 0.0, math.sin(a)])
        p2 = rachis_position(v, 1, False) + (v["r1"] + v["r2"] - 3e-4) * n
        h2 = p2 - v["l2"] * twig(False, (v["s2"],))
        v["hx2"], v["hz2"] = h2[0], h2[2]
        v.update(kc=2000.0, cc=1.3, k3=3.0, c3=0.02)
        rachis = random_rachis(rng, v, "plane", level=trial == 0)
        law = ContactLaw("kelvin-voigt", v["kc"], v["cc"])
        sc = Scene(Model((berry_of(v, 1, False, "a"), berry_of(v, 2, False, "b")), (ContactPair(0, 1, law),),
                         (Coupling(0, 1, v["k3"], v["c3"]),), G), (v["s1"], v["s2"]), (v["d_s1"], v["d_s2"]))
        lay, y, dy, _ = core_state(sc, v, rachis)
        check_rhs(lay, y, dy, f.accelerations(v), rachis)


def test_spherical_berries_under_a_full_rotation_match_world_lagrange(mp30):
    """Two spherical berries (azimuths, rest angles, hinges anywhere) pressed into each other on a rachis
    that translates and turns about all three axes."""
    f = world_equations(("spherical", "spherical"), "berries", "mpmath")
    rng = np.random.default_rng(77)
    for trial in range(8):
        v = {**random_berry(rng, 1, True), **random_berry(rng, 2, True)}
        n = rng.normal(size=3)
        n /= np.linalg.norm(n)
        p2 = rachis_position(v, 1, True) + (v["r1"] + v["r2"] - 3e-4) * n
        h2 = p2 - v["l2"] * twig(True, (v["s2"], v["t2"]), v["psi2"])
        v["hx2"], v["hy2"], v["hz2"] = h2
        v.update(kc=2000.0, cc=1.3)
        rachis = random_rachis(rng, v, "full", level=trial == 0)
        law = ContactLaw("kelvin-voigt", v["kc"], v["cc"])
        sc = Scene(Model((berry_of(v, 1, True, "a"), berry_of(v, 2, True, "b")), (ContactPair(0, 1, law),), (), G),
                   (v["s1"], v["t1"], v["s2"], v["t2"]), (v["d_s1"], v["d_t1"], v["d_s2"], v["d_t2"]))
        lay, y, dy, _ = core_state(sc, v, rachis)
        check_rhs(lay, y, dy, f.accelerations(v), rachis)


def test_spherical_berry_pressed_into_a_world_plane_matches_world_lagrange(mp30):
    """A spherical berry pressed into a plane fixed in the world (Kelvin–Voigt, loaded) while the rachis
    translates and turns: δ = r − n·(x − p) depends on b and R as well as on the angles, and δ̇ on ḃ and ω."""
    f = world_equations(("spherical",), "plane", "mpmath")
    rng = np.random.default_rng(5)
    for trial in range(8):
        v = random_berry(rng, 1, True)
        rachis = random_rachis(rng, v, "full", level=trial == 0)
        n = rng.normal(size=3)
        n /= np.linalg.norm(n)
        x = rachis["b"] + rachis["R"] @ rachis_position(v, 1, True)
        p = x - (v["r1"] - 3e-4) * n  # 0.3 mm deep
        v.update(kc=2000.0, cc=1.3, px=p[0], py=p[1], pz=p[2], nx=n[0], ny=n[1], nz=n[2])
        law = ContactLaw("kelvin-voigt", v["kc"], v["cc"])
        plane = Obstacle("plane", "plane", tuple(p), tuple(n))
        sc = Scene(Model((berry_of(v, 1, True, "a"),), (ContactPair(0, 1, law),), (), G, 0, (plane,)),
                   (v["s1"], v["t1"]), (v["d_s1"], v["d_t1"]))
        lay, y, dy, _ = core_state(sc, v, rachis)
        check_rhs(lay, y, dy, f.accelerations(v), rachis)


# ------------------------------------------------------------------------------------------------------
# 2. whole runs against scipy on the world-frame equations
# ------------------------------------------------------------------------------------------------------
class SineMotion:
    """A scene's sine excitation in closed form (start 0): b̈ = a sin 2πft and α = A sin 2πft for t < duration,
    then nothing; ḃ(0) = 0, b(0) = 0, ω(0) = ω0."""

    def __init__(self, a, A, f, duration, omega0):
        self.a, self.A, self.f, self.T = np.asarray(a, float), np.asarray(A, float), f, duration
        self.omega0 = np.asarray(omega0, float)

    def _integrals(self, t):
        w = 2 * math.pi * self.f
        tt = min(t, self.T)
        s = math.sin(w * tt) if t < self.T else 0.0
        i1 = (1 - math.cos(w * tt)) / w           # ∫ sin
        i2 = (tt - math.sin(w * tt) / w) / w      # ∫∫ sin
        if t > self.T:
            i2 += i1 * (t - self.T)
        return s, i1, i2

    def at(self, t):
        """(b, ḃ, b̈, ω, α) at t."""
        s, i1, i2 = self._integrals(t)
        return self.a * i2, self.a * i1, self.a * s, self.omega0 + self.A * i1, self.A * s

    def turn(self, t) -> float:
        """∫₀ᵗ of the angular speed along A (the angle turned when ω0 is parallel to A), rad."""
        _, _, i2 = self._integrals(t)
        return float(np.linalg.norm(self.A)) * i2


def berry_values(b: dict, i: int = 1) -> dict:
    """A scene dict's berry as the derivation's named values."""
    h = b.get("hinge", [b.get("hinge_x", 0.0), 0.0, 0.0])
    rest = b.get("rest_angles", [0.0, 0.0])
    return {f"m{i}": b["mass"], f"r{i}": b["radius"], f"l{i}": b["twig_length"], f"k{i}": b.get("hinge_stiffness", 0.0),
            f"c{i}": b.get("hinge_damping", 0.0), f"hx{i}": h[0], f"hy{i}": h[1], f"hz{i}": h[2],
            f"psi{i}": b.get("azimuth", 0.0), f"s0{i}": rest[0], f"t0{i}": rest[1], "g": G}


class WorldReference:
    """One spherical berry integrated in the world frame by scipy: state (s, t, ṡ, ṫ, roll, pitch, yaw). The
    Euler angles follow the prescribed ω(t) through ω = E(angles) · rates (E from the derivation), their
    accelerations through α = E · accelerations + Ė · rates. A plane fixed in the world, if given, pushes with
    the Kelvin–Voigt force F = k δ + c δ̇ (δ = r − n·(x − p), δ̇ = −n·ẋ, no pull: the clamp's modes located as
    events) added as the generalized force F n·∂x/∂q."""

    def __init__(self, berry: dict, excitation: dict, t_end: float, plane: dict | None = None):
        self.f = world_equations(("spherical",), None, "numpy")
        self.kin = rachis_kinematics()
        self.v = berry_values(berry)
        ex = excitation
        amp = list(ex.get("amplitude", [0.0, 0.0, 0.0]))
        self.motion = SineMotion(amp, ex.get("angular_amplitude", [0.0, 0.0, 0.0]), ex["frequency"],
                                 ex.get("duration", t_end), ex.get("angular_velocity", [0.0, 0.0, 0.0]))
        self.y0 = np.r_[berry["angle"], berry["angular_velocity"], ex.get("orientation", [0.0, 0.0, 0.0])]
        self.t_end = t_end
        self.plane = plane
        if plane is not None:
            n = np.asarray(plane["normal"], float)
            self.n, self.p = n / np.linalg.norm(n), np.asarray(plane["point"], float)
            self.k, self.c = plane["stiffness"], plane["damping"]

    def values(self, t, y):
        b, bd, bdd, omega, alpha = self.motion.at(t)
        e = y[4:7]
        rates = self.kin["euler_rates"](*e, *omega, *alpha)
        ed, edd = rates[:3], rates[3:]
        v = dict(self.v)
        v.update(s1=y[0], t1=y[1], d_s1=y[2], d_t1=y[3])
        for k, ax in enumerate("xyz"):
            v[f"b{ax}"], v[f"d_b{ax}"], v[f"dd_b{ax}"] = b[k], bd[k], bdd[k]
        for k, nm in enumerate(EULER):
            v[nm], v[f"d_{nm}"], v[f"dd_{nm}"] = e[k], ed[k], edd[k]
        return v, ed

    def gap(self, v):
        """(δ, δ̇) of the berry against the plane."""
        x, xd = self.f.position(v, 0), self.f.velocity(v, 0)
        return self.v["r1"] - self.n @ (x - self.p), -self.n @ xd

    def rhs(self, t, y, mode):
        v, ed = self.values(t, y)
        extra = None
        if mode == 1:
            delta, delta_dot = self.gap(v)
            force = self.k * delta + self.c * delta_dot
            extra = force * (self.n @ self.f.jacobian(v, 0))  # +F n on the berry
        return np.concatenate((y[2:4], self.f.accelerations(v, extra), ed))

    def _events(self, mode):
        """(function, direction, next mode) watched in `mode` (0 apart, 1 loaded, 2 overlapping unloaded)."""
        def delta(t, y):
            return self.gap(self.values(t, y)[0])[0]

        def force(t, y):
            d, dd = self.gap(self.values(t, y)[0])
            return self.k * d + self.c * dd
        if self.plane is None:
            return []
        return {0: [(delta, 1, 1)], 1: [(delta, -1, 0), (force, -1, 2)], 2: [(delta, -1, 0), (force, 1, 1)]}[mode]

    def run(self):
        """Segments (t0, t1, dense solution) and the onsets (times the mode went 0 → 1)."""
        breaks = sorted({b for b in (self.motion.T, self.t_end) if 0 < b <= self.t_end})
        t, y, mode = 0.0, self.y0.copy(), 0
        if self.plane is not None:
            assert self.gap(self.values(0.0, y)[0])[0] < 0  # starts apart
        self.segments, self.onsets = [], []
        while t < self.t_end - 1e-15:
            stop = next(b for b in breaks if b > t + 1e-15)
            watched = self._events(mode)
            fns = []
            for fn, direction, _ in watched:
                fn = functools.partial(lambda fn_, tt, yy, *_: fn_(tt, yy), fn)
                fn.terminal, fn.direction = True, direction
                fns.append(fn)
            sol = solve_ivp(self.rhs, (t, stop), y, method="DOP853", rtol=1e-12, atol=1e-14, dense_output=True,
                            events=fns or None, args=(mode,), max_step=1e-3)
            assert sol.success, sol.message
            self.segments.append((t, sol.t[-1], sol.sol))
            y = sol.y[:, -1].copy()
            if sol.status == 1:
                k = min((k for k in range(len(fns)) if sol.t_events[k].size), key=lambda k: sol.t_events[k][0])
                t = float(sol.t_events[k][0])
                y = sol.y_events[k][0].copy()
                new = watched[k][2]
                if mode == 0 and new == 1:
                    self.onsets.append(t)
                mode = new
            else:
                t = stop
        return self

    def __call__(self, times):
        out = np.empty((len(times), 7))
        for n, tt in enumerate(times):
            seg = next((s for s in self.segments if s[0] <= tt <= s[1]), self.segments[-1])
            out[n] = seg[2](tt)
        return out


SPUN_BERRY = {"name": "b", "kind": "spherical", "mass": 0.011, "radius": 0.0135, "twig_length": 0.03,
              "hinge": [0.02, -0.01, 0.005], "hinge_stiffness": 1e-3, "hinge_damping": 2e-5, "azimuth": 0.4,
              "rest_angles": [0.1, -0.05], "angle": [0.3, -0.2], "angular_velocity": [1.0, -2.0]}
#: tilting about x and y while spinning about z, and translating in 3-D
TILT_SPIN = {"kind": "sine", "amplitude": [3.0, -2.0, 4.0], "angular_amplitude": [6.0, -4.0, 0.0], "frequency": 3.0,
             "orientation": [0.1, -0.15, 0.3], "angular_velocity": [0.5, 0.2, 2.0]}
LANDING_BERRY = {"name": "b", "kind": "spherical", "mass": 0.011, "radius": 0.0135, "twig_length": 0.03,
                 "hinge": [0.005, 0.0, 0.0], "hinge_stiffness": 1e-3, "hinge_damping": 2e-5, "azimuth": -0.3,
                 "angle": [0.1, 0.05], "angular_velocity": [0.0, 0.0]}
#: one period of a sine: lowered 1 cm and turned 0.14 rad about a horizontal axis, then at rest but spinning
#: slowly about z
LOWER_AND_TILT = {"kind": "sine", "amplitude": [0.2, 0.0, -0.25], "angular_amplitude": [2.0, -3.0, 0.0],
                  "frequency": 2.0, "duration": 0.5, "orientation": [0.05, -0.05, 0.0],
                  "angular_velocity": [0.0, 0.0, 0.8]}
TILTED_FLOOR = {"name": "floor", "point": [0.0, 0.0, -0.05], "normal": [0.15, -0.1, 1.0], "law": "kelvin-voigt",
                "stiffness": 2000.0, "damping": 1.0}


def test_spherical_berry_on_a_tilting_spinning_rachis_matches_scipy_world_frame():
    t_end = 0.6
    sc = scene({"berries": [SPUN_BERRY], "excitation": TILT_SPIN, "solver": {"t_end": t_end}})
    run = simulate(sc, rtol=1e-11, atol=1e-14)
    ref = WorldReference(SPUN_BERRY, TILT_SPIN, t_end).run()
    expect = ref(run.t)
    assert np.abs(expect[:, 0]).max() < 1.3  # inside the chart, and the twig really swings
    assert np.ptp(expect[:, 4:7], axis=0).min() > 0.1  # the rachis really turns about every axis
    err = np.abs(run.angles - expect[:, :2]).max()
    assert err < 1e-8, err
    # the rachis' pose: orientation against the Euler angles integrated here, displacement in closed form
    lay = run.layout
    for k in range(0, len(run.t), 50):
        R = quaternion_matrix(run.y[k, lay.base_orientation])
        np.testing.assert_allclose(R, euler_matrix(*expect[k, 4:7]), atol=1e-9)
        b, bd, _, omega, _ = ref.motion.at(run.t[k])
        np.testing.assert_allclose(run.y[k, lay.base], b, atol=1e-12)
        np.testing.assert_allclose(run.y[k, lay.base_velocity], bd, atol=1e-11)
        np.testing.assert_allclose(run.y[k, lay.base_angular_velocity], omega, atol=1e-11)


def test_a_berry_landing_on_a_tilted_floor_while_the_rachis_turns_matches_scipy():
    t_end = 0.8
    plane = {**TILTED_FLOOR}
    sc = scene({"berries": [LANDING_BERRY], "obstacles": [plane], "excitation": LOWER_AND_TILT,
                "solver": {"t_end": t_end}})
    run = simulate(sc, rtol=1e-12, atol=1e-14)
    ref = WorldReference(LANDING_BERRY, LOWER_AND_TILT, t_end, plane).run()
    expect = ref(run.t)
    assert len(ref.onsets) >= 2  # it lands and bounces
    assert run.collision_count == len(ref.onsets)
    np.testing.assert_allclose(run.impacts.onset, ref.onsets, atol=1e-10)
    err = np.abs(run.angles - expect[:, :2]).max()
    assert err < 1e-8, err


# ------------------------------------------------------------------------------------------------------
# 3. closed forms and free pendulums
# ------------------------------------------------------------------------------------------------------
def one_berry(**kw) -> dict:
    """A spherical berry hinged at the rachis origin, hanging at rest, without hinge spring or damper."""
    b = {"name": "b", "kind": "spherical", "mass": 0.011, "radius": 0.0135, "twig_length": 0.03,
         "hinge": [0.0, 0.0, 0.0], "hinge_stiffness": 0.0, "hinge_damping": 0.0, "angle": [0.0, 0.0],
         "angular_velocity": [0.0, 0.0]}
    b.update(kw)
    return b


def spin_about_z(omega: float) -> dict:
    return {"kind": "constant", "accel": [0.0, 0.0, 0.0], "angular_accel": [0.0, 0.0, 0.0],
            "angular_velocity": [0.0, 0.0, omega]}


def cone_angle(omega, m, length, k):
    """θ ≠ 0 of m l² Ω² sinθ cosθ − m g l sinθ − kθ = 0."""
    from scipy.optimize import brentq

    return brentq(lambda th: m * length**2 * omega**2 * math.sin(th) * math.cos(th) - m * G * length * math.sin(th)
                  - k * th, 1e-3, 0.5 * math.pi)


@pytest.mark.parametrize("k, c, t_end", [(0.0, 2e-4, 2.5), (1e-3, 1e-4, 9.0)])
def test_conical_pendulum_settles_where_gravity_balances_the_centrifugal_field(k, c, t_end):
    """A twig hinged on the axis of a rachis spinning at Ω about the vertical, with a hinge damper, settles at
    rest in the rachis on the cone m l² Ω² sinθ cosθ − m g l sinθ − kθ = 0: without a hinge spring (the scene
    allows k = 0) cos θ = g / (Ω² l); with one, swung along s (the spring's energy at a given θ is least along
    s or t, so the Coriolis-driven sideways swing dies out)."""
    omega, m, length = 25.0, 0.011, 0.03
    theta = cone_angle(omega, m, length, k)
    if k == 0.0:
        assert math.cos(theta) == pytest.approx(G / (omega**2 * length), rel=1e-12)
    berry = one_berry(mass=m, twig_length=length, hinge_stiffness=k, hinge_damping=c, angle=[theta + 0.1, 0.0])
    run = simulate(scene({"berries": [berry], "excitation": spin_about_z(omega),
                          "solver": {"t_end": t_end, "output_interval": 0.01}}), rtol=1e-10, atol=1e-13)
    s, t = run.angles[-1]
    cos_theta = math.cos(s) * math.cos(t)  # −u_z; the rachis' z stays vertical
    assert np.abs(run.angular_velocities[-1]).max() < 1e-6
    assert math.acos(cos_theta) == pytest.approx(theta, rel=1e-6)
    if k > 0.0:
        assert abs(t) < 1e-6  # on the s axis
    # the run saw a transient: the start was off the cone and the Coriolis field swung the twig sideways
    assert np.abs(run.angles[:, 1]).max() > 1e-3


def test_conical_equilibrium_with_a_hinge_spring_is_a_rest_point_of_the_rhs():
    """With a hinge spring k, the twig at rest in the rachis on the cone m l² Ω² sinθ cosθ − m g l sinθ − kθ = 0
    (swung along s or along t) has zero acceleration; 1 % off the cone it does not."""
    omega, m, length, k = 25.0, 0.011, 0.03, 1e-3
    theta = cone_angle(omega, m, length, k)
    for angle in ([theta, 0.0], [0.0, theta], [theta * 1.01, 0.0]):
        sc = scene({"berries": [one_berry(hinge_stiffness=k, angle=angle)], "excitation": spin_about_z(omega)})
        lay = layout_of(sc)
        y = np.zeros(lay.size)
        y[lay.q] = angle
        y[lay.base_angular_velocity] = [0.0, 0.0, omega]
        y[lay.base_orientation] = [0.0, 0.0, math.sin(0.35), math.cos(0.35)]  # any turn about z
        dy = derivative(sc.arrays, y, np.zeros(0, dtype=CONTACT), (0.0,) * 6)
        scale = k * theta / (m * length**2)  # the hinge's share of the acceleration
        if angle[0] == theta * 1.01:
            assert np.abs(dy[lay.w]).max() > 0.01 * scale
        else:
            assert np.abs(dy[lay.w]).max() < 1e-10 * scale


def free_pendulum(phi0, rate0, length, times):
    sol = solve_ivp(lambda _, y: [y[1], -G / length * math.sin(y[0])], (0.0, times[-1]), [phi0, rate0],
                    method="DOP853", rtol=1e-13, atol=1e-15, dense_output=True)
    return sol.sol(times)[0]


@pytest.mark.parametrize("yaw", [0.0, 0.7])
def test_planar_twig_on_the_turning_axis_swings_as_a_free_pendulum(yaw):
    """A planar twig hinged on the rachis' y axis without spring or damper, the rachis (yawed, so that the
    berry's vertical plane has the normal n = Rz(yaw) ŷ) turning about n with a varying rate: no force reaches
    the twig through the hinge, so its angle in that plane, s − pitch(t), swings as a free pendulum whatever
    the rachis does (the rachis frame needs the Euler term and the turned gravity for it)."""
    length, t_end = 0.03, 1.0
    n = np.array([-math.sin(yaw), math.cos(yaw), 0.0])
    ex = {"kind": "sine", "amplitude": [0.0, 0.0, 0.0], "angular_amplitude": list(30.0 * n), "frequency": 2.0,
          "orientation": [0.0, 0.3, yaw], "angular_velocity": list(4.0 * n)}
    berry = {"name": "b", "mass": 0.011, "radius": 0.0135, "twig_length": length, "hinge_x": 0.0,
             "angle": 0.5, "angular_velocity": 2.0}
    run = simulate(scene({"berries": [berry], "excitation": ex, "solver": {"t_end": t_end}}), rtol=1e-12, atol=1e-14)
    motion = SineMotion([0, 0, 0], ex["angular_amplitude"], ex["frequency"], t_end, ex["angular_velocity"])
    # about the fixed axis n: R = Rot(n, θ) Rz(yaw) Ry(0.3) = Rz(yaw) Ry(0.3 + θ), θ = 4 t + ∬ 30 sin 2πft
    pitch = np.array([0.3 + 4.0 * t + motion.turn(t) for t in run.t])
    # in the plane: Ry(pitch) (sin s, 0, −cos s) = (sin(s − pitch), 0, −cos(s − pitch))
    expect = free_pendulum(0.5 - 0.3, 2.0 - 4.0, length, run.t)
    assert np.ptp(pitch) > 3.0  # the rachis turned
    err = np.abs(run.angles[:, 0] - pitch - expect).max()
    assert err < 1e-8, err
    lay = run.layout
    for k in range(0, len(run.t), 100):  # and the orientation is that turn
        R = quaternion_matrix(run.y[k, lay.base_orientation])
        np.testing.assert_allclose(R, euler_matrix(0.0, pitch[k], yaw), atol=1e-9)


def test_spherical_twig_on_the_rachis_origin_swings_as_a_free_spherical_pendulum():
    """A spherical twig hinged at the rachis origin without spring or damper, the rachis tilting and spinning:
    its world direction e = R u(q) follows the free spherical pendulum ë = −(g/l)(ẑ − (ẑ·e) e) − |ė|² e, with
    R(t) integrated here from Ṙ = [ω(t)]× R. In the rachis frame this needs every inertial term (Coriolis
    included: the berry moves fast relative to the spinning rachis)."""
    length, t_end = 0.03, 0.8
    ex = {"kind": "sine", "amplitude": [0.0, 0.0, 0.0], "angular_amplitude": [2.0, -3.0, 1.0], "frequency": 1.5,
          "orientation": [0.2, -0.1, 0.5], "angular_velocity": [0.2, -0.1, 3.0]}
    berry = one_berry(azimuth=0.6, angle=[0.4, 0.3], angular_velocity=[1.0, -0.5], twig_length=length)
    run = simulate(scene({"berries": [berry], "excitation": ex, "solver": {"t_end": t_end}}), rtol=1e-12, atol=1e-14)
    motion = SineMotion([0, 0, 0], ex["angular_amplitude"], ex["frequency"], t_end, ex["angular_velocity"])
    R0 = euler_matrix(*ex["orientation"])
    q0, w0 = np.array(berry["angle"]), np.array(berry["angular_velocity"])
    e0 = R0 @ twig(True, q0, 0.6)
    ed0 = np.cross(motion.at(0.0)[3], e0) + R0 @ twig_jacobian(q0, 0.6) @ w0

    def rhs(t, y):
        e, ed, R = y[:3], y[3:6], y[6:].reshape(3, 3)
        edd = -G / length * (np.array([0.0, 0.0, 1.0]) - e[2] * e) - (ed @ ed) * e
        return np.r_[ed, edd, (skew(motion.at(t)[3]) @ R).ravel()]

    sol = solve_ivp(rhs, (0.0, t_end), np.r_[e0, ed0, R0.ravel()], method="DOP853", rtol=1e-13, atol=1e-15,
                    dense_output=True)
    ref = sol.sol(run.t).T
    lay = run.layout
    worst_e, worst_R = 0.0, 0.0
    for k in range(len(run.t)):
        R = ref[k, 6:].reshape(3, 3)
        worst_R = max(worst_R, np.abs(quaternion_matrix(run.y[k, lay.base_orientation]) - R).max())
        worst_e = max(worst_e, np.abs(R @ twig(True, run.angles[k], 0.6) - ref[k, :3]).max())
    assert np.abs(run.angles[:, 0]).max() < 1.3  # inside the chart
    assert worst_R < 1e-9, worst_R
    assert worst_e < 1e-8, worst_e


# ------------------------------------------------------------------------------------------------------
# 4. stiff twigs turn with the rachis
# ------------------------------------------------------------------------------------------------------
def test_stiff_twigs_follow_the_turning_rachis_rigidly():
    """Stiff hinges, the rachis turned about a fixed tilted axis by a sine angular acceleration (no
    translation): its orientation is R(t) = Rot(n, θ(t)) R0 with θ = ∬ A sin 2πft in closed form; the berries'
    world positions stay on the rigid motion R(t)(h + l u(q0)) within the deflection the hinges allow, and the
    deflection itself is the quasi-static load of the turning frame over k."""
    m, length, k, zeta = 0.011, 0.03, 5.0, 0.2
    inertia = m * length**2
    omega_n = math.sqrt(k / inertia)
    c = 2 * zeta * math.sqrt(k * inertia)
    hinges = [np.array([0.05, 0.01, -0.01]), np.array([-0.04, -0.02, 0.0])]
    psis = [0.7, -1.1]
    berries = [one_berry(name=nm, mass=m, twig_length=length, hinge=list(h), hinge_stiffness=k, hinge_damping=c,
                         azimuth=psi) for nm, h, psi in zip(("a", "b"), hinges, psis)]
    axis = np.array([0.3, -0.5, 0.8]) / np.linalg.norm([0.3, -0.5, 0.8])
    A, f, t_end = 100.0, 2.0, 1.0
    ex = {"kind": "sine", "amplitude": [0.0, 0.0, 0.0], "angular_amplitude": list(A * axis), "frequency": f,
          "orientation": [0.2, 0.1, -0.3], "angular_velocity": [0.0, 0.0, 0.0]}
    run = simulate(scene({"berries": berries, "excitation": ex, "solver": {"t_end": t_end}}), rtol=1e-10, atol=1e-13)
    motion = SineMotion([0, 0, 0], A * axis, f, t_end, [0, 0, 0])
    R0 = euler_matrix(*ex["orientation"])
    lay = run.layout
    q0 = np.zeros(2)
    # the loads of the turning frame on a berry (per unit mass), bounded over the run
    w_max = 2 * A / (2 * math.pi * f)
    p_max = max(np.linalg.norm(h) for h in hinges) + length
    qd_max = np.abs(run.angular_velocities).max()
    load = G + A * p_max + w_max**2 * p_max + 2 * w_max * length * qd_max  # gravity, Euler, centrifugal, Coriolis
    q_load = m * length * load          # |Q| ≤ m l |load| per angle (|∂x/∂q| ≤ l)
    deflection = 2 * q_load / k          # a step load's overshoot at most doubles the static deflection
    tol_position = length * 2 * deflection  # |Δu| ≤ |Δs| + |Δt|
    positions = run.positions
    worst_R = worst_x = worst_out = worst_qs = scale_qs = 0.0
    for j, t in enumerate(run.t):
        R = rodrigues(axis, motion.turn(t)) @ R0
        Rr = quaternion_matrix(run.y[j, lay.base_orientation])
        worst_R = max(worst_R, np.abs(Rr - R).max())
        _, _, _, omega, alpha = motion.at(t)
        for i in range(2):
            q = run.angles[j, 2 * i: 2 * i + 2]
            x = run.y[j, lay.base] + Rr @ (hinges[i] + length * twig(True, q, psis[i]))
            p0 = hinges[i] + length * twig(True, q0, psis[i])
            worst_x = max(worst_x, np.linalg.norm(x - R @ p0))
            worst_out = max(worst_out, np.abs(positions[j, i] - x).max())
            if t >= 0.2:  # the start-up transient has decayed (e^(−ζ ω_n t) < 1e-12)
                accel = np.cross(alpha, R @ p0) + np.cross(omega, np.cross(omega, R @ p0))
                Q = length * twig_jacobian(q0, psis[i]).T @ (R.T @ (m * (np.array([0.0, 0.0, -G]) - accel)))
                worst_qs = max(worst_qs, np.abs(q - q0 - Q / k).max())
                scale_qs = max(scale_qs, np.abs(Q / k).max())
    assert worst_R < 1e-9, worst_R
    assert worst_out < 1e-12, worst_out  # the output channel is the world position
    assert worst_x < tol_position, (worst_x, tol_position)
    assert worst_x > 0.05 * tol_position  # the bound is not vacuous: the hinges do give
    # quasi-static: the load changes at |ω| + 4πf at most, r = that / ω_n; a damped oscillator lags by 2ζr and
    # overshoots by r²; the loads' own stiffness (m l |load|) shifts it by that over k
    r = (w_max + 4 * math.pi * f) / omega_n
    tol_qs = 2 * (2 * zeta * r + r**2 + q_load / k)
    assert worst_qs < tol_qs * scale_qs, (worst_qs / scale_qs, tol_qs)


# ------------------------------------------------------------------------------------------------------
# 5. the energy ledger
# ------------------------------------------------------------------------------------------------------
KV_FLOOR = {"name": "floor", "point": [0.0, 0.0, -0.05], "normal": [0.0, 0.0, 1.0], "law": "kelvin-voigt",
            "stiffness": 3000.0, "restitution": 0.4}
LEDGER_CASES = {
    "yawed planar pair pitched and lowered onto a floor": {
        "berries": [{"name": "left", "mass": 0.011, "radius": 0.0135, "twig_length": 0.03, "hinge_x": -0.015,
                     "hinge_stiffness": 1e-3, "hinge_damping": 2e-5, "angle": -0.3},
                    {"name": "right", "mass": 0.011, "radius": 0.0135, "twig_length": 0.03, "hinge_x": 0.015,
                     "hinge_stiffness": 1e-3, "hinge_damping": 2e-5, "angle": 0.3}],
        "contact": {"law": "kelvin-voigt", "stiffness": 2000.0, "restitution": 0.5},
        "obstacles": [KV_FLOOR],
        "excitation": {"kind": "sine", "amplitude": [1.0, 0.3, -0.4], "frequency": 2.0, "duration": 0.5,
                       "orientation": [0.0, 0.0, 0.4],  # turning about the plane's normal Rz(0.4) ŷ
                       "angular_amplitude": [-10.0 * math.sin(0.4), 10.0 * math.cos(0.4), 0.0],
                       "angular_velocity": [math.sin(0.4), -math.cos(0.4), 0.0]},
        "solver": {"t_end": 1.0}},
    "spherical berry landing on a tilted floor while the rachis turns": {
        "berries": [LANDING_BERRY], "obstacles": [TILTED_FLOOR], "excitation": LOWER_AND_TILT,
        "solver": {"t_end": 0.8}},
    "spherical berry on a tilting, spinning, translating rachis": {
        "berries": [SPUN_BERRY], "excitation": TILT_SPIN, "solver": {"t_end": 0.6}},
}


@pytest.mark.parametrize("name", list(LEDGER_CASES))
def test_ledger_closes_with_a_turning_rachis(name):
    doc = LEDGER_CASES[name]
    run = simulate(scene(doc), rtol=1e-11, atol=1e-13)
    if "obstacles" in doc:
        assert any(run.scene.model.touches_obstacle(int(p)) for p in run.impacts.pair)
    work = run.energy["base_work"]
    assert np.ptp(work) > 0.1 * np.ptp(run.energy["stored"])  # the turning rachis does work that matters
    assert run.ledger_error() < 1e-8, run.ledger_report()


# ------------------------------------------------------------------------------------------------------
# 6. planar berries turn about their plane's normal only
# ------------------------------------------------------------------------------------------------------
def planar_pair(excitation: dict) -> dict:
    return {**LEDGER_CASES["yawed planar pair pitched and lowered onto a floor"], "excitation": excitation}


@pytest.mark.parametrize("key, value, fine", [
    ("angular_amplitude", [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]),
    ("angular_amplitude", [0.0, 0.5, 2.0], [0.0, 0.5, 0.0]),
    ("orientation", [0.1, 0.0, 0.0], [0.0, 0.1, 0.0]),     # roll tilts the berries' plane
    ("orientation", [0.3, 0.2, 0.0], [0.0, 0.2, 0.3]),     # pitch and yaw keep it vertical
    ("angular_velocity", [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]),
    ("angular_velocity", [0.5, 0.0, 0.0], [0.0, 0.5, 0.0]),
])
def test_a_planar_scene_turning_about_x_or_z_is_refused_naming_the_key(key, value, fine):
    ex = {"kind": "sine", "amplitude": [1.0, 0.0, 0.0], "frequency": 2.0, key: value}
    with pytest.raises(SceneError) as err:
        scene(planar_pair(ex))
    assert f"excitation.{key}" in str(err.value)
    scene(planar_pair({**ex, key: fine}))  # about the plane's normal it is accepted


def test_a_yawed_planar_scene_turns_about_its_plane_normal_only():
    """Yawed by ψ, the berries' plane has the normal Rz(ψ) ŷ: a turn about the world y axis is then refused,
    one about the normal accepted."""
    yaw = 0.6
    n = [-math.sin(yaw), math.cos(yaw), 0.0]
    ex = {"kind": "sine", "amplitude": [1.0, 0.0, 0.0], "frequency": 2.0, "orientation": [0.0, 0.0, yaw]}
    with pytest.raises(SceneError) as err:
        scene(planar_pair({**ex, "angular_amplitude": [0.0, 2.0, 0.0]}))
    assert "excitation.angular_amplitude" in str(err.value)
    with pytest.raises(SceneError) as err:
        scene(planar_pair({**ex, "angular_velocity": [0.0, 1.0, 0.0]}))
    assert "excitation.angular_velocity" in str(err.value)
    scene(planar_pair({**ex, "angular_amplitude": [2.0 * c for c in n], "angular_velocity": n}))


def test_a_yawed_planar_scene_takes_the_rounding_of_a_turn_as_no_turn():
    """A master that integrates α into ω component by component, turning a yawed planar scene about its axis and back
    to rest, sends ω = (1.9e-16, -1.4e-16, 0) rad/s: rounding, all of it across the axis. Judged relative to itself
    (1e-9 of the vector) it was a turn about another axis and the step was refused (the FMU returned Error). Below
    ACROSS_FLOOR it is none; a turn across the axis at the floor's scale still is, and the state is kept."""
    from grapefmu import Solver, SolverError
    from grapefmu.model.model import ACROSS_FLOOR
    yaw = 0.5
    n = np.array([-math.sin(yaw), math.cos(yaw), 0.0])
    sc = scene(planar_pair({"kind": "none", "orientation": [0.0, 0.0, yaw]}))
    s = Solver(sc, driven=True)
    omega = np.zeros(3)
    for a in [3.0] * 100 + [-3.0] * 100:  # ω summed per component, as a master's integrator does: about n, then back
        omega = omega + a * 1e-3 * n
    rest = tuple(float(c) for c in omega)
    assert 0.0 < max(map(abs, rest)) < 1e3 * ACROSS_FLOOR  # rounding, not exactly 0 ...
    assert np.abs(np.cross(rest, n)).max() > 1e-9 * max(map(abs, rest))  # ... and across n, to the relative test
    s.advance(0.01, (0.0,) * 6, rest)
    assert s.t == pytest.approx(0.01)
    across = (0.0, 0.0, 10 * ACROSS_FLOOR)
    before = s.get_state()
    with pytest.raises(SolverError, match="angular_velocity"):
        s.advance(0.01, (0.0,) * 6, across)
    assert s.t == before.physical.t[0]


def test_a_constant_angular_acceleration_about_x_is_refused_for_planar_berries():
    ex = {"kind": "constant", "accel": [0.0, 0.0, 0.0], "angular_accel": [0.3, 0.0, 0.0]}
    with pytest.raises(SceneError) as err:
        scene(planar_pair(ex))
    assert "excitation.angular_accel" in str(err.value)
    scene(planar_pair({**ex, "angular_accel": [0.0, 0.3, 0.0]}))


def test_a_scene_with_one_planar_berry_among_spherical_ones_is_refused_a_turn_about_x():
    doc = planar_pair({"kind": "sine", "amplitude": [1.0, 0.0, 0.0], "frequency": 2.0,
                       "angular_amplitude": [1.0, 0.0, 0.0]})
    doc["berries"] = [doc["berries"][0], {**LANDING_BERRY, "hinge": [0.05, 0.0, 0.0]}]
    with pytest.raises(SceneError) as err:
        scene(doc)
    assert "excitation.angular_amplitude" in str(err.value)

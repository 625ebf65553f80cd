"""How many steps an explicit pair needs at the least for a scene's stiffest hinge, known before the first step, and
which hinge a fixed step blew up (docs/reliability.md, "Known limits": stiff scenes).

An explicit Runge–Kutta step h is stable on y' = λy only while hλ lies in the pair's stability region
{z : |R(z)| ≤ 1}, R(z) = 1 + Σ_k z^k bᵀ A^(k−1) 𝟙. Its largest radius in the left half-plane, r_max, bounds every
stable step by r_max / |λ|, so a run over T needs at least T |λ| / r_max steps, whatever the tolerance. A berry's
hinge is such a λ: m l² q̈ = −c q̇ − K q about any pose, with K the hinge stiffness k plus the pull of gravity and
the rachis (at most m l G). The eigenvalues' sum is −c/(m l²) and their product K/(m l²), so the faster one is at
least max(c / (2 m l²), √(K / (m l²))) in magnitude (a spherical berry's tilt has the smaller inertia m l² cos² s:
faster still). A run whose bound passes its step limit cannot end: it is refused at once, naming the berry and its
hinge, where before it stepped to the limit (10⁷ steps, tens of seconds) and then named no berry. A fixed step past
a hinge's stability grows its mode every step until the state is NaN; the error then names the hinge and the
longest stable fixed step (fixed_step_hint, on an estimate of the eigenvalue rather than a bound). A contact law is
stiff only while its pair touches, so it cannot be refused before a step; a run that stops at its step limit with
pairs in contact names them and their laws (contact_hint)."""
from __future__ import annotations

import math

import numpy as np

from ..errors import SolverError
from ..model.contact import LAW_BOUNDS, Law
from ..model.excitation import MAX_ACCEL
from ..model.model import Model
from .tableau import Tableau

#: directions in the upper left quarter-plane (R has real coefficients: its region is symmetric about the real axis)
_ANGLES = np.linspace(math.pi / 2, math.pi, 181)  # 0.5° apart: the radii agree with 721 directions' to 1.2e-5


def stability_polynomial(tb: Tableau) -> np.ndarray:
    """R's coefficients, constant first: 1, bᵀ𝟙, bᵀA𝟙, bᵀA²𝟙, … (A strictly lower triangular: degree ≤ stages)."""
    coef, v = [1.0], np.ones(tb.b.shape[0])
    for _ in range(tb.b.shape[0]):
        coef.append(float(tb.b @ v))
        v = tb.a @ v
    return np.array(coef)


def _edge(coef: np.ndarray, direction: complex) -> float:
    """How far the region reaches from the origin along a unit direction: |R(r d)|² − 1 is a real polynomial in r, and
    its smallest positive root is where the region seen from the origin ends that way. Islands beyond it about R's far
    zeros (DOP853's at z = −23.2, |R| < 1 within about 1e-5 of it) are narrower than any step-size controller's
    spread, and left out."""
    alpha = coef * direction ** np.arange(len(coef))
    sq = np.convolve(alpha, alpha.conj()).real
    sq[0] -= 1.0
    roots = np.roots(sq[::-1])
    real = roots[(np.abs(roots.imag) <= 1e-9 * np.abs(roots)) & (roots.real > 1e-6)].real  # r = 0 is a root
    return float(real.min(initial=np.inf))


def _radius(coef: np.ndarray) -> float:
    far = max(_edge(coef, complex(math.cos(phi), math.sin(phi))) for phi in _ANGLES)
    return far * 1.001  # between the directions the edge may reach a little farther: a bound may only be too long


#: r_max of each tableau asked for, by identity (4 to 16 ms to find, once a process; every Solver asks)
_RADII: dict[int, tuple[Tableau, float]] = {}


def stability_radius(tb: Tableau) -> float:
    """r_max: the largest |z| of the pair's stability region in Re z ≤ 0, as seen from the origin along each direction
    (_radius; tests/test_stiffness.py gives each)."""
    known = _RADII.get(id(tb))
    if known is None or known[0] is not tb:
        known = _RADII[id(tb)] = (tb, _radius(stability_polynomial(tb)))
    return known[1]


def hinge_rate(b, gravity: float, turning: bool) -> float:
    """A lower bound on berry b's fastest hinge eigenvalue |λ| (1/s). The pull on it is at most g plus the largest
    rachis acceleration a scene may give (MAX_ACCEL); a turning rachis adds fields no such bound holds, so there only
    the damping's part is taken."""
    inertia = b.mass * b.twig_length * b.twig_length
    if inertia <= 0.0:  # a mass so small that m l² underflows (5e-324 kg): no explicit step can follow it
        return math.inf
    rate = b.hinge_damping / (2.0 * inertia)
    if not turning:
        k_low = b.hinge_stiffness - b.mass * b.twig_length * (gravity + MAX_ACCEL)
        if k_low > 0.0:
            rate = max(rate, math.sqrt(k_low / inertia))
    return rate


def least_steps(model: Model, tb: Tableau, span: float, turning: bool) -> tuple[float, int]:
    """(steps, berry): the fewest steps any run of `span` seconds can take, set by the berry whose hinge asks most."""
    best, which = -1.0, 0
    for i, b in enumerate(model.berries):
        rate = hinge_rate(b, model.gravity, turning)
        if rate > best:
            best, which = rate, i
    return span * best / stability_radius(tb), which


def refuse_stiff(model: Model, tb: Tableau, integrator: str, span: float, turning: bool, max_steps: int) -> None:
    """A SolverError, before any step, if the stiffest hinge alone needs more than max_steps steps over span."""
    steps, i = least_steps(model, tb, span, turning)
    if not steps > max_steps:
        return
    b = model.berries[i]
    rate = hinge_rate(b, model.gravity, turning)
    raise SolverError(
        f"berries[{i}] ({b.name!r}): its hinge is too stiff for the explicit solver ({integrator}) within max_steps = "
        f"{max_steps}: hinge_damping = {b.hinge_damping:g} N·m·s/rad and hinge_stiffness = {b.hinge_stiffness:g} "
        f"N·m/rad on an inertia m l² = {b.mass * b.twig_length ** 2:.3g} kg·m² give a time scale of "
        f"{1.0 / rate:.3g} s, so no stable step is longer than "
        f"{span / steps:.3g} s and the {span:g} s asked need at least {steps:.3g} steps; lower its hinge_damping "
        "or hinge_stiffness, give the berry more mass or a longer twig, or allow more steps (solver.max_steps) "
        "(docs/reliability.md, 'Known limits'); nothing was run")


def hinge_eigenvalue(b, gravity: float) -> complex:
    """Berry b's faster hinge eigenvalue hanging at rest, m l² λ² + c λ + (k + m g l) = 0: an estimate (the pose and
    the rachis change the pull), where hinge_rate is a bound."""
    inertia = b.mass * b.twig_length * b.twig_length
    disc = b.hinge_damping ** 2 - 4.0 * inertia * (b.hinge_stiffness + b.mass * gravity * b.twig_length)
    if disc >= 0.0:
        return complex(-(b.hinge_damping + math.sqrt(disc)) / (2.0 * inertia), 0.0)
    return complex(-b.hinge_damping, math.sqrt(-disc)) / (2.0 * inertia)


def fixed_step_hint(model: Model, tb: Tableau, integrator: str, h: float) -> str | None:
    """Why a fixed step h may have blown a run up: the hinge whose eigenvalue (hinge_eigenvalue) h carries furthest
    outside the pair's stability region, with the longest step that keeps it inside; None if every one is inside."""
    coef = stability_polynomial(tb)
    worst = None
    for i, b in enumerate(model.berries):
        lam = hinge_eigenvalue(b, model.gravity)
        if lam == 0.0:
            continue
        reach = _edge(coef, lam / abs(lam))
        over = h * abs(lam) / reach
        if over > 1.0 and (worst is None or over > worst[0]):
            worst = (over, i, lam, reach)
    if worst is None:
        return None
    _, i, lam, reach = worst
    b = model.berries[i]
    return (f"berries[{i}] ({b.name!r}): its hinge (hinge_damping = {b.hinge_damping:g} N·m·s/rad, hinge_stiffness = "
            f"{b.hinge_stiffness:g} N·m/rad, m l² = {b.mass * b.twig_length ** 2:.3g} kg·m²) has an eigenvalue of "
            f"{abs(lam):.3g} /s hanging, so the fixed step {h:g} s puts hλ {h * abs(lam):.3g} from the origin, beyond "
            f"the edge of {integrator}'s stability region that way ({reach:.3g}); a fixed step under "
            f"{reach / abs(lam):.3g} s keeps it stable")


def contact_hint(model: Model, contacts: np.ndarray, delta: np.ndarray) -> str | None:
    """The pairs in contact (contacts: each pair's CONTACT record; delta: its overlap δ, m) and their laws, for a run
    that stopped at its step limit there: a law far stiffer or more damped than its berries' mass m (m_i m_j /
    (m_i + m_j) between berries, m_i on an obstacle) shortens the steps while the pair touches. Each law's time
    scales on m: Kelvin–Voigt's m/c and √(m/k); a Hertzian law's √(m/k) on its stiffness at the overlap,
    k = dF/dδ = 1.5 K √δ, and Hunt–Crossley's also m/c on its damping there, c = ∂F/∂δ̇ = χ K δ^1.5 / δ̇⁻ (docs/model.md
    §3). None when no pair touches."""
    touching = np.flatnonzero(contacts["mode"])
    if not len(touching):
        return None
    nb, words = model.n_berries, []
    for p in touching[:3]:
        pr, law = model.pairs[p], model.pairs[p].law
        m = model.berries[pr.i].mass
        if pr.j < nb:
            m = m * model.berries[pr.j].mass / (m + model.berries[pr.j].mass)
        units = LAW_BOUNDS[law.law]
        text = f"{model.pair_name(p)} ({law.kind}: stiffness {law.stiffness:.3g} {units['stiffness'].unit}"
        if law.law != Law.HERTZ:  # the only law without a damping coefficient
            text += f", damping {law.damping:.3g} {units['damping'].unit}"
        text += f"; m = {m:.3g} kg"
        c = None  # Hertz: undamped
        if law.law == Law.KELVIN_VOIGT:
            k, c = law.stiffness, law.damping
        else:
            d = max(float(delta[p]), 0.0)
            k = 1.5 * law.stiffness * math.sqrt(d)
            text += f"; at δ = {d:.3g} m, k = {k:.3g} N/m"
            if law.law == Law.HUNT_CROSSLEY:
                v = float(contacts["v_onset"][p])
                c = law.damping * law.stiffness * d * math.sqrt(d) / v if v > 0.0 else math.inf
                text += f", c = {c:.3g} N·s/m"
        if c is not None:
            text += f", m/c = {m / c if c > 0 else math.inf:.3g} s"
        text += f", √(m/k) = {math.sqrt(m / k) if k > 0 else math.inf:.3g} s"
        words.append(text + ")")
    more = f" and {len(touching) - 3} more" if len(touching) > 3 else ""
    return f"in contact when it stopped: {'; '.join(words)}{more}"

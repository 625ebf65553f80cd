"""The broad phase: a Verlet list of the pairs that can touch soon (docs/solver.md).

The list keeps every candidate pair whose gap was below the skin when it was built, and every pair in
contact; it stays valid while no berry moves skin/2 from where it was (in the rachis frame, and in the
world frame too when the scene has obstacles, which are fixed there). Its validity is checked on every
step's samples (`reach`), which are also what the event search reads.
"""
from __future__ import annotations

import math

import numpy as np

from ..physics.compiled import inline, jit
from ..physics.kinematics import KINEMATICS, contact_gap, fixed_in_world, kinematics
from ..physics.layout import model_head, model_offsets
from .events import N_SAMPLES
from .step import dense_head


@jit
def samples_for(M):
    """The berries at the N_SAMPLES + 1 equally spaced points of a step's dense output: (N_SAMPLES + 1, N)."""
    return np.zeros((N_SAMPLES + 1, M.berry.shape[0]), dtype=KINEMATICS)


@jit
def rebuild(M, contacts, Bk, B, kin, skin):
    """Keep the pairs with a gap below `skin` with the berries at kin, and every pair in contact.
    A smooth law under step-size control is evaluated inline exactly for its near pairs."""
    nn = 0
    for p in range(contacts.shape[0]):
        c = contacts[p]
        pr = M.pair[p]
        near = -contact_gap(M, pr, kin)[0] < skin or c.mode != 0
        if Bk.pair[p].smooth_until == np.inf:
            c.smooth = near
        if near or c.smooth:
            B.near[nn] = p
            nn += 1
    B.count[0] = nn
    for i in range(kin.shape[0]):
        k = kin[i]
        B.reference[i, 0], B.reference[i, 1], B.reference[i, 2] = k.px, k.py, k.pz
        B.reference[i, 3], B.reference[i, 4], B.reference[i, 5] = k.wx, k.wy, k.wz
    Bk.counters[0].near_list_rebuilds += 1


@jit
def sample(y0, q, h, M, work, samples):
    """Fill samples from the step's dense output (stage 1 at every sample point) but its ends, which the loop put
    there: θ = 0, y0 itself, and θ = 1, the step's end (its FSAL stage)."""
    m = model_head(M)  # the head of y: angles, rates and the rachis motion
    for k in range(1, N_SAMPLES):
        dense_head(k / N_SAMPLES, y0, q, h, work, m)
        kinematics(work, M, samples[k])


@jit
def reach(samples, reference, world):
    """How far any berry gets from reference over the step: its samples, plus half the largest chord
    between samples for the stretch in between; in the world frame as well if `world` (obstacles)."""
    worst = 0.0
    for i in range(samples.shape[1]):
        for k in range(N_SAMPLES + 1):
            p = samples[k, i]
            d = math.sqrt((p.px - reference[i, 0]) ** 2 + (p.py - reference[i, 1]) ** 2 + (p.pz - reference[i, 2]) ** 2)
            if k > 0:
                o = samples[k - 1, i]
                d += 0.5 * math.sqrt((p.px - o.px) ** 2 + (p.py - o.py) ** 2 + (p.pz - o.pz) ** 2)
            worst = max(worst, d)
            if world:
                d = math.sqrt((p.wx - reference[i, 3]) ** 2 + (p.wy - reference[i, 4]) ** 2
                              + (p.wz - reference[i, 5]) ** 2)
                if k > 0:
                    d += 0.5 * math.sqrt((p.wx - o.wx) ** 2 + (p.wy - o.wy) ** 2 + (p.wz - o.wz) ** 2)
                worst = max(worst, d)
    return worst


@inline
def travel(q, h, r):
    """A bound on how far component r of y gets on the step's dense output, |y_r(θ) − y_r(0)| for θ in [0, 1]: the
    largest Bernstein coefficient of h Σ_j Q[r, j] θ^(j+1) (a polynomial on [0, 1] lies within its Bernstein
    coefficients; β_i = Σ_{m ≤ i} C(i, m) / C(n, m) a_m from the power coefficients a_m, a_0 = 0). Tight where
    Σ_j |Q[r, j]| is not: DOP853's power-basis coefficients reach several hundred and cancel."""
    worst = 0.0
    for i in range(1, q.shape[1] + 1):
        worst = max(worst, abs(bernstein(q, r, i)))
    return h * worst


def _bernstein_weights(degree: int) -> np.ndarray:
    """W[n, i, m] = C(i, m) / C(n, m) for 1 ≤ m ≤ i ≤ n ≤ degree, as the running product Π_(k ≤ m) (i − k + 1) /
    (n − k + 1): a table, because that chain of divisions, on every angle of every step, took a third of quiet()."""
    w = np.zeros((degree + 1, degree + 1, degree + 1))
    for n in range(1, degree + 1):
        for i in range(1, n + 1):
            c = 1.0
            for m in range(1, i + 1):
                c *= (i - m + 1) / (n - m + 1)
                w[n, i, m] = c
    return w


#: for dense outputs of degree up to 8 (DOP853's is 7: Q has 7 columns)
BERNSTEIN = _bernstein_weights(8)


@inline
def bernstein(q, r, i):
    """Σ_(m ≤ i) C(i, m) / C(n, m) Q[r, m − 1]: the i-th Bernstein coefficient of Σ_j Q[r, j] θ^(j+1), degree n."""
    w = BERNSTEIN[q.shape[1], i]
    b = 0.0
    for m in range(1, i + 1):
        b += w[m] * q[r, m - 1]
    return b


@jit
def quiet(y0, q, h, M, contacts, B, cfg, kin, bound, suspect):
    """A certificate that a step needs neither samples nor an event search, or −1: no berry gets skin/2 from the
    near list's reference, and no near pair that is apart (and event-located) can touch, on the step's dense output.
    Returns the bound on how far a berry got from the reference (the caller's `far`, as keep_valid's).

    The bound on berry i's travel: its twig end moves at most l (|Δs| + |Δt|) (u is 1-Lipschitz in s and in t),
    and in the world frame also |Δb| + ‖ΔR‖ |p| (‖ΔR‖ ≤ 2 |Δq̂| ≤ 4 |Δq| / |q| for the orientation quaternion q);
    each from travel(). A gap moves at most by the travel of what it separates (|∇δ| ≤ 1 in each position).
    kin holds stage 1 at the step's start; bound ((N, 2)) each berry's travel in the rachis and the world frame;
    suspect[kk] whether near pair kk can switch on this step (the bound cannot rule it out): the event search looks
    at the suspects alone (every near pair when the list itself is not certified)."""
    nb = M.berry.shape[0]
    world = M.obstacle.shape[0] > 0
    o_bv, o_b, o_om, o_rot = model_offsets(M)[:4]
    for kk in range(B.count[0]):
        suspect[kk] = True
    base = 0.0
    turn = 0.0
    if world and M.moving:
        base = math.sqrt(travel(q, h, o_b) ** 2 + travel(q, h, o_b + 1) ** 2 + travel(q, h, o_b + 2) ** 2)
        if M.turning:
            n0 = math.sqrt(y0[o_rot] ** 2 + y0[o_rot + 1] ** 2 + y0[o_rot + 2] ** 2 + y0[o_rot + 3] ** 2)
            if n0 < 0.5:
                return -1.0
            turn = 4.0 * math.sqrt(travel(q, h, o_rot) ** 2 + travel(q, h, o_rot + 1) ** 2
                                   + travel(q, h, o_rot + 2) ** 2 + travel(q, h, o_rot + 3) ** 2) / n0
    ref = B.reference
    far = 0.0
    for i in range(nb):
        b = M.berry[i]
        d = travel(q, h, b.dof)
        if b.n_angles == 2:
            d += travel(q, h, b.dof + 1)
        d *= b.twig_length
        k = kin[i]
        bound[i, 0] = d
        far = max(far, d + math.sqrt((k.px - ref[i, 0]) ** 2 + (k.py - ref[i, 1]) ** 2 + (k.pz - ref[i, 2]) ** 2))
        if world:
            dw = d + base + turn * (math.sqrt(k.px * k.px + k.py * k.py + k.pz * k.pz) + d)
            bound[i, 1] = dw
            far = max(far, dw + math.sqrt((k.wx - ref[i, 3]) ** 2 + (k.wy - ref[i, 4]) ** 2 + (k.wz - ref[i, 5]) ** 2))
    if not (far <= 0.5 * cfg.skin):
        return -1.0
    if not cfg.locate:
        return far
    calm = True
    for kk in range(B.count[0]):
        p = B.near[kk]
        c = contacts[p]
        if c.smooth:
            suspect[kk] = False  # evaluated inline, never located
            continue
        if c.mode != 0:
            calm = False
            continue
        pr = M.pair[p]
        if pr.j < nb:
            reach = bound[pr.i, 0] + bound[pr.j, 0]
        else:
            reach = bound[pr.i, 1] if fixed_in_world(M, pr) else bound[pr.i, 0]
        delta = contact_gap(M, pr, kin)[0]
        if delta + 1.001 * reach + 1e-12 < 0.0:  # margin for rounding in the gap and the polynomials
            suspect[kk] = False
        else:
            calm = False
    return far if calm else -1.0


@jit
def keep_valid(y0, q, h, M, contacts, Bk, B, cfg, work, samples):
    """Keep the near list valid over this step. Returns how far a berry got from the list's reference
    (the caller rebuilds after the step once that passes skin/4), or −1: retry shorter.

    Up to skin/2 the list holds for the whole step. Beyond, a pair outside the list could have touched
    inside this step: with event location the list is rebuilt from the step's start (wide enough for
    the step) and the events search it; under step-size control the forces of such a pair were
    missing from the stages, so the step is refused."""
    if contacts.shape[0] == 0:
        return 0.0
    sample(y0, q, h, M, work, samples)
    world = M.obstacle.shape[0] > 0
    far = reach(samples, B.reference, world)
    if not math.isfinite(cfg.skin):
        return 0.0
    if far <= 0.5 * cfg.skin:
        return far
    if cfg.step_control:
        return -1.0
    rebuild(M, contacts, Bk, B, samples[0], cfg.skin)
    far = reach(samples, B.reference, world)
    if far > 0.5 * cfg.skin:
        rebuild(M, contacts, Bk, B, samples[0], 2.0 * far * 1.001)
    return math.inf  # rebuild again from the committed state

"""Contact events (docs/solver.md): which function a pair watches in its mode, where on a step's dense
output it turns positive, and what a switch changes (mode, impact book, Zeno guard).

An event is where sign·fn turns positive: δ (the gap closes or opens) and φ (the clamped law unloads
or loads again). Each function is sampled on the step's dense output, so a contact that opens and
closes inside one step is still seen; a sampled local maximum close to zero is refined, so a graze
between two samples is not missed.
"""
from __future__ import annotations


import numpy as np

from ..model.contact import HC_MIN_APPROACH_SPEED, Law
from ..physics.compiled import inline, jit
from ..physics.damage import bruise_thresholds, bruising
from ..physics.forces import pair_force, pair_law
from ..physics.kinematics import contact_gap, pair_state
from .step import dense_pair

EV_DELTA, EV_PHI = 0, 1
EV_FORCE = 2           # not an event: the pair's force, for the peak search (sampling.py), through the same maximiser
N_SAMPLES = 4          # sub-intervals per step searched for a sign change (plus local-maximum refinement)
ROOT_TOL = 1e-13       # s, absolute tolerance of event times
ARGMAX_TOL = 1.5e-8    # of the step, the place of a maximum: √ε, below which its values differ by round-off only
GOLDEN = 0.3819660112501051  # golden section, 1 − 1/φ (Brent's maximiser, brent_point)


@inline
def event_value(fn, sign, pr, c, delta, delta_dot):
    """sign·fn of a pair (pr PAIR, c CONTACT record) at penetration δ and rate δ̇."""
    if fn == EV_DELTA:
        return sign * delta
    if fn == EV_PHI:
        return sign * pair_law(pr, c.v_onset, delta, delta_dot)[2]
    return sign * pair_force(pr, c, delta, delta_dot)[0]


@inline
def watched(mode, law, clamp):
    """(count, fn1, sign1, fn2, sign2): the functions a pair watches in its mode."""
    clamped = clamp and law != Law.HERTZ
    if mode == 0:
        return 1, EV_DELTA, 1.0, EV_PHI, 0.0
    if mode == 1:
        return (2 if clamped else 1), EV_DELTA, -1.0, EV_PHI, -1.0
    return 2, EV_DELTA, -1.0, EV_PHI, 1.0


@jit
def value_at(fn, sign, p, y, M, contacts, kin):
    """An event function of pair p at state y."""
    pr = M.pair[p]
    delta, delta_dot, _, _, _ = pair_state(y, M, pr, kin)
    return event_value(fn, sign, pr, contacts[p], delta, delta_dot)


@jit
def classify(p, y, M, contacts, kin, old_mode):
    """(mode, δ̇): the mode the state is in, 0 apart, 1 loaded, 2 overlapping but unloaded; a pair that
    was apart is judged with the onset speed it would get now."""
    pr = M.pair[p]
    delta, delta_dot, _, _, _ = pair_state(y, M, pr, kin)
    if delta <= 0.0:
        return 0, delta_dot
    vo = contacts[p].v_onset if old_mode != 0 else max(delta_dot, HC_MIN_APPROACH_SPEED)
    return (1 if pair_law(pr, vo, delta, delta_dot)[2] > 0.0 else 2), delta_dot


@jit
def locate_root(fn, sign, p, ta, tb, y0, q, h, M, contacts, kin, work, tol):
    """Illinois iteration on θ ∈ [ta, tb] with v(ta) ≤ 0 < v(tb); returns the right end."""
    pr = M.pair[p]
    dense_pair(ta, y0, q, h, work, M, pr)
    va = value_at(fn, sign, p, work, M, contacts, kin)
    dense_pair(tb, y0, q, h, work, M, pr)
    vb = value_at(fn, sign, p, work, M, contacts, kin)
    side = 0
    for _ in range(200):
        if (tb - ta) * h <= tol:
            break
        if va < vb and va <= 0.0 < vb:
            tm = (ta * vb - tb * va) / (vb - va)
        else:
            tm = 0.5 * (ta + tb)
        if not (ta < tm < tb):
            tm = 0.5 * (ta + tb)
        if (tb - ta) * h < 64 * tol:  # keep the bracket shrinking from both sides
            tm = 0.5 * (ta + tb)
        dense_pair(tm, y0, q, h, work, M, pr)
        vm = value_at(fn, sign, p, work, M, contacts, kin)
        if vm > 0.0:
            tb, vb = tm, vm
            if side == 1:
                va *= 0.5
            side = 1
        else:
            ta, va = tm, vm
            if side == -1:
                vb *= 0.5
            side = -1
    return tb


@inline
def far_below(v, v_left, v_right):
    """Whether a local maximum sampled as v between v_left and v_right is far below zero: below by twice the rise
    from its neighbours (a parabola through the three peaks at most a quarter of that rise above v)."""
    return v + 2.0 * ((v - v_left) + (v - v_right)) <= 0.0


@inline
def graze_possible(va, vb, sa, sb):
    """Whether a function with values va, vb ≤ 0 and slopes sa, sb (per the interval's length) at an interval's ends
    may reach zero inside it: it must turn from rising to falling there, and its tangents at the ends meet above zero
    or within their rise of it (where they meet bounds a concave function; the margin covers a slope that is read
    from the interpolated rates, not differentiated). A sampled local maximum alone misses a graze just after a
    step's start: the start is then the largest sample, and a parabola through the samples puts the maximum
    at the start, far below zero (a 0.5 µm graze 6.5 ms into a 56 ms DOP853 step was missed that way)."""
    if not (sa > 0.0 and sb < 0.0):
        return False
    u = min(max((vb - va - sb) / (sa - sb), 0.0), 1.0)
    peak = va + sa * u
    return peak + (peak - max(va, vb)) > 0.0


@jit
def largest_on(fn, sign, p, a, b, fa, fb, y0, q, h, M, contacts, kin, work, graze):
    """The largest sign·fn on [a, b] (θ units; fa, fb its values there), by Brent's method (brent_point): returns
    (θ, value) once the bracket is ARGMAX_TOL wide (ROOT_TOL / h on a shorter step), or for a graze search (`graze`)
    as soon as a value is positive or the largest is far below zero. A graze and a force peak are smooth maxima, so
    the parabolic steps converge in a few evaluations where golden sections alone took thirty to forty."""
    pr = M.pair[p]
    tol = max(ROOT_TOL / h, ARGMAX_TOL)
    x = w = v = a + GOLDEN * (b - a)
    dense_pair(x, y0, q, h, work, M, pr)
    fx = value_at(fn, sign, p, work, M, contacts, kin)
    fw = fv = fx
    d = e = 0.0
    for _ in range(60):
        if graze and (fx > 0.0 or far_below(fx, fa, fb)):
            break
        done, u, d, e = brent_point(a, b, x, w, v, fx, fw, fv, d, e, tol)
        if done:
            break
        dense_pair(u, y0, q, h, work, M, pr)
        fu = value_at(fn, sign, p, work, M, contacts, kin)
        a, fa, b, fb, x, fx, w, fw, v, fv = brent_keep(u, fu, a, fa, b, fb, x, fx, w, fw, v, fv)
    return x, fx


@inline
def brent_point(a, b, x, w, v, fx, fw, fv, d, e, tol):
    """Brent's maximiser on [a, b] (scipy's minimiser with its signs turned): x the best point so far, w and v the
    two before it, d and e its last two steps. Returns (done, u, d, e): done once x is within the tolerance of the
    bracket's middle, else the next point u, by a parabola through x, w, v where it helps, else a golden section.
    The one step both peak searches take (largest_on here, sampling.largest_tension)."""
    xm = 0.5 * (a + b)
    tol1 = tol + 1e-15 * abs(x)
    if abs(x - xm) <= 2.0 * tol1 - 0.5 * (b - a):
        return True, x, d, e
    golden = True
    if abs(e) > tol1:  # a parabola through x, w, v (maximising: the signs of scipy's minimiser turned)
        r = (x - w) * (fv - fx)
        t = (x - v) * (fw - fx)
        num = (x - v) * t - (x - w) * r
        den = 2.0 * (t - r)
        if den > 0.0:
            num = -num
        den = abs(den)
        if abs(num) < abs(0.5 * den * e) and den * (a - x) < num < den * (b - x):
            e, d = d, num / den
            golden = False
            if (x + d) - a < 2.0 * tol1 or b - (x + d) < 2.0 * tol1:
                d = tol1 if xm >= x else -tol1
    if golden:
        e = (a - x) if x >= xm else (b - x)
        d = GOLDEN * e
    return False, x + (d if abs(d) >= tol1 else (tol1 if d > 0.0 else -tol1)), d, e


@inline
def brent_keep(u, fu, a, fa, b, fb, x, fx, w, fw, v, fv):
    """The bracket (a, b) and Brent's three best points (x, w, v) once the value fu at u is known."""
    if fu >= fx:
        if u >= x:
            a, fa = x, fx
        else:
            b, fb = x, fx
        v, fv, w, fw, x, fx = w, fw, x, fx, u, fu
    else:
        if u < x:
            a, fa = u, fu
        else:
            b, fb = u, fu
        if fu >= fw or w == x:
            v, fv, w, fw = w, fw, u, fu
        elif fu >= fv or v == x or v == w:
            v, fv = u, fu
    return a, fa, b, fb, x, fx, w, fw, v, fv


@jit
def find_event(y0, q, h, t0, M, contacts, near, n_near, suspect, kin, samples, values, rates, work):
    """Earliest θ in (0, 1] where a watched function of a near pair turns positive, or (1, False); of the near
    pairs, those the broad phase could not rule out (suspect).

    samples ((N_SAMPLES + 1, N) KINEMATICS) holds the berries at the step's sample points (the broad phase
    computed them); a sign change between samples gives a bracket at once. A maximum between samples that may
    reach zero is refined by Brent's method: for δ, whose rate each sample has, where the slopes turn from rising
    to falling and the tangents meet near zero (graze_possible); for φ, at a sampled local maximum close to zero.
    values and rates ((N_SAMPLES + 1, 2P)) are scratch."""
    tol = max(ROOT_TOL, 8 * 2.2e-16 * abs(t0))
    for k in range(N_SAMPLES + 1):
        at = samples[k]
        for kk in range(n_near):
            if not suspect[kk]:
                continue
            p = near[kk]
            pr, c = M.pair[p], contacts[p]
            delta, delta_dot, _, _, _ = contact_gap(M, pr, at)
            na, f1, s1, f2, s2 = watched(c.mode, pr.law, pr.clamp)
            values[k, 2 * kk] = event_value(f1, s1, pr, c, delta, delta_dot)
            rates[k, 2 * kk] = s1 * delta_dot * (h / N_SAMPLES)  # f1 is δ in every mode: its slope per sample spacing
            values[k, 2 * kk + 1] = event_value(f2, s2, pr, c, delta, delta_dot) if na == 2 else -1.0
    best = 2.0
    for kk in range(n_near):
        p = near[kk]
        pr, c = M.pair[p], contacts[p]
        if c.smooth or not suspect[kk]:
            continue
        na, f1, s1, f2, s2 = watched(c.mode, pr.law, pr.clamp)
        for a in range(na):
            fn = f1 if a == 0 else f2
            sg = s1 if a == 0 else s2
            col = 2 * kk + a
            if values[0, col] > 0.0:
                best = 0.0  # inconsistent start: switch at once, no advance
                continue
            for k in range(1, N_SAMPLES + 1):
                th_a = (k - 1) / N_SAMPLES
                if th_a >= best:
                    break
                if values[k, col] > 0.0:
                    root = locate_root(fn, sg, p, th_a, k / N_SAMPLES, y0, q, h, M, contacts, kin, work, tol)
                    best = min(best, root)
                    break
            for k in range(N_SAMPLES + 1):
                lo = max(k - 1, 0)
                if lo / N_SAMPLES >= best:
                    break
                if a == 0:  # δ: the sub-interval [k - 1, k], judged on its ends' values and slopes
                    hi = k
                    va, vb = values[lo, col], values[hi, col]
                    if k == 0 or va > 0.0 or vb > 0.0 or not graze_possible(va, vb, rates[lo, col], rates[hi, col]):
                        continue
                else:  # φ: around a sampled local maximum
                    hi = min(k + 1, N_SAMPLES)
                    v = values[k, col]
                    if v > 0.0 or v < values[lo, col] or v < values[hi, col]:
                        continue
                    if far_below(v, values[lo, col], values[hi, col]):
                        continue  # no graze here
                th_m, vm = largest_on(fn, sg, p, lo / N_SAMPLES, hi / N_SAMPLES, values[lo, col], values[hi, col],
                                      y0, q, h, M, contacts, kin, work, True)
                if vm > 0.0:
                    root = locate_root(fn, sg, p, lo / N_SAMPLES, th_m, y0, q, h, M, contacts, kin, work, tol)
                    best = min(best, root)
    if best <= 1.0:
        return best, True
    return 1.0, False


@jit
def switch_pair(p, new_mode, t, delta_dot, M, contacts, Bk, cfg, impacts, cursor):
    """Change a pair's mode: open or close its impact (a closed one goes to impacts at the recorder's
    cursor) and keep the Zeno guard."""
    c = contacts[p]
    old = c.mode
    if old == new_mode:
        return
    bp = Bk.pair[p]
    tot = Bk.totals[0]
    if old == 0:
        c.v_onset = max(delta_dot, HC_MIN_APPROACH_SPEED)
        open_impact(bp, tot, t, delta_dot)
    elif new_mode == 0:
        cur = cursor[0]
        row = impacts[cur.n_impacts]
        row.pair = p
        row.onset = bp.onset
        row.end = t
        row.approach_speed = bp.approach_speed
        row.peak_force = bp.impact_peak
        row.peak_time = bp.impact_peak_time
        row.impulse = bp.impulse - bp.impulse_at_onset
        row.dissipated = bp.dissipated - bp.dissipated_at_onset
        row.separation_speed = -delta_dot
        check_bruising(bp, tot, M, M.pair[p], cfg)
        row.bruising = bp.bruising
        cur.n_impacts += 1
    c.mode = new_mode
    Bk.counters[0].switches += 1
    if bp.smooth_until == np.inf:
        return  # a smooth law under step-size control: no events, so no Zeno guard either
    ring = Bk.ring
    kz = ring.shape[1]
    pos = bp.ring_pos
    ring[p, pos] = t
    pos = (pos + 1) % kz
    bp.ring_pos = pos
    if t - ring[p, pos] < cfg.zeno_window:
        c.smooth = True
        bp.smooth_until = t + cfg.zeno_window
        Bk.counters[0].zeno_guard_activations += 1


@inline
def open_impact(bp, tot, t, approach_speed):
    """A pair (bp, its BOOK_PAIR record) comes into contact at t: its impact starts and is counted."""
    bp.onset = t
    bp.approach_speed = approach_speed
    bp.impact_peak = 0.0
    bp.impact_peak_time = t
    bp.impulse_at_onset = bp.impulse
    bp.dissipated_at_onset = bp.dissipated
    bp.bruising = False
    tot.collision_count += 1


@inline
def check_bruising(bp, tot, M, pr, cfg):
    """Count an open impact (bp, its BOOK_PAIR record; pr its PAIR) as bruising the first time it reaches the
    thresholds of what it hits."""
    force, energy = bruise_thresholds(M, pr, cfg.bruise_force, cfg.bruise_energy)
    if not bp.bruising and bruising(bp.impact_peak, bp.dissipated - bp.dissipated_at_onset, force, energy):
        bp.bruising = True
        tot.bruising_impacts += 1


__all__ = ["ARGMAX_TOL", "EV_DELTA", "EV_FORCE", "EV_PHI", "N_SAMPLES", "ROOT_TOL", "classify", "find_event", "switch_pair",
           "value_at", "watched"]

"""The committed part of each step, sampled: peaks of contact force and pedicel tension (each refined around a
maximum between samples that could raise it), each near pair's mode class at every sample (for the Zeno
guard), and the per-pair impulse and dissipation integrals (Boole's rule, docs/model.md §6)."""
from __future__ import annotations

import numpy as np

from ..physics.compiled import inline, jit
from ..physics.damage import detaching
from ..physics.excitation import applied_accel, pull_bound
from ..physics.forces import active, berry_force, coupling, forces, pair_force, pedicel_tension
from ..physics.kinematics import Workspace, berry_kinematics, kinematics, pair_state, rachis_frame
from ..physics.layout import model_head, model_offsets
from .broadphase import travel
from .events import (ARGMAX_TOL, EV_FORCE, GOLDEN, N_SAMPLES, ROOT_TOL, brent_keep, brent_point, check_bruising,
                     classify, largest_on)
from .step import dense_berry, dense_head, dense_pair, dense_rachis

#: Boole's rule on the N_SAMPLES + 1 equally spaced samples: exact for quintics; its error per step,
#: O(h^7), stays below DOPRI5's local error O(h^6)
BOOLE = np.array([7.0, 32.0, 12.0, 32.0, 7.0]) / 90.0
#: Gauss–Legendre on N_SAMPLES + 1 nodes in [0, 1] (exact to degree 9, error O(h^11)), for a dense output of
#: higher degree than Boole's rule is exact for. DOP853's steps are 5..10 times longer than DOPRI5's: with
#: Boole's rule its booked dissipation missed the energy ledger by 1.6e-6..5.9e-9 (relative; the ledger's
#: dissipative case at rtol 1e-8..1e-11) where DOPRI5's misses by 1.5e-8..2.7e-10; on these nodes,
#: 6.3e-9..1.7e-11. It costs N_SAMPLES + 1 more force evaluations on a step with a pair in contact, which is why
#: DOPRI5 keeps Boole's rule on the samples the pass already has: Gauss nodes for both pairs were measured 3 % (paper
#: collision) to 7 % (shaken stiff pair, 230 impacts) slower at rtol 1e-6, for no accuracy a DOPRI5 step can use.
_NODES, _WEIGHTS = np.polynomial.legendre.leggauss(N_SAMPLES + 1)  # on [-1, 1]
GAUSS_X, GAUSS_W = 0.5 * (_NODES + 1.0), 0.5 * _WEIGHTS
#: a bracket whose bound exceeds a berry's peak tension by less than this fraction of it is not searched
#: (refine_tensions): the ripples of a berry hanging still are round-off
PEAK_GAIN = 1e-12


@jit
def pair_at(theta, p, y0, q, h, M, contacts, kin, work):
    """Pair p's force and dissipation power at θ on the step's dense output, from its own stage 1 alone (the
    numbers stage 2 gives it)."""
    pr = M.pair[p]
    dense_pair(theta, y0, q, h, work, M, pr)
    delta, delta_dot, _, _, _ = pair_state(work, M, pr, kin)
    return pair_force(pr, contacts[p], delta, delta_dot)


@jit
def integrate_gauss(h, theta_end, y0, q, M, contacts, near, nnear, book_pair, kin, work):
    """Book the active near pairs' impulse and dissipation over the step on the Gauss nodes."""
    span = theta_end * h
    for kk in range(nnear):
        p = near[kk]
        if not active(contacts[p]):
            continue
        fi = 0.0
        pi = 0.0
        for k in range(N_SAMPLES + 1):
            f, pw = pair_at(theta_end * GAUSS_X[k], p, y0, q, h, M, contacts, kin, work)
            fi += GAUSS_W[k] * f
            pi += GAUSS_W[k] * pw
        book_pair[p].impulse += span * fi
        book_pair[p].dissipated += span * pi


@jit
def sample_step(t0, h, theta_end, y0, q, M, X, inp, contacts, near, nnear, totals, book_pair, peak_tension, cfg, W,
                work, fbuf, pwbuf, cls, tbuf, pushing, samples, sampled, start_sampled, reach):
    """Book the step up to θ = theta_end.

    Every berry's pedicel tension is sampled at θ = k / N_SAMPLES inside the committed part (its end is the next
    step's first sample): on the berries the broad phase sampled there (`sampled`), else (a quiet step) on its own
    but at the step's ends, which the loop keeps in samples.
    The active pairs' forces, for the quadrature and the peak, are sampled on N_SAMPLES + 1 points of the committed
    part: on a whole step the same points, on a step an event cut short each pair on its own (pair_at), so a
    cluster's event step evaluates the pairs in contact and not every berry again.
    start_sampled: this step's start is the last step's end, sampled there in the same modes on the same near list
    (loop.integrate), so its tensions are booked and its pairs' row is that step's last: copied, not evaluated again
    (a fifth of the samples on a step that follows a whole one).
    Each berry's tensions at the samples stay in tbuf (N_SAMPLES + 1, N), for refine_tensions (pushing: its scratch).
    A step the broad phase did not sample, with no pair that can push, on which no berry's tension can pass its peak
    (tensions_bounded; reach: its scratch) is not sampled at all: nothing on it could raise a peak or an integral.
    Returns False when it left the step out (its rows hold nothing of it: the next step evaluates its start), else
    True."""
    tot = totals[0]
    berry, kin = M.berry, W.berry
    span = theta_end * h
    whole = theta_end == 1.0
    if whole and not sampled and tensions_bounded(t0, h, y0, q, M, X, inp, contacts, near, nnear, samples[0],
                                                  peak_tension, reach):
        return False
    if start_sampled:
        for kk in range(nnear):
            fbuf[0, kk], pwbuf[0, kk], cls[0, kk] = fbuf[N_SAMPLES, kk], pwbuf[N_SAMPLES, kk], cls[N_SAMPLES, kk]
        for i in range(berry.shape[0]):
            tbuf[0, i] = tbuf[N_SAMPLES, i]
    last = 0  # the last sample taken
    for k in range(1 if start_sampled else 0, N_SAMPLES + 1):
        th = k / N_SAMPLES
        if not whole and k > 0 and th >= theta_end:
            break
        acc = applied_accel(X, inp, t0 + th * h, t0)
        given = sampled or k == 0 or k == N_SAMPLES  # the loop keeps a step's ends in samples
        if given:
            at = samples[k]
            dense_rachis(th, y0, q, h, work, M)
            fr = rachis_frame(work, M)
            Wk = Workspace(at, W.torque, W.pair, W.coupling_power)
        else:
            at = kin
            dense_head(th, y0, q, h, work, model_head(M))
            fr = kinematics(work, M, at)
            Wk = W
        forces(acc, fr, contacts, M, Wk, near, nnear)
        if whole:
            for kk in range(nnear):
                p = near[kk]
                fbuf[k, kk] = W.pair[kk].force
                pwbuf[k, kk] = W.pair[kk].power
                if contacts[p].smooth:
                    if given:
                        dense_pair(th, y0, q, h, work, M, M.pair[p])
                    cls[k, kk] = classify(p, work, M, contacts, at, contacts[p].mode)[0]
        for i in range(berry.shape[0]):
            tbuf[k, i] = pedicel_tension(berry[i], at[i])
            book_tension(i, tbuf[k, i], peak_tension, tot, cfg)
        last = k
    if not whole:
        for kk in range(nnear):
            p = near[kk]
            if not active(contacts[p]):
                continue  # its force is zero: neither booked nor searched
            for k in range(N_SAMPLES + 1):
                fbuf[k, kk], pwbuf[k, kk] = pair_at(theta_end * k / N_SAMPLES, p, y0, q, h, M, contacts, kin, work)
                if contacts[p].smooth:
                    cls[k, kk] = classify(p, work, M, contacts, kin, contacts[p].mode)[0]
    gauss = q.shape[1] > 5  # a dense output of higher degree than Boole's rule is exact for
    if gauss:
        integrate_gauss(h, theta_end, y0, q, M, contacts, near, nnear, book_pair, kin, work)
    for kk in range(nnear):
        p = near[kk]
        c = contacts[p]
        if not active(c):
            continue
        bp = book_pair[p]
        if not gauss:
            fi = 0.0
            pi = 0.0
            for k in range(N_SAMPLES + 1):
                fi += BOOLE[k] * fbuf[k, kk]
                pi += BOOLE[k] * pwbuf[k, kk]
            bp.impulse += span * fi
            bp.dissipated += span * pi
        kbest = 0
        kmin = 0
        for k in range(1, N_SAMPLES + 1):
            if fbuf[k, kk] > fbuf[kbest, kk]:
                kbest = k
            if fbuf[k, kk] < fbuf[kmin, kk]:
                kmin = k
        fbest = fbuf[kbest, kk]
        tbest = theta_end * kbest / N_SAMPLES
        # Whether this step can raise the impact's peak is judged on an upper bound of its maximum, not on
        # its best sample: the maximum exceeds the best sample by at most a quarter of the samples' spread
        # (a parabola between samples; far less at a step end). A peak just after a step boundary is first
        # booked as the previous step's end value, and this step's first sample, the same point on another
        # dense output, can come out an ulp below it: compared with the booked peak, it skipped the search.
        if fbest > 0.0 and 2.0 * fbest - fbuf[kmin, kk] >= bp.impact_peak:
            turning = 0 < kbest < N_SAMPLES
            if not turning:
                # a maximum at a step end is a peak only if the force turns inside the step there, which a
                # probe eps inside the end tells, corrected for the curvature (the samples' second difference
                # d2 at that end): along u -> fm - c (u - um)^2, u inward in sample spacings, the probe at
                # eps' = eps N_SAMPLES rises by c eps' (2 um - eps') with d2 = -2 c. Against 0, a vertex
                # within eps'/2 of the end (um < eps'/2) was missed; against d2 eps'^2, any vertex inside
                # the step (um > 0) is found, and one up to eps'/2 outside costs a search that returns the end.
                eps = 1e-3 / N_SAMPLES
                if kbest == N_SAMPLES:
                    th_in = theta_end * (1.0 - eps)
                    d2 = fbuf[N_SAMPLES, kk] - 2.0 * fbuf[N_SAMPLES - 1, kk] + fbuf[N_SAMPLES - 2, kk]
                else:
                    th_in = theta_end * eps
                    d2 = fbuf[0, kk] - 2.0 * fbuf[1, kk] + fbuf[2, kk]
                rise = pair_at(th_in, p, y0, q, h, M, contacts, kin, work)[0] - fbest
                turning = rise > min(d2, 0.0) * (eps * N_SAMPLES) ** 2
            if turning:
                # the maximum between the neighbouring samples, by the graze search's maximiser (one-sided at the
                # step's ends, where the peak may sit just inside this step)
                lo, hi = max(kbest - 1, 0), min(kbest + 1, N_SAMPLES)
                tm, fm = largest_on(EV_FORCE, 1.0, p, theta_end * lo / N_SAMPLES, theta_end * hi / N_SAMPLES,
                                    fbuf[lo, kk], fbuf[hi, kk], y0, q, h, M, contacts, kin, work, False)
                if fm > fbest:
                    fbest, tbest = fm, tm
        if fbest > bp.peak_force:
            bp.peak_force = fbest
            if fbest > tot.peak_contact_force:
                tot.peak_contact_force = fbest
        if fbest > bp.impact_peak:
            bp.impact_peak = fbest
            bp.impact_peak_time = t0 + tbest * h
        if c.mode != 0:
            check_bruising(bp, tot, M, M.pair[p], cfg)
    refine_tensions(t0, h, theta_end, last, y0, q, M, X, inp, contacts, near, nnear, tbuf, pushing, peak_tension, tot,
                    cfg, kin, work)
    return True


@inline
def tensions_bounded(t0, h, y0, q, M, X, inp, contacts, near, nnear, kin, peak_tension, reach):
    """Whether no berry's pedicel tension can pass its booked peak anywhere on the step's dense output (docs/solver.md,
    "Peaks"): T = m l |u̇|² + F·u ≤ m l ω² + |F| with ω a bound on |u̇| (u is 1-Lipschitz in s and in t, so
    |u̇| ≤ |ṡ| + |ṫ|, each bounded by its start value and broadphase.travel), where F is the pull of gravity and the
    rachis (excitation.pull_bound) and the couplings' springs and dampers, each bounded by its value at the start
    (kin: stage 1 there) and how far its berries get; a rachis turned but not spinning pulls with the same |a + g ẑ|
    (rotation keeps lengths). Contact and the fields of a spinning rachis (Euler, centrifugal, Coriolis) are not
    bounded: a near pair that can push, or ω or α other than zero on the step, answers False. reach ((N, 3)
    scratch): each berry's twig-end travel, its ω and its bound on |F|.
    Why: a quiet step's inner samples evaluate every berry three times to book peaks that, once a berry has swung
    harder before, they cannot raise (paper collision: a fifth of the loop's time, benchmarks/loop_sections.py)."""
    if M.turning:  # ω ≡ 0 on the step: zero at its start and no travel (α = 0: pull_bound)
        o_om = model_offsets(M)[2]
        for r in range(o_om, o_om + 3):
            if y0[r] != 0.0 or travel(q, h, r) != 0.0:
                return False
    for kk in range(nnear):
        if active(contacts[near[kk]]):
            return False
    pull = pull_bound(X, inp, t0, t0 + h, M.gravity)
    if not pull < np.inf:
        return False
    berry, nd = M.berry, M.n_dof
    for i in range(berry.shape[0]):
        b = berry[i]
        o = b.dof
        moved = travel(q, h, o)
        rate = abs(y0[nd + o]) + travel(q, h, nd + o)
        if b.n_angles == 2:
            moved += travel(q, h, o + 1)
            rate += abs(y0[nd + o + 1]) + travel(q, h, nd + o + 1)
        reach[i, 0] = b.twig_length * moved
        reach[i, 1] = rate
        reach[i, 2] = b.mass * pull
    for k in range(M.coupling.shape[0]):
        cp = M.coupling[k]
        i, j = cp.i, cp.j
        _, sep, _ = coupling(cp, berry[i], berry[j], kin[i], kin[j])
        f = abs(cp.stiffness) * (abs(sep) + reach[i, 0] + reach[j, 0]) + abs(cp.damping) * (
            berry[i].twig_length * reach[i, 1] + berry[j].twig_length * reach[j, 1])
        reach[i, 2] += f
        reach[j, 2] += f
    for i in range(berry.shape[0]):
        b = berry[i]
        if b.mass * b.twig_length * reach[i, 1] ** 2 + reach[i, 2] > peak_tension[i]:
            return False
    return True


@inline
def book_tension(i, tension, peak_tension, tot, cfg):
    """Berry i's pedicel tension at a point of the step: its peak and the run's raised, a berry that passes the
    detachment force counted once."""
    if tension > peak_tension[i]:
        if detaching(tension, cfg.detachment_force) and not detaching(peak_tension[i], cfg.detachment_force):
            tot.berries_over_detachment_force += 1
        peak_tension[i] = tension
        if tension > tot.peak_pedicel_tension:
            tot.peak_pedicel_tension = tension


@inline
def refine_tensions(t0, h, theta_end, last, y0, q, M, X, inp, contacts, near, nnear, tbuf, pushing, peak_tension, tot,
                    cfg, kin, work):
    """Each berry's largest pedicel tension between its samples, where it could raise the berry's peak (docs/solver.md,
    "Peaks"), as for a contact force's peak. The points are the samples θ_j = j/N_SAMPLES (j ≤ last) and, on a step an
    event cut short, the committed part's end θ_e (its tension taken here when needed; the next step's first sample
    books it). The largest point's neighbours bracket the maximum, and 2·largest − the lower neighbour bounds what the
    bracket can hold; a largest point at an end is a maximum only if the tension turns just inside it (a probe, where
    the samples say it may: turns_near).
    Why: the samples alone missed a peak between them by up to a quarter of the spacing's curvature, so the booked
    peak did not converge with the tolerance (1.9e-3 relative at rtol 1e-8 on a 100-berry cluster, whose DOP853 steps
    are long: benchmarks/peak_tension.py). The evaluations are a berry's and its neighbours' (tension_at), over the
    pairs in contact (`pushing`, scratch (P,)), not every near pair."""
    npush = 0
    for kk in range(nnear):
        if active(contacts[near[kk]]):
            pushing[npush] = near[kk]
            npush += 1
    whole = theta_end == 1.0
    m = last if whole else last + 1  # the committed part's end point
    th_m = 1.0 if whole else theta_end
    for i in range(M.berry.shape[0]):
        kb = 0
        for k in range(1, last + 1):
            if tbuf[k, i] > tbuf[kb, i]:
                kb = k
        best = tbuf[kb, i]
        t_m = tbuf[last, i]
        if not whole and kb == last:  # the committed part runs on for less than a spacing past the last sample
            if last >= 2 and not turns_near(tbuf[last, i], tbuf[last - 1, i], tbuf[last - 2, i]):
                continue  # rising for a spacing more, past θ_e: the next step's first sample is the largest
            if last >= 1 and not best + 2.0 * (best - tbuf[last - 1, i]) - peak_tension[i] > \
                    PEAK_GAIN * abs(peak_tension[i]):
                continue  # twice the last spacing's rise again does not reach the peak
            t_m = tension_at(theta_end, i, t0, y0, q, h, M, X, inp, contacts, pushing, npush, kin, work)
            if t_m > best:
                kb, best = m, t_m
        if 0 < kb < m:
            a, b = (kb - 1) / N_SAMPLES, (th_m if kb + 1 == m else (kb + 1) / N_SAMPLES)
            low = min(tbuf[kb - 1, i], t_m if kb + 1 == m else tbuf[kb + 1, i])
        elif kb == 0:
            a, b = 0.0, (th_m if m == 1 else 1.0 / N_SAMPLES)
            low = t_m if m == 1 else tbuf[1, i]
        else:
            a, b = (m - 1) / N_SAMPLES, th_m
            low = tbuf[m - 1, i]
        if not 2.0 * best - low - peak_tension[i] > PEAK_GAIN * abs(peak_tension[i]):
            continue  # the bracket cannot hold more than the peak (a berry hanging still samples ripples of 1e-16)
        if kb == 0 or kb == m:  # at an end: a maximum only if the tension turns just inside it
            if whole and not (turns_near(tbuf[0, i], tbuf[1, i], tbuf[2, i]) if kb == 0 else
                              turns_near(tbuf[m, i], tbuf[m - 1, i], tbuf[m - 2, i])):
                continue
            probe = a + 1e-3 * (b - a) if kb == 0 else b - 1e-3 * (b - a)
            if tension_at(probe, i, t0, y0, q, h, M, X, inp, contacts, pushing, npush, kin, work) <= best:
                continue
        book_tension(i, largest_tension(i, a, b, t0, y0, q, h, M, X, inp, contacts, pushing, npush, kin, work),
                     peak_tension, tot, cfg)


@inline
def turns_near(t_end, t_1, t_2):
    """Whether a function sampled t_end at a step's end and t_1, t_2 one and two spacings inside, largest at the end, may
    turn inside the end's interval: the parabola through the three is concave and its vertex lies less than a spacing
    beyond the end (its slope there, in spacings, above −curvature; a spacing's room for what the parabola leaves
    out). Else the tension rises into the end (or falls from it) for a spacing more, which the next step (or the last)
    samples: no probe. A steady rise, the common case on a lift, is judged without an evaluation."""
    d2 = t_end - 2.0 * t_1 + t_2
    if d2 >= 0.0:
        return False
    return (3.0 * t_end - 4.0 * t_1 + t_2) / 2.0 < -d2


@jit
def largest_tension(i, a, b, t0, y0, q, h, M, X, inp, contacts, near, nnear, kin, work):
    """Berry i's largest pedicel tension on [a, b] (θ units) by Brent's maximiser, as events.largest_on."""
    tol = max(ROOT_TOL / h, ARGMAX_TOL)
    x = w = v = a + GOLDEN * (b - a)
    fx = tension_at(x, i, t0, y0, q, h, M, X, inp, contacts, near, nnear, kin, work)
    fw = fv = fx
    fa = fb = d = e = 0.0
    for _ in range(60):
        done, u, d, e = brent_point(a, b, x, w, v, fx, fw, fv, d, e, tol)
        if done:
            break
        fu = tension_at(u, i, t0, y0, q, h, M, X, inp, contacts, near, nnear, kin, work)
        a, fa, b, fb, x, fx, w, fw, v, fv = brent_keep(u, fu, a, fa, b, fb, x, fx, w, fw, v, fv)
    return fx


@jit
def tension_at(theta, i, t0, y0, q, h, M, X, inp, contacts, near, nnear, kin, work):
    """Berry i's pedicel tension at θ on the step's dense output: stage 1 of berry i and of the berries that push it
    (its couplings, its pairs in contact among the first nnear of `near`), then its F (forces.berry_force), which is
    the number a sample there gives it, for the cost of one berry and its neighbours."""
    dense_rachis(theta, y0, q, h, work, M)
    fr = rachis_frame(work, M)
    berry_at(theta, i, y0, q, h, M, kin, work, fr)
    for k in range(M.coupling.shape[0]):
        cp = M.coupling[k]
        if cp.i == i or cp.j == i:
            berry_at(theta, cp.j if cp.i == i else cp.i, y0, q, h, M, kin, work, fr)
    for kk in range(nnear):
        p = near[kk]
        pr = M.pair[p]
        if (pr.i == i or pr.j == i) and active(contacts[p]):
            j = pr.j if pr.i == i else pr.i
            if j < M.berry.shape[0]:
                berry_at(theta, j, y0, q, h, M, kin, work, fr)
    berry_force(i, applied_accel(X, inp, t0 + theta * h, t0), fr, contacts, M, kin, near, nnear)
    return pedicel_tension(M.berry[i], kin[i])


@inline
def berry_at(theta, i, y0, q, h, M, kin, work, fr):
    """Stage 1 of berry i at θ on the dense output into kin[i] (the rachis frame fr there)."""
    dense_berry(theta, y0, q, h, work, M, i)
    b, o, nd = M.berry[i], M.berry[i].dof, M.n_dof
    berry_kinematics(b, kin[i], work[o], work[nd + o], work[o + 1], work[nd + o + 1], fr)

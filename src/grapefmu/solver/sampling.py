"""The committed part of each step, sampled: peaks of contact force and pedicel tension (the force
refined around an interior maximum), each near pair's mode class at every sample (for the Zeno
guard), and the per-pair impulse and dissipation integrals (Boole's rule, docs/model.md §6)."""
from __future__ import annotations

import numpy as np

from ..physics.compiled import jit
from ..physics.damage import detaching
from ..physics.excitation import applied_accel
from ..physics.forces import active, forces, pair_force, pedicel_tension
from ..physics.kinematics import kinematics, pair_state
from ..physics.layout import model_head
from .events import N_SAMPLES, check_bruising, classify
from .step import dense_head

#: Boole's rule on the N_SAMPLES + 1 equally spaced samples: exact for quintics like the step's dense output
BOOLE = np.array([7.0, 32.0, 12.0, 32.0, 7.0]) / 90.0
GOLDEN = 0.6180339887498949


@jit
def force_at(theta, p, y0, q, h, M, contacts, kin, work):
    """Pair p's force at θ on the step's dense output."""
    dense_head(theta, y0, q, h, work, model_head(M))
    pr = M.pair[p]
    delta, delta_dot, _, _, _ = pair_state(work, M, pr, kin)
    return pair_force(pr, contacts[p], delta, delta_dot)[0]


@jit
def sample_step(t0, h, theta_end, y0, q, M, X, inp, contacts, near, nnear, totals, book_pair, peak_tension, cfg, W,
                work, fbuf, pwbuf, cls):
    tot = totals[0]
    berry, kin = M.berry, W.berry
    for k in range(N_SAMPLES + 1):
        th = theta_end * k / N_SAMPLES
        dense_head(th, y0, q, h, work, model_head(M))
        acc = applied_accel(X, inp, t0 + th * h, t0)
        fr = kinematics(work, M, kin)
        forces(acc, fr, contacts, M, W, near, nnear)
        for kk in range(nnear):
            p = near[kk]
            fbuf[k, kk] = W.pair[kk].force
            pwbuf[k, kk] = W.pair[kk].power
            if contacts[p].smooth:
                cls[k, kk] = classify(p, work, M, contacts, kin, contacts[p].mode)[0]
        for i in range(berry.shape[0]):
            tension = pedicel_tension(berry[i], kin[i])
            if tension > peak_tension[i]:
                if detaching(tension, cfg.detachment_force) and not detaching(peak_tension[i], cfg.detachment_force):
                    tot.berries_over_detachment_force += 1
                peak_tension[i] = tension
                if tension > tot.peak_pedicel_tension:
                    tot.peak_pedicel_tension = tension
    span = theta_end * h
    for kk in range(nnear):
        p = near[kk]
        c = contacts[p]
        if not active(c):
            continue
        bp = book_pair[p]
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
                rise = force_at(th_in, p, y0, q, h, M, contacts, kin, work) - fbest
                turning = rise > min(d2, 0.0) * (eps * N_SAMPLES) ** 2
            if turning:
                # golden-section search between the neighbouring samples (one-sided at the step's ends,
                # where the peak may sit just inside this step)
                a = theta_end * max(kbest - 1, 0) / N_SAMPLES
                b = theta_end * min(kbest + 1, N_SAMPLES) / N_SAMPLES
                c1 = b - GOLDEN * (b - a)
                c2 = a + GOLDEN * (b - a)
                f1 = force_at(c1, p, y0, q, h, M, contacts, kin, work)
                f2 = force_at(c2, p, y0, q, h, M, contacts, kin, work)
                for _ in range(40):  # one new point a round: the kept one is the next round's other point
                    if f1 > f2:
                        b, c2, f2 = c2, c1, f1
                        c1 = b - GOLDEN * (b - a)
                        f1 = force_at(c1, p, y0, q, h, M, contacts, kin, work)
                    else:
                        a, c1, f1 = c1, c2, f2
                        c2 = a + GOLDEN * (b - a)
                        f2 = force_at(c2, p, y0, q, h, M, contacts, kin, work)
                    if (b - a) * h < 1e-12:
                        break
                tm = 0.5 * (a + b)
                fm = force_at(tm, p, y0, q, h, M, contacts, kin, work)
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

"""The committed part of each step, sampled: peaks of contact force and pedicel tension (the force
refined around an interior maximum), each near pair's mode class at every sample (for the Zeno
guard), and the per-pair impulse and dissipation integrals (Boole's rule, docs/model.md §6)."""
from __future__ import annotations

import numpy as np

from ..physics.compiled import jit
from ..physics.damage import detaching
from ..physics.excitation import applied_accel
from ..physics.forces import active, forces, pair_force, pedicel_tension
from ..physics.kinematics import Workspace, kinematics, pair_state, rachis_frame
from ..physics.layout import model_head
from .events import EV_FORCE, N_SAMPLES, check_bruising, classify, largest_on
from .step import dense_head, dense_pair, dense_rachis

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
                work, fbuf, pwbuf, cls, samples, sampled, start_sampled):
    """Book the step up to θ = theta_end.

    Every berry's pedicel tension is sampled at θ = k / N_SAMPLES inside the committed part (its end is the next
    step's first sample): on the berries the broad phase sampled there (`sampled`), else (a quiet step) on its own
    but at the step's ends, which the loop keeps in samples.
    The active pairs' forces, for the quadrature and the peak, are sampled on N_SAMPLES + 1 points of the committed
    part: on a whole step the same points, on a step an event cut short each pair on its own (pair_at), so a
    cluster's event step evaluates the pairs in contact and not every berry again.
    start_sampled: this step's start is the last step's end, sampled there in the same modes on the same near list
    (loop.integrate), so its tensions are booked and its pairs' row is that step's last: copied, not evaluated again
    (a fifth of the samples on a step that follows a whole one)."""
    tot = totals[0]
    berry, kin = M.berry, W.berry
    span = theta_end * h
    whole = theta_end == 1.0
    if start_sampled:
        for kk in range(nnear):
            fbuf[0, kk], pwbuf[0, kk], cls[0, kk] = fbuf[N_SAMPLES, kk], pwbuf[N_SAMPLES, kk], cls[N_SAMPLES, kk]
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
            tension = pedicel_tension(berry[i], at[i])
            if tension > peak_tension[i]:
                if detaching(tension, cfg.detachment_force) and not detaching(peak_tension[i], cfg.detachment_force):
                    tot.berries_over_detachment_force += 1
                peak_tension[i] = tension
                if tension > tot.peak_pedicel_tension:
                    tot.peak_pedicel_tension = tension
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

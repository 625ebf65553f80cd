"""How far each berry drifts from the path its window started on (solver/islands.py, docs/solver.md "Islands").

At a window's start each angle's path is extrapolated, q̂(τ) = q₀ + q̇₀ τ + ½ q̈₀ τ²; the berries' positions on that
path are known before the window runs (`predict`), and every accepted step bounds how far the angles got from it
(`drift`, on the step's dense output). A berry then stays within l (Δs + Δt) of its predicted position (u is
1-Lipschitz in s and in t), so two berries of different islands provably did not meet if their predicted positions
stay farther apart than their radii and those bounds: a bound on the difference from a shared swing, where a bound
on each berry's travel would grow with the swing itself.
"""
from __future__ import annotations

import math

import numpy as np

from ..physics.compiled import inline, jit
from ..physics.kinematics import kinematics
from .broadphase import bernstein


@inline
def off_path(q, h, r, e0, c1, c2):
    """max over θ in [0, 1] of |e0 + h Σ_j Q[r, j] θ^(j+1) − c1 θ − c2 θ²|, by the polynomial's Bernstein coefficients
    (those of θ and θ² are i/n and i(i − 1)/(n(n − 1)); broadphase.travel is the case e0 = c1 = c2 = 0): the step's
    dense output of angle r, less the path."""
    n = q.shape[1]
    worst = abs(e0)
    for i in range(1, n + 1):
        worst = max(worst, abs(e0 + h * bernstein(q, r, i) - c1 * i / n - c2 * i * (i - 1) / (n * (n - 1))))
    return worst


@jit
def anchor(y, f, t, M, path, drifted):
    """Start a window at t: path ((D + 1, 3)) gets each angle's q₀, q̇₀, q̈₀ (y and its derivative f: the path
    `predict` places the berries on) and, in its last row, t; drifted ((N,)) is zeroed."""
    nd = M.n_dof
    for r in range(nd):
        path[r, 0], path[r, 1], path[r, 2] = y[r], y[nd + r], f[nd + r]
    path[nd, 0] = t
    drifted[:] = 0.0


@jit
def drift(y0, q, h, t0, M, path, drifted):
    """After a step from (t0, y0) with dense coefficients q: drifted[i] becomes at least berry i's largest distance
    from its predicted position on the step, l (max |s − ŝ| + max |t − t̂|)."""
    nd = M.n_dof
    tau = t0 - path[nd, 0]
    for i in range(M.berry.shape[0]):
        b = M.berry[i]
        d = 0.0
        for r in range(b.dof, b.dof + b.n_angles):
            q0, v0, a0 = path[r, 0], path[r, 1], path[r, 2]
            e0 = y0[r] - (q0 + v0 * tau + 0.5 * a0 * tau * tau)
            d += off_path(q, h, r, e0, h * (v0 + a0 * tau), 0.5 * a0 * h * h)
        drifted[i] = max(drifted[i], b.twig_length * d)


@jit
def predict(y, f, M, span, work, kin, lin, reach, rows):
    """The berries' rachis-frame positions on the path a window starting at (y, its derivative f) anchors, at K
    equally spaced times over its length span (lin, (K, ·, 3), berry i's in lin[:, rows[i]]), and for each berry
    bounds on the path's speed and curvature there (reach[rows[i]]: l Σ (|q̇₀| + |q̈₀| span) and
    l ((Σ (|q̇₀| + |q̈₀| span))² + Σ |q̈₀|), u's first and second derivatives being at most 1 in each angle)."""
    nd = M.n_dof
    K = lin.shape[0]
    work[:] = y
    for k in range(K):
        tau = span * k / (K - 1)
        for r in range(nd):
            work[r] = y[r] + y[nd + r] * tau + 0.5 * f[nd + r] * tau * tau
        kinematics(work, M, kin)
        for i in range(kin.shape[0]):
            lin[k, rows[i], 0], lin[k, rows[i], 1], lin[k, rows[i], 2] = kin[i].px, kin[i].py, kin[i].pz
    for i in range(M.berry.shape[0]):
        b = M.berry[i]
        v = 0.0
        a = 0.0
        for r in range(b.dof, b.dof + b.n_angles):
            v += abs(y[nd + r]) + abs(f[nd + r]) * span
            a += abs(f[nd + r])
        reach[rows[i], 0] = b.twig_length * v
        reach[rows[i], 1] = b.twig_length * (v * v + a)


@jit
def slack(lin, reach, drifted, radius, pair_i, pair_j, span, far, out):
    """For each berry-berry pair (pair_i, pair_j), a lower bound on its gap over a window of length span into out:
    the least distance of the chords between the predicted positions (lin), less the paths' sag from their chords
    (Δτ²/8 × the curvature bounds in reach), less both berries' drift and radii. A pair still farther apart than
    `far` with both berries at their paths' speed bounds gets that cheaper bound."""
    K = lin.shape[0]
    dt = span / (K - 1)
    for p in range(pair_i.shape[0]):
        i, j = pair_i[p], pair_j[p]
        margin = drifted[i] + drifted[j] + radius[i] + radius[j]
        cx = lin[0, j, 0] - lin[0, i, 0]
        cy = lin[0, j, 1] - lin[0, i, 1]
        cz = lin[0, j, 2] - lin[0, i, 2]
        bound = math.sqrt(cx * cx + cy * cy + cz * cz) - span * (reach[i, 0] + reach[j, 0]) - margin
        if bound >= far:
            out[p] = bound
            continue
        near = np.inf
        for k in range(K - 1):
            ax, ay, az = cx, cy, cz
            cx = lin[k + 1, j, 0] - lin[k + 1, i, 0]
            cy = lin[k + 1, j, 1] - lin[k + 1, i, 1]
            cz = lin[k + 1, j, 2] - lin[k + 1, i, 2]
            dx, dy, dz = cx - ax, cy - ay, cz - az
            dd = dx * dx + dy * dy + dz * dz
            u = 0.0 if dd == 0.0 else min(1.0, max(0.0, -(ax * dx + ay * dy + az * dz) / dd))
            ax, ay, az = ax + u * dx, ay + u * dy, az + u * dz
            near = min(near, math.sqrt(ax * ax + ay * ay + az * az))
        out[p] = near - dt * dt / 8.0 * (reach[i, 1] + reach[j, 1]) - margin


@jit
def components(n, a, b, label):
    """Connected components of n nodes joined by the edges (a[e], b[e]) into label (0, 1, … in order of each
    component's first node); returns how many."""
    root = np.arange(n)
    for e in range(a.shape[0]):
        x, y = a[e], b[e]
        while root[x] != x:
            root[x] = root[root[x]]
            x = root[x]
        while root[y] != y:
            root[y] = root[root[y]]
            y = root[y]
        if x != y:
            root[max(x, y)] = min(x, y)
    count = 0
    for v in range(n):
        r = v
        while root[r] != r:
            r = root[r]
        if r == v:
            label[v] = count
            count += 1
        else:
            label[v] = label[r]
    return count


@jit
def joined(n, engaged, pair_index, slack, label, pair_i, pair_j, coupled, join, stay, out):
    """Each of n berries' group for the next window into out (components' labels): berries joined by a pair engaged
    (in contact or in a Zeno window), a coupling, or a pair whose slack is below join; a pair of one island now (label)
    stays joined while its slack is below stay. slack: per berry-berry pair (pair_i, pair_j, the scene's pair
    pair_index, whose engaged flag it reads)."""
    a = np.empty(pair_i.shape[0] + coupled.shape[0], np.int64)
    b = np.empty_like(a)
    m = 0
    for p in range(pair_i.shape[0]):
        i, j = pair_i[p], pair_j[p]
        if engaged[pair_index[p]] or slack[p] < join or (label[i] == label[j] and slack[p] < stay):
            a[m], b[m] = i, j
            m += 1
    for c in range(coupled.shape[0]):
        a[m], b[m] = coupled[c, 0], coupled[c, 1]
        m += 1
    return components(n, a[:m], b[:m], out)


@jit
def regrouped(group, label, n_islands):
    """The islands (0 … n_islands - 1; label: each berry's) whose berries group otherwise for the next window (group:
    each berry's, from `joined`), ascending, and the groups their berries form, ascending: the islands to retire and
    those to form. An island is kept where its berries make one group and no other berry joins it."""
    n_groups = 0
    for i in range(group.shape[0]):
        n_groups = max(n_groups, group[i] + 1)
    first = np.full(n_islands, -1, np.int64)  # each island's group, where its berries make one
    split = np.zeros(n_islands, np.bool_)
    size = np.zeros(n_islands, np.int64)
    group_size = np.zeros(n_groups, np.int64)
    for i in range(group.shape[0]):
        k, g = label[i], group[i]
        size[k] += 1
        group_size[g] += 1
        if first[k] < 0:
            first[k] = g
        elif first[k] != g:
            split[k] = True
    leaving = np.zeros(n_islands, np.bool_)
    for k in range(n_islands):
        leaving[k] = split[k] or group_size[first[k]] != size[k]
    forming = np.zeros(n_groups, np.bool_)
    for i in range(group.shape[0]):
        if leaving[label[i]]:
            forming[group[i]] = True
    return np.flatnonzero(leaving), np.flatnonzero(forming)

"""Split a scene into groups of berries that can never interact, and run each group on its own.

Two berries interact only through a candidate contact pair or a coupling (an obstacle is fixed in the
world, so touching the same one links no berries: each group keeps every obstacle). Berries that cannot
reach each other form independent systems, so each group gets its own step sizes: a stiff contact
in one group never shortens the steps of another, a berry with no possible contact runs the pure
pendulum model, and each group's results are exactly those of the group simulated alone.
"""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace

import numpy as np

from ..model.model import ContactPair, Coupling, Model, Scene
from ..errors import SolverError
from ..physics.forces import CONTACT
from ..physics.layout import layout_of
from ..results.contacts import CHANGE, ContactLog
from ..results.impacts import Impacts
from ..results.records import COUNTS, PEAKS, TOTALS, WORK, concat
from ..results.run import Run


def groups(model: Model) -> list[list[int]]:
    """Connected components of the interaction graph (berry indices, each group ascending)."""
    parent = list(range(model.n_berries))

    def root(i: int) -> int:
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    for link in (*model.pairs, *model.couplings):
        if link.j >= model.n_berries:
            continue  # a berry and an obstacle
        a, b = root(link.i), root(link.j)
        if a != b:
            parent[max(a, b)] = min(a, b)
    out: dict[int, list[int]] = {}
    for i in range(model.n_berries):
        out.setdefault(root(i), []).append(i)
    return list(out.values())


def sub_scene(scene: Scene, members: list[int]) -> Scene:
    """The scene restricted to some berries (the pairs and couplings among them and with obstacles, renumbered)."""
    m = scene.model
    new = {old: k for k, old in enumerate(members)}
    new.update({m.n_berries + k: len(members) + k for k in range(len(m.obstacles))})  # obstacles follow the berries
    pairs = tuple(ContactPair(new[p.i], new[p.j], p.law) for p in m.pairs if p.i in new and p.j in new)
    couplings = tuple(Coupling(new[c.i], new[c.j], c.stiffness, c.damping) for c in m.couplings
                      if c.i in new and c.j in new)
    dof = m.dof
    idx = [k for i in members for k in range(dof[i], dof[i + 1])]
    model = Model(tuple(m.berries[i] for i in members), pairs, couplings, m.gravity, obstacles=m.obstacles)
    return replace(scene, model=model, angles=tuple(scene.angles[k] for k in idx),
                   angular_velocities=tuple(scene.angular_velocities[k] for k in idx))


def run_by_group(scene: Scene, simulate_one: Callable[[Scene, float, float], Run]) -> Run:
    """simulate_one(sub_scene, done, share) on each group, merged into one Run of the whole scene;
    done and share place the group's progress within the whole run's (fractions of the work)."""
    parts = groups(scene.model)
    if len(parts) == 1:
        return simulate_one(scene, 0.0, 1.0)
    total = scene.model.n_berries
    runs, done = [], 0
    for members in parts:
        runs.append(simulate_one(sub_scene(scene, members), done / total, len(members) / total))
        done += len(members)
    return merge(scene, parts, runs)


def merge(scene: Scene, parts: list[list[int]], runs: list[Run]) -> Run:
    """One Run of the whole scene from the runs of its groups (all sampled on the same grid)."""
    m = scene.model
    lay = layout_of(scene)
    t = runs[0].t
    n, npair = len(t), len(m.pairs)
    y = np.zeros((n, lay.size))
    start, changes = np.zeros(npair, dtype=CONTACT), []
    totals = np.zeros(n, dtype=TOTALS)
    totals["peak_pedicel_tension"] = -np.inf
    peak_force, peak_tension = np.zeros(npair), np.zeros(m.n_berries)
    pair_index = {(p.i, p.j): k for k, p in enumerate(m.pairs)}
    coup_index = {(c.i, c.j): k for k, c in enumerate(m.couplings)}
    dof = m.dof
    finished, ongoing = [], []
    for members, run in zip(parts, runs):
        if len(run.t) != n or not np.array_equal(run.t, t):
            raise SolverError("groups were sampled on different grids")  # same scene settings: cannot happen
        sl = run.layout
        idx = np.array([k for i in members for k in range(dof[i], dof[i + 1])], dtype=int)
        y[:, lay.q.start + idx] = run.y[:, sl.q]
        y[:, lay.w.start + idx] = run.y[:, sl.w]
        y[:, lay.d_hinge.start + np.array(members)] = run.y[:, sl.d_hinge]
        for k, c in enumerate(run.scene.model.couplings):
            y[:, lay.d_coupling.start + coup_index[(members[c.i], members[c.j])]] = run.y[:, sl.d_coupling.start + k]
        y[:, lay.d_contact] += run.y[:, sl.d_contact]
        y[:, lay.work] += run.y[:, sl.work]
        blocks = ("base_velocity", "base", "base_angular_velocity", "base_orientation")
        for block in blocks[: 4 if lay.turning else 2 if lay.moving else 0]:
            y[:, getattr(lay, block)] = run.y[:, getattr(sl, block)]
        body = members + list(range(m.n_berries, m.n_berries + len(m.obstacles)))  # group's body -> scene's
        glob = np.array([pair_index[(body[p.i], body[p.j])] for p in run.scene.model.pairs], dtype=int)
        if len(glob):
            start[glob] = run.contact_log.start
            ch = run.contact_log.changes.copy()
            ch["pair"] = glob[ch["pair"]]
            changes.append(ch)
            peak_force[glob] = run.peak_force
        peak_tension[members] = run.peak_tension
        for f in COUNTS:
            totals[f] += run.totals[f]
        for f in PEAKS:
            totals[f] = np.maximum(totals[f], run.totals[f])
        rec = run.impacts.records()
        rec["pair"] = glob[rec["pair"]] if len(rec) else rec["pair"]
        finished.append(rec[~run.impacts.ongoing])
        ongoing.append(rec[run.impacts.ongoing])
    stats = dict(runs[0].stats)
    for key in (*WORK, "impacts", "degrees_of_freedom", "candidate_pairs", "wall_time", "segments", "islands_formed",
                "island_rollbacks"):
        if all(key in r.stats for r in runs):
            stats[key] = sum(r.stats[key] for r in runs)
    if all("near_pairs_mean" in r.stats for r in runs):
        stats["near_pairs_mean"] = sum(r.stats["near_pairs_mean"] * r.stats["steps"] for r in runs) / max(stats["steps"], 1)
    stats["groups"] = len(parts)
    if len({r.stats.get("integrator") for r in runs}) > 1:  # groups of fewer and more berries (solver.integrator_for)
        stats["integrator"] = "mixed"
    impacts = Impacts.from_records(concat(finished), concat(ongoing))
    changes = concat(changes) if changes else np.zeros(0, CHANGE)
    log = ContactLog(start, changes[np.argsort(changes["sample"], kind="stable")])
    return Run(scene, t, y, log, runs[0].accel, totals, impacts, peak_force, peak_tension, stats)

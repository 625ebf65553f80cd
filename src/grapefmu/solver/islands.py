"""Multirate islands (docs/solver.md, "Islands"): berries that cannot touch each other within a window are
integrated apart, each island with its own step sizes.

Time is cut into windows on the output grid. At a window's start every berry's angles are extrapolated,
q̂(τ) = q₀ + q̇₀ τ + ½ q̈₀ τ², and its positions on that path predicted (solver/drift.py); berries whose predicted
gap, less what they drifted from their paths in the last window, is small share an island (with the pairs among
them and with the obstacles). Each island then runs its own step sequence to the window's end, bounding on every
step how far each berry drifts from its path. Berries of different islands provably did not meet if their
predicted positions stayed farther apart than their radii and those bounds (`Islands._slack`); where a pair fails
that test, the islands it joins are rolled back to the window's start and run again as one. So every contact is
located as in one Solver of the whole scene, and a stiff contact in one island never shortens another's steps.
An island forms from the state its berries' islands left (solver/handover.py; the rachis' motion, which every
island integrates, from the last of them) and records its own samples, contact changes and impacts, which `run`
assembles into one Run of the scene: each energy term and count as the sum over islands, each peak as the largest.
"""
from __future__ import annotations

import time
from collections.abc import Callable

import numpy as np

from ..errors import SolverError
from ..model.model import Scene, islands_refusal
from ..physics.kinematics import overlaps
from ..physics.layout import layout_of
from ..results.contacts import ContactLog
from ..results.impacts import Impacts
from ..results.records import COUNTS, IMPACT, PEAKS, TOTALS, concat
from ..results.run import Run
from . import session as ses
from . import state as st
from .loop import IMPACTS_FULL, OUT_FULL, grid_last
from .drift import components, joined, regrouped, slack
from .handover import flush_all, form_all, parts, retire_all
from .solver import Solver, near_pole, open_impacts, run_stats, stopped
from .stiffness import contact_hint

#: the default window, s: long enough that a window's calls cost little against its steps, short enough that
#: berries stay near their extrapolated paths (`grapefmu bench --scale` measures other lengths)
WINDOW = 0.02
#: predicted positions per berry and window (drift.predict)
K = 5
#: m: berries of different islands join for the next window where a pair's slack (Islands._slack, with the drift
#: of the last window) is below JOIN; berries of one island part where it is above STAY
JOIN = 5e-4
STAY = 5e-3
#: systems out of use kept for islands of their shape to come, the least recently used dropped first: each holds its
#: model, state and a window's recorder. Under sustained shaking nearly every island has a shape of its own, and a pool
#: that kept them all grew with every window for as long as the run went on (docs/solver.md, "Islands": the memory
#: measured, and the command that measures it); gentle motion reuses a few shapes, which this keeps
FREE_SYSTEMS = 64


class _System:
    """An island's compiled side, made in compiled code (session.island): its model (room for the scene's rows of its
    berries, pairs and couplings), state in one buffer with its backup, recorder and loop buffers, all in one
    session. Built once per shape (berries, angles, couplings, pairs) and loaded with an island's berries in place
    (handover.form): until then its model and state hold no island's values."""

    __slots__ = ("shape", "session")

    def __init__(self, parent: Solver, n: int, n_dof: int, n_couplings: int, n_pairs: int, rows: int):
        self.shape = (n, n_dof, n_couplings, n_pairs)
        self.session = ses.island(parent._session, n, n_dof, n_couplings, n_pairs, rows)


class _Segment:
    """One island over the windows it lived through: its berries and pairs (scene indices, as Python reads them;
    its compiled side holds them too, with its map of the scene's components, handover.form), its system, and the
    impacts it recorded, which the run assembles last (its samples go into the run's arrays at each window's start
    and, with its contact changes, when it retires: handover.flush, retire)."""

    __slots__ = ("members", "pairs", "system", "impacts", "window", "base")

    def __init__(self, members, pairs, system, base):
        self.members, self.pairs = members, pairs
        self.system = system
        self.base = base  # the most steps any of its berries' islands took before it formed (the step limit's)
        self.impacts: list[np.ndarray] = []   # finished impacts of the windows kept
        self.window: list[np.ndarray] = []    # ... of the window in progress


class _Batch:
    """The islands a window runs, as the compiled loop (session.windows) reads them: their sessions in a numba list
    (each holding its berries and pairs in the scene, handover.form), what each island's window returned, and each
    berry's island (label; berries of no island in the batch keep what they held)."""

    def __init__(self, segs: list[_Segment], n: int, formation: Callable):
        """A batch of these islands, formed in it by formation (Islands._islands)."""
        self.segs = list(segs)
        self.sessions = ses.listed(segs[0].system.session)
        for k, seg in enumerate(segs[1:], 1):
            ses.put(self.sessions, k, seg.system.session)
        formation(self.sessions, np.arange(len(segs)))
        self.label = np.zeros(n, dtype=np.int64)
        self._index()

    def _index(self) -> None:
        k = len(self.segs)
        self.saved = np.zeros(k, dtype=st.CURSOR)
        self.base = np.array([seg.base for seg in self.segs], dtype=np.int64)
        self.status = np.zeros(k, dtype=np.int64)
        self.n_impacts = np.zeros(k, dtype=np.int64)
        ses.labels(self.sessions, self.label)

    def replace(self, slots: list[int], new: list[_Segment], formation: Callable | None = None,
                ran: _Batch | None = None) -> None:
        """The islands at these slots leave, islands new come (the sessions list changed in place: rebuilding it costs
        more), formed here by formation, or within a window already formed and run in the batch ran (new, in order),
        where each island keeps its saved cursor, for a later rollback."""
        slots = sorted(slots)
        n = len(self.segs)
        src = list(range(n))  # where each island's saved cursor is: here (< n), or n + its index in ran
        placed = []
        for j, seg in enumerate(new):
            if j < len(slots):
                k = slots[j]
                self.segs[k], src[k] = seg, n + j
            else:
                k = len(self.segs)
                self.segs.append(seg)
                src.append(n + j)
            ses.put(self.sessions, k, seg.system.session)
            placed.append(k)
        if formation is not None:
            formation(self.sessions, np.array(placed, dtype=np.int64))
        for k in reversed(slots[len(new):]):  # the last island moves into the free slot
            last = len(self.segs) - 1
            if k != last:
                self.segs[k], src[k] = self.segs[last], src[last]
            self.segs.pop()
            src.pop()
            ses.take_last(self.sessions, k)
        saved = self.saved
        self._index()
        if ran is not None:
            self.saved[:] = np.concatenate([saved, ran.saved])[src]


class Islands:
    """A whole run of an event-located scene in multirate islands (`run`); `Solver` arguments as in Solver (a method
    and fixed step given override the scene's, as `simulate`'s do)."""

    def __init__(self, scene: Scene, *, rtol: float | None = None, atol: float | None = None,
                 window: float = WINDOW, max_steps: int | None = None, method: str | None = None,
                 fixed_step: float | None = None):
        why = islands_refusal(method or scene.solver.method,
                              scene.solver.fixed_step if fixed_step is None else fixed_step)
        if why:
            raise SolverError(f"solver: {why}")
        if not window > 0.0:
            raise SolverError(f"window: must be > 0 s, got {window!r}")
        self.whole = Solver(scene, method=method, rtol=rtol, atol=atol, fixed_step=fixed_step,
                            max_steps=max_steps)  # the start, the settings
        self.scene, self.window, self.max_steps = scene, window, self.whole.max_steps
        m = scene.model
        self.n = m.n_berries
        self.layout = layout_of(scene)
        self.radius = self.whole.M.berry["radius"].copy()
        pi = np.array([p.i for p in m.pairs], dtype=int)
        pj = np.array([p.j for p in m.pairs], dtype=int)
        between = pj < self.n
        self.pair_i, self.pair_j = pi[between], pj[between]           # berry-berry pairs
        self.slack = np.zeros(len(self.pair_i))
        self.pair_index = np.flatnonzero(between)
        self.pair_owner, self.pair_other = pi, pj                     # every pair, obstacles too
        self.coupled = np.array([(c.i, c.j) for c in m.couplings], dtype=int).reshape(-1, 2)
        self.dof = m.dof
        self.free: dict[tuple[int, ...], list[_System]] = {}  # systems out of use, by shape, least recently used first
        self.local = np.zeros(self.n + len(m.obstacles), dtype=np.int64)  # scratch: scene body -> island's

    @property
    def n_free(self) -> int:
        """The systems in the pool (at most FREE_SYSTEMS + 1 of them in as many shapes: a sum of few lengths)."""
        return sum(len(pool) for pool in self.free.values())

    # --- the state between islands (scene indices) ----------------------------------------------------------
    def _start(self) -> None:
        """The scene's state between islands and the run's arrays, their first sample from the start Solver(scene)
        made; nothing formed or rolled back yet."""
        S = self.whole.state
        self.G = (S.physical.y.copy(), S.physical.contacts.copy(), S.book.pair.copy(), S.book.ring.copy(),
                  S.book.peak_tension.copy(), np.zeros(self.n), np.zeros(self.n))
        self.contacts0 = S.physical.contacts.copy()
        lay, n = self.layout, self.n_samples
        self.scene_offsets = np.array([lay.base_velocity.start, lay.d_hinge.start, lay.d_coupling.start, lay.d,
                                       lay.d_contact, lay.work])
        self.y, self.accel = np.zeros((n, lay.size)), np.zeros((n, 6))
        self.y[0], self.accel[0] = S.physical.y, self.whole.base_accel
        self.totals = np.repeat(S.book.totals, n)  # the pairs that start in contact count from the start (Solver's)
        self.later = np.zeros(n + 1, dtype=TOTALS)
        for f in PEAKS:
            self.later[f] = -np.inf
        self.ledger_later = np.zeros((n + 1, 2))
        self.counters = np.zeros(1, dtype=st.COUNTERS)
        self.segments: list[_Segment] = []
        self.changes: list[np.ndarray] = []  # the retired islands' contact changes, in the order they retired
        self.formed = self.rollbacks = self.berry_steps = 0
        self.done = np.zeros(self.n, dtype=np.int64)  # each berry's steps since the start, its islands' (max_steps)

    def _retire(self, segs: list[_Segment], slots: np.ndarray, sessions) -> None:
        """Put the state of these segments (at slots of the sessions list) into the scene's and their samples into
        the run's arrays, keep their contact changes and free their systems: one compiled call for them all."""
        changes, steps = retire_all(sessions, slots, self.G, self.scene_offsets, self.y, self.accel, self.totals,
                                    self.later, self.ledger_later, self.counters)
        self.changes.append(changes)
        for seg, n_steps in zip(segs, steps.tolist()):
            self.berry_steps += len(seg.members) * n_steps
            self.done[seg.members] = seg.base + n_steps
            seg.impacts += seg.window
            seg.window = []
            self.segments.append(seg)
            self._keep(seg.system)
            seg.system = None  # a retired segment keeps its berries, pairs and impacts, not its system

    def _keep(self, system: _System) -> None:
        """A system out of use into the pool (FREE_SYSTEMS)."""
        pool = self.free.pop(system.shape, [])
        pool.append(system)
        self.free[system.shape] = pool  # its shape now the most recently used
        while self.n_free > FREE_SYSTEMS:
            oldest = next(iter(self.free))
            self.free[oldest].pop(0)
            if not self.free[oldest]:
                del self.free[oldest]

    def _islands(self, label: np.ndarray, which: np.ndarray, t: float, k0: int) -> tuple[list[_Segment], Callable]:
        """Islands at time t, recording from sample k0: island k of the berries labelled which[k]. Returns their
        segments and the call that forms them, from the scene's state, once their sessions are in a list
        (formation(sessions, slots): handover.form_all)."""
        parted = parts(label, which, self.pair_owner, self.pair_other, self.coupled, self.dof)
        members, m_off, dofs, d_off, pairs, p_off, couplings, c_off = parted
        m, d, p, c = m_off.tolist(), d_off.tolist(), p_off.tolist(), c_off.tolist()
        segs = []
        for k in range(len(which)):
            shape = (m[k + 1] - m[k], d[k + 1] - d[k], c[k + 1] - c[k], p[k + 1] - p[k])
            pool = self.free.get(shape)
            # a recorder holds one window's samples (flushed at the next window's start): a few kilobytes that the
            # allocator hands back, where room for the rest of the run was fresh pages, faulted in for every system
            if pool:
                system = pool.pop()
                if not pool:
                    del self.free[shape]
            else:
                system = _System(self.whole, *shape, self.per + 1)
            mine = members[m[k]:m[k + 1]]
            segs.append(_Segment(mine, pairs[p[k]:p[k + 1]], system, int(self.done[mine].max())))
        self.formed += len(segs)
        M, G, local, offsets = self.whole.M, self.G, self.local, self.scene_offsets
        t0, dt, t_end = self.t0, self.dt, self.t_end

        def formation(sessions, slots: np.ndarray) -> None:
            form_all(sessions, slots, M, G, parted, local, offsets, t, t0, dt, k0, t_end)

        return segs, formation

    # --- windows ----------------------------------------------------------------------------------------------
    def _run(self, batch: _Batch, t_w: float) -> None:
        """Every island of the batch to t_w in compiled calls: each saves its state and anchors its path first; a
        full recorder grows, finished impacts go to the island's window list."""
        fresh = np.ones(len(batch.segs), dtype=bool)
        k = 0
        while True:
            batch.n_impacts[:] = 0
            k = ses.windows(batch.sessions, k, t_w, self.max_steps, batch.base, fresh, batch.saved, batch.status,
                            batch.n_impacts, self.drifted, self.engaged)
            for m in np.flatnonzero(batch.n_impacts):
                seg = batch.segs[m]
                seg.window.append(ses.take_impacts(seg.system.session))
                self.pending.add(seg)
            if k == len(batch.segs):
                return
            status, s = batch.status[k], batch.segs[k].system.session
            fresh[k] = False
            if status == OUT_FULL:
                ses.grow(s)
            elif status != IMPACTS_FULL:
                S, seg, m = ses.views(s)[0], batch.segs[k], self.scene.model
                t, h = S.physical.t[0], float(S.integrator.clock["h"][0])
                berries = [m.berries[i] for i in seg.members]
                pole = near_pole(S.physical.y, berries, np.cumsum([0] + [b.ndof for b in berries]))
                contacts = np.zeros(len(m.pairs), dtype=S.physical.contacts.dtype)  # the island's pairs in the scene's
                contacts[seg.pairs] = S.physical.contacts[:len(seg.pairs)]
                delta = np.zeros(len(m.pairs))
                delta[seg.pairs] = overlaps(S.physical.y, ses.model(s))[:len(seg.pairs)]
                why = stopped(status, h, self.max_steps, pole, contact_hint(m, contacts, delta))
                ses.rollback(s, batch.saved[k])
                raise SolverError(f"integration stopped at t = {t:.9g} s: {why}")

    def _slack(self, span: float) -> np.ndarray:
        """For each berry-berry pair, a lower bound on its gap over the window (drift.slack)."""
        slack(self.lin, self.reach, self.drifted, self.radius, self.pair_i, self.pair_j, span, STAY, self.slack)
        return self.slack

    def _components(self, slack: np.ndarray, label: np.ndarray) -> np.ndarray:
        """Each berry's island for the next window (a label; drift.joined's rules, with JOIN and STAY: a pair of one
        island stays joined up to the larger STAY, so that islands do not form and part on every window)."""
        group = np.empty(self.n, dtype=np.int64)
        joined(self.n, self.engaged, self.pair_index, slack, label, self.pair_i, self.pair_j, self.coupled, JOIN, STAY,
               group)
        return group

    def _regroup(self, t: float, t_w: float, k: int) -> None:
        """Islands for the window [t, t_w]: predict every berry's path (its drift taken from the last window), retire
        the islands whose berries now group otherwise and form the new groups. The first window's paths start
        from the start Solver's state, as from one island of every berry."""
        b = self.batch
        if b is None:
            ses.preview(self.whole._session, t_w - t, np.arange(self.n), self.lin, self.reach)
            comp = self._components(self._slack(t_w - t), np.zeros(self.n, dtype=np.int64))
            segs, formation = self._islands(comp, np.unique(comp), t, k)
            self.batch = _Batch(segs, self.n, formation)
            return
        ses.previews(b.sessions, t_w - t, self.lin, self.reach)
        comp = self._components(self._slack(t_w - t), b.label)
        slots, which = regrouped(comp, b.label, len(b.segs))
        if len(slots):
            self._retire([b.segs[m] for m in slots], slots, b.sessions)
            b.replace(slots.tolist(), *self._islands(comp, which, t, k))

    def _window(self, t: float, t_w: float, k: int) -> None:
        """Run every island to t_w; where berries of different islands could have met, roll their islands back and
        run them again as one."""
        for seg in self.pending:  # the last window's impacts are kept
            seg.impacts += seg.window
            seg.window = []
        self.pending.clear()
        b = self.batch
        flush_all(b.sessions, self.scene_offsets, self.y, self.accel, self.totals)  # the last window is final
        self._run(b, t_w)
        while True:
            label = b.label
            bad = (label[self.pair_i] != label[self.pair_j]) & (self._slack(t_w - t) <= 1e-12)
            if not bad.any():
                return
            x, y = label[self.pair_i[bad]], label[self.pair_j[bad]]
            comp = np.empty(len(b.segs), dtype=np.int64)
            components(len(b.segs), x, y, comp)
            size = np.bincount(comp)
            groups: dict[int, list[int]] = {}
            for m in np.flatnonzero(size[comp] > 1):
                groups.setdefault(comp[m], []).append(m)
            slots = np.array([m for members in groups.values() for m in members], dtype=np.int64)
            out = [b.segs[m] for m in slots]
            for m, seg in zip(slots, out):
                ses.rollback(seg.system.session, b.saved[m])
                seg.window = []
            self._retire(out, slots, b.sessions)
            self.rollbacks += len(groups)
            new, formation = self._islands(comp[label], np.array(list(groups), dtype=np.int64), t, k)
            ran = _Batch(new, self.n, formation)
            self._run(ran, t_w)
            b.replace(slots.tolist(), new, ran=ran)

    # --- the run ----------------------------------------------------------------------------------------------
    def run(self, t_end: float | None = None, output_interval: float | None = None,
            progress: Callable[[float, float], None] | None = None) -> Run:
        """The scene from its start to t_end (Solver.run's arguments), as one Run. Its stats count every island's
        steps and evaluations, and how many islands formed and were rolled back."""
        t_end, dt = self.whole.run_span(t_end, output_interval)  # refused as Solver.run refuses them
        self.dt = dt
        self.t0 = t0 = self.whole.t
        self.t_end = t_end
        # the run's step limit, as one Solver's: the stiffest hinge's island alone takes at least its steps
        self.whole.refuse_stiff(t_end - t0)
        self.n_samples = n = grid_last(t0, t_end, dt, True) + 1
        self.per = per = max(1, int(round(min(self.window / dt, n - 1))))  # a window beyond the run is the run
        self._start()
        wall_start = time.perf_counter()
        self.lin, self.reach = np.zeros((K, self.n, 3)), np.zeros((self.n, 2))
        self.drifted = np.zeros(self.n)
        self.engaged = np.zeros(len(self.scene.model.pairs), dtype=bool)
        self.pending: set[_Segment] = set()
        self.batch: _Batch | None = None
        k = 0
        while k < n - 1:
            k_w = min(k + per, n - 1)
            t = t0 + k * dt
            t_w = t0 + k_w * dt if k_w < n - 1 else t_end
            self._regroup(t, t_w, k + 1)
            self._window(t, t_w, k + 1)
            k = k_w
            if progress:
                progress(t_w, t_end)
        if self.batch:
            self._retire(self.batch.segs, np.arange(len(self.batch.segs)), self.batch.sessions)
        return self._assemble(t_end, time.perf_counter() - wall_start)

    def _assemble(self, t_end: float, wall: float) -> Run:
        """One Run of the scene from the run's arrays and the segments (as a Solver of the whole scene would record
        it)."""
        lay, n = self.layout, self.n_samples
        t = self.t0 + np.arange(n) * self.dt
        t[-1] = min(t[-1], t_end)
        y, totals, later = self.y, self.totals, self.later[:n]
        y[:, [lay.d_contact, lay.work]] += np.cumsum(self.ledger_later[:n], axis=0)
        for f in COUNTS:
            totals[f] += np.cumsum(later[f])
        for f in PEAKS:
            np.maximum(totals[f], np.maximum.accumulate(later[f]), out=totals[f])
        finished = []
        for seg in self.segments:
            for rec in seg.impacts:
                rec = rec.copy()
                rec["pair"] = seg.pairs[rec["pair"]]
                finished.append(rec)
        ongoing = open_impacts(self.G[1], self.G[2], t[-1])
        changes = concat(self.changes) if self.changes else np.zeros(0, dtype=st.CHANGE)
        log = ContactLog(self.contacts0, changes[np.argsort(changes["sample"], kind="stable")])
        impacts = concat(finished) if finished else np.zeros(0, dtype=IMPACT)
        impacts = impacts[np.argsort(impacts["end"], kind="stable")]
        stats = run_stats(self.counters, totals[-1:], lay, len(self.scene.model.pairs))
        stats |= {"wall_time": wall, "method": "event", "integrator": self.whole.integrator, "t_start": self.t0,
                  "rtol": self.whole.rtol, "atol": self.whole.atol, "fixed_step": self.whole.fixed_step,
                  "islands_formed": self.formed, "island_rollbacks": self.rollbacks, "window": self.window}
        return Run(self.scene, t, y, log, self.accel, totals, Impacts.from_records(impacts, ongoing),
                   self.G[2]["peak_force"].copy(), self.G[4].copy(), stats)

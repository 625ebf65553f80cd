"""`Solver`: the event-driven simulator as an object that steps (like scipy's OdeSolver).

`step()` takes one accepted step, `advance(dt, base_accel)` integrates a whole interval
with the acceleration held (what an FMU's do_step and a ROS timer need) and `run(t_end)`
records a whole run. State can be saved and restored exactly, solver internals included.
"""
from __future__ import annotations

import math
import time
from collections.abc import Callable
from typing import NamedTuple

import numpy as np

from ..errors import SolverError
from ..model.excitation import ExcitationArrays, constant
from ..model.model import Scene
from ..physics.dynamics import centres, jit, rhs
from ..physics.layout import layout
from . import core
from .tableau import BOGACKI_SHAMPINE, DOPRI5

#: MATLAB ode23's default tolerances, used by the paper method unless told otherwise.
PAPER_RTOL, PAPER_ATOL = 1e-3, 1e-6
#: the broad phase's skin as a fraction of the mean berry radius (benchmarked in docs/benchmarks.md):
#: wider means fewer rebuilds but more near pairs to watch on every step
SKIN_FRACTION = 0.5


class SolverState(NamedTuple):
    y: np.ndarray
    f: np.ndarray
    y_prev: np.ndarray
    k: np.ndarray
    q: np.ndarray
    fl: np.ndarray
    it: np.ndarray
    mode: np.ndarray
    v_onset: np.ndarray
    smooth: np.ndarray
    smooth_until: np.ndarray
    imp_open: np.ndarray
    ring: np.ndarray
    ring_pos: np.ndarray
    peak_force: np.ndarray
    peak_tension: np.ndarray
    pair_int: np.ndarray   # (P, 2): impulse ∫F dt and dissipation per pair since the start
    near: np.ndarray       # (P,): the broad phase's near pairs, the first it[N_NEAR] entries
    ref: np.ndarray        # (N, 3): berry centres when the near list was built

    def copy(self) -> SolverState:
        return SolverState(*(a.copy() for a in self))


class Buffers(NamedTuple):
    t: np.ndarray
    y: np.ndarray
    mode: np.ndarray
    acc: np.ndarray
    v_onset: np.ndarray
    smooth: np.ndarray
    imp: np.ndarray


def _buffers(cap: int, ny: int, npair: int, cap_imp: int) -> Buffers:
    p = max(npair, 1)
    return Buffers(np.zeros(cap), np.zeros((cap, ny)), np.zeros((cap, p), dtype=np.int64), np.zeros((cap, 2)),
                   np.zeros((cap, p)), np.zeros((cap, p), dtype=np.bool_), np.zeros((cap_imp, core.IMPACT_COLUMNS)))


@jit
def _initial_modes(S, M, skin):
    """Modes from the state (a pair that starts in contact opens an impact at the start time),
    then the first near list."""
    npair = S.mode.shape[0]
    for p in range(npair):
        mode, ddot = core.classify(p, S.y, M, S.v_onset, 0)
        S.mode[p] = mode
        if mode != 0:
            S.imp_open[p, core.O_ONSET] = S.fl[core.T]
            S.imp_open[p, core.O_SPEED] = ddot
            S.imp_open[p, core.O_PEAK] = 0.0
            S.imp_open[p, core.O_TPEAK] = S.fl[core.T]
            S.imp_open[p, core.O_J] = 0.0
            S.imp_open[p, core.O_D] = 0.0
            S.it[core.N_IMPACTS] += 1
    pos = np.zeros((M.berry.shape[0], 3))
    centres(S.y, M, pos)
    core.rebuild_near(S, M, pos, skin)
    S.it[core.N_REBUILDS] = 0


def _held_input(S: SolverState) -> tuple[float, float] | None:
    """The held (zero-order-hold) input, kept in the state so that set_state restores it too."""
    return (float(S.fl[core.HELD_AX]), float(S.fl[core.HELD_AY])) if S.it[core.HELD] else None


STATUS_TEXT = {
    core.MAX_STEPS: "the step limit was reached",
    core.STEP_UNDERFLOW: "the step size fell below the resolution of time (the problem is too stiff for this tolerance)",
    core.NOT_FINITE: "the state became NaN or infinite",
}


class Solver:
    """One simulation in progress. The model is read-only; everything that changes lives in `state`."""

    def __init__(self, scene: Scene, *, method: str | None = None, rtol: float | None = None,
                 atol: float | None = None, fixed_step: float | None = None, max_steps: int = 10_000_000,
                 skin: float | None = None):
        s = scene.solver
        self.scene = scene
        self.method = method or s.method
        if self.method not in ("event", "paper"):
            raise ValueError(f"method: Solver runs 'event' or 'paper', got {self.method!r} (use simulate() for 'reference')")
        self.tableau = DOPRI5 if self.method == "event" else BOGACKI_SHAMPINE
        self.rtol = rtol if rtol is not None else s.rtol
        self.atol = atol if atol is not None else s.atol
        self.fixed_step = fixed_step if fixed_step is not None else s.fixed_step
        self.max_steps = max_steps
        self.model = scene.model
        self.M = scene.model.arrays
        self.excitation = scene.excitation.arrays
        self.layout = layout(self.model.n_berries, self.model.n_dof, len(self.model.couplings))
        self.npair = len(self.model.pairs)
        if skin is None:
            skin = SKIN_FRACTION * float(np.mean([b.radius for b in self.model.berries]))
        step_control = s.contact_location == "step-control" and self.method == "event"
        self.cfg = np.array([self.rtol, self.atol, self.fixed_step, s.zeno_window,
                             1.0 if self.method == "event" else 0.0, math.inf, skin, float(step_control)])
        self._held_arrays = constant(1.0, 0.0).arrays  # reused for every held input: no allocation per step
        self._closed: list[np.ndarray] = []
        self.state = self._fresh_state(scene.initial_state, s.zeno_max_events)
        self._scratch = _buffers(1, self.layout.size, self.npair, max(self.npair, 1) * 4)

    # --- state -----------------------------------------------------------------------------------
    def _fresh_state(self, x0: np.ndarray, zeno_max: int) -> SolverState:
        lay = self.layout
        ny, npair, n = lay.size, self.npair, lay.n
        p = max(npair, 1)
        ns = self.tableau.b.shape[0]
        y = np.zeros(ny)
        y[: 2 * lay.d] = x0
        S = SolverState(y, np.zeros(ny), y.copy(), np.zeros((ns + 1, ny)), np.zeros((ny, self.tableau.p.shape[1])),
                        np.zeros(8), np.zeros(15, dtype=np.int64), np.zeros(npair, dtype=np.int64),
                        np.full(npair, core.HC_MIN_APPROACH_SPEED), np.zeros(npair, dtype=np.bool_),
                        np.zeros(npair), np.zeros((p, 6)), np.full((p, zeno_max), -np.inf),
                        np.zeros(p, dtype=np.int64), np.zeros(npair), np.full(n, -np.inf), np.zeros((npair, 2)),
                        np.zeros(npair, dtype=np.int64), np.zeros((n, 3)))
        if self.cfg[core.STEP_CONTROL]:
            S.smooth_until[self.M.pair_law != 0] = np.inf  # hertz, hunt-crossley: no force jump at onset
        _initial_modes(S, self.M, self.cfg[core.SKIN])
        self._refresh_derivative(S)
        return S

    @property
    def _held(self) -> tuple[float, float] | None:
        return _held_input(self.state)

    def _hold(self, held: tuple[float, float] | None) -> None:
        S = self.state
        S.it[core.HELD] = held is not None
        S.fl[core.HELD_AX], S.fl[core.HELD_AY] = held if held is not None else (0.0, 0.0)

    def _inputs(self, S: SolverState | None = None) -> ExcitationArrays:
        held = _held_input(self.state if S is None else S)
        if held is None:
            return self.excitation
        self._held_arrays.par[0], self._held_arrays.par[1] = held
        return self._held_arrays

    def _refresh_derivative(self, S: SolverState) -> None:
        X = self._inputs(S)
        t = S.fl[core.T]
        rhs(t, t, S.y, S.f, S.mode, S.v_onset, S.smooth, self.M, X.kind, X.par, X.table)

    def get_state(self) -> SolverState:
        """A deep copy: restoring it with set_state replays the same trajectory bit for bit."""
        return self.state.copy()

    def set_state(self, state: SolverState) -> None:
        self.state = state.copy()

    @property
    def t(self) -> float:
        return float(self.state.fl[core.T])

    @property
    def y(self) -> np.ndarray:
        return self.state.y.copy()

    @property
    def angles(self) -> np.ndarray:
        return self.state.y[self.layout.q].copy()

    @property
    def angular_velocities(self) -> np.ndarray:
        return self.state.y[self.layout.w].copy()

    @property
    def modes(self) -> np.ndarray:
        return self.state.mode.copy()

    @property
    def stats(self) -> dict[str, int]:
        it = self.state.it
        return {"steps": int(it[core.N_STEPS]), "rejected": int(it[core.N_REJECTED]), "rhs_evaluations": int(it[core.N_RHS]),
                "switches": int(it[core.N_SWITCHES]), "impacts": int(it[core.N_IMPACTS]),
                "zeno_guard_activations": int(it[core.N_ZENO]), "degrees_of_freedom": self.layout.d,
                "candidate_pairs": self.npair, "near_pairs_mean": float(it[core.NEAR_SUM]) / max(int(it[core.N_STEPS]), 1),
                "near_list_rebuilds": int(it[core.N_REBUILDS])}

    # --- stepping --------------------------------------------------------------------------------
    def _integrate(self, t_target: float, buffers: Buffers, max_steps: int) -> int:
        return core.integrate(self.M, self._inputs(), self.tableau, self.state, self.cfg, buffers, t_target, max_steps)

    def step(self) -> float:
        """Take one accepted step (it may end early at a contact switch or breakpoint); return the new time."""
        before = self.state.copy()
        self.state.it[core.N_IMP] = 0
        self.state.fl[core.GRID_DT] = 0.0
        status = self._integrate(math.inf, self._scratch, 1)
        if status not in (core.DONE, core.MAX_STEPS):
            self._fail(status, before)
        self._closed.extend(self._scratch.imp[: self.state.it[core.N_IMP]].copy())
        return self.t

    def dense_output(self) -> Callable[[np.ndarray | float], np.ndarray]:
        """The continuous extension of the last step over [t_prev, t]: y(t) for t in that interval."""
        S = self.state
        t0, h = S.fl[core.T_PREV], S.fl[core.H_LAST]
        y0, q = S.y_prev.copy(), S.q.copy()

        def y_of(t):
            th = (np.atleast_1d(np.asarray(t, dtype=float)) - t0) / h
            out = np.empty((th.size, y0.size))
            for i, x in enumerate(th):
                core.dense(x, y0, q, h, out[i])
            return out if np.ndim(t) else out[0]

        return y_of

    def advance(self, dt: float, base_accel: tuple[float, float] | None = None) -> None:
        """Integrate exactly dt seconds. With base_accel the rachis acceleration is held at that
        value over the interval (zero-order hold, as an FMU input or a ROS message gives it);
        without it the scene's excitation is used. On failure the state is left unchanged."""
        if not (isinstance(dt, (int, float)) and math.isfinite(dt) and dt > 0):
            raise SolverError(f"dt: expected a finite step > 0 s, got {dt!r}")
        if base_accel is not None:
            ax, ay = (float(base_accel[0]), float(base_accel[1]))
            if not (math.isfinite(ax) and math.isfinite(ay)):
                raise SolverError(f"base_accel: expected finite values in m/s², got ({ax!r}, {ay!r})")
            held = (ax, ay)
        else:
            held = None
        before = self.state.copy()
        if held != self._held:
            self._hold(held)
            self._refresh_derivative(self.state)
        self.state.it[core.N_IMP] = 0
        self.state.fl[core.GRID_DT] = 0.0
        t_target = self.t + dt
        closed = []
        while True:
            status = self._integrate(t_target, self._scratch, self.max_steps)
            closed.append(self._scratch.imp[: self.state.it[core.N_IMP]].copy())
            if status != core.IMP_FULL:
                break
            self.state.it[core.N_IMP] = 0
        if status != core.DONE:
            self._fail(status, before)
        self._closed.extend(r for c in closed for r in c)

    def take_impacts(self):
        """Impacts that ended since the last call (during step() or advance()), oldest first."""
        from ..results.run import Impacts

        rows, self._closed = self._closed, []
        return Impacts.from_rows(np.array(rows).reshape(-1, core.IMPACT_COLUMNS))

    def _fail(self, status: int, before: SolverState) -> None:
        t = self.t
        self.state = before
        raise SolverError(f"integration stopped at t = {t:.9g} s: {STATUS_TEXT.get(status, f'status {status}')}; "
                          f"the state is left at t = {self.t:.9g} s")

    def run(self, t_end: float | None = None, output_interval: float | None = None,
            progress: Callable[[float, float], None] | None = None):
        """Integrate from the current time to t_end, recording samples every output_interval."""
        from ..results.run import Run

        s = self.scene.solver
        t_end = s.t_end if t_end is None else float(t_end)
        dt_out = s.output_interval if output_interval is None else float(output_interval)
        S = self.state
        lay = self.layout
        n_expected = int(math.floor((t_end - self.t) / dt_out + 1e-9)) + 1
        buf = _buffers(n_expected + 1, lay.size, self.npair, max(self.npair, 1) * 256)
        S.fl[core.GRID_T0] = self.t
        S.fl[core.GRID_DT] = dt_out
        S.it[core.GRID_K] = 1
        S.it[core.N_OUT] = 0
        S.it[core.N_IMP] = 0
        t_start = self.t
        first = _snapshot(self, self._inputs())
        impacts, chunks = [], [first]
        wall = time.perf_counter()
        chunk, steps = 5000, 0
        while True:
            status = self._integrate(t_end, buf, chunk)
            if status in (core.IMP_FULL, core.OUT_FULL, core.MAX_STEPS, core.DONE):
                impacts.append(buf.imp[: S.it[core.N_IMP]].copy())
                chunks.append(tuple(b[: S.it[core.N_OUT]].copy() for b in buf[:6]))
                S.it[core.N_IMP] = 0
                S.it[core.N_OUT] = 0
            if status == core.MAX_STEPS:
                steps += chunk
                if progress:
                    progress(self.t, t_end)
                if steps < self.max_steps:
                    continue
            if status in (core.IMP_FULL, core.OUT_FULL):
                continue
            break
        if status != core.DONE:
            raise SolverError(f"integration stopped at t = {self.t:.9g} s: {STATUS_TEXT.get(status, f'status {status}')}")
        wall = time.perf_counter() - wall
        if progress:
            progress(self.t, t_end)
        samples = tuple(np.concatenate([c[i] for c in chunks]) for i in range(6))
        stats = self.stats | {"wall_time": wall, "method": self.method, "t_start": t_start, "rtol": self.rtol,
                              "atol": self.atol}
        return Run.from_solver(self.scene, samples, np.concatenate(impacts), self, stats)


def _snapshot(solver: Solver, X: ExcitationArrays) -> tuple[np.ndarray, ...]:
    from ..physics.dynamics import base_accel

    S = solver.state
    t = S.fl[core.T]
    ax, ay = base_accel(X.kind, X.par, X.table, t, t)
    p = max(S.mode.shape[0], 1)
    mode = np.zeros((1, p), dtype=np.int64)
    mode[0, : S.mode.shape[0]] = S.mode
    v_onset = np.zeros((1, p))
    v_onset[0, : S.mode.shape[0]] = S.v_onset
    smooth = np.zeros((1, p), dtype=np.bool_)
    smooth[0, : S.mode.shape[0]] = S.smooth
    return (np.array([t]), S.y[None, :].copy(), mode, np.array([[ax, ay]]), v_onset, smooth)

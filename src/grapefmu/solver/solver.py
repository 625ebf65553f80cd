"""`Solver`: the event-driven simulator as an object that steps (like scipy's OdeSolver).

`step()` takes one accepted step, `advance(dt, base_accel)` integrates a whole interval with the
acceleration held (what an FMU's do_step and a ROS timer need) and `run(t_end)` records a whole run.
`observe()` and `totals()` give what every face reports; `get_state`/`set_state` save and restore the
whole state exactly, solver internals included. Every failure leaves the state as it was.
"""
from __future__ import annotations

import functools
import hashlib
import math
import time
from collections.abc import Callable
from numbers import Integral, Real

import numpy as np

from ..errors import SceneError, SolverError, StateError
from ..model.excitation import MAX_ACCEL, MAX_ANGULAR_ACCEL, MAX_ANGULAR_VELOCITY
from ..model.bounds import bound
from ..model.model import MAX_OVERLAP_FRACTION, Scene, SolverSettings, off_axis
from ..physics import observe as obs
from ..physics.compiled import entry
from ..physics.excitation import ACCEL_COMPONENTS, base_accel
from ..physics.kinematics import deepest_overlap, overlaps
from ..physics.layout import LEDGER_TERMS, angular_velocity, displacement, initial, ledger, layout_of, orientation
from ..results import catalogue
from ..results.contacts import ContactLog
from ..results.impacts import Impacts
from ..results.records import WORK, concat
from ..results.run import Run
from . import session as ses
from . import state as st
from .budget import check_samples
from .loop import (AT_POLE, DONE, IMPACTS_FULL, MAX_STEPS, NOT_FINITE, OUT_FULL, POLE_CHECKS, POLE_EVERY, POLE_STOP,
                   REFUSED, STEP_UNDERFLOW, grid_last)
from .stiffness import contact_hint, fixed_step_hint, least_steps, refuse_stiff
from .tableau import BOGACKI_SHAMPINE, DOP853, DOPRI5, Tableau

#: the broad phase's skin as a fraction of the mean berry radius (benchmarked in docs/benchmarks.md):
#: wider means fewer rebuilds but more near pairs to watch on every step
SKIN_FRACTION = 0.5

#: The event method's pair: DOP853 below DOP853_BELOW, or below DOP853_BELOW_FEW for a scene of fewer than
#: FEW_BERRIES berries run whole (not driven: a face's communication points cut its steps); DOPRI5 otherwise.
#: DOP853 is asked DOP853_TOLERANCE times the tolerances (rtol and atol), where its error matches DOPRI5's at the
#: asked ones, so a run's accuracy follows its rtol whichever pair steps it. The measurements behind each number:
#: docs/solver.md, "Order to match the tolerance" (benchmarks/order_crossover.py).
DOP853_BELOW = 1e-7
DOP853_BELOW_FEW = 1e-5
FEW_BERRIES = 10
DOP853_TOLERANCE = 1 / 3

#: accepted steps one call may take where neither its caller nor its scene (solver.max_steps) says: a whole run, and a
#: face's step (advance of a driven Solver: an FMU's doStep, a ROS node's tick), which a master or an executor waits
#: for, so it ends in bounded time (well under a second) with an error a master can act on
RUN_MAX_STEPS, FACE_MAX_STEPS = 10_000_000, 100_000
#: s: the longest span a run or an advance takes from the solver's time (solver.t_end's bound). A longer step is no
#: step of a co-simulation: a wall-clock stamp (1.7e9 s) sent to a lockstep node was refused as a hinge too stiff for
#: 2.5e8 solver steps
LONGEST_STEP = bound(SolverSettings, "t_end").hi
#: |cos s| below which a failed run blames a spherical berry's swing for its shrinking steps: the swing–tilt chart
#: is singular at cos s = 0, and one approaching it stalls the run (|cos s| = 1.2e-3 at steps of 0.6 µs and 1.5e-5
#: at 80 ps, in a pass that never ended)
POLE = 1e-2

NO_IMPACTS = Impacts.from_records(np.zeros(0, dtype=st.IMPACT))

STATUS_TEXT = {
    MAX_STEPS: "the step limit was reached",
    STEP_UNDERFLOW: "the step size fell below the resolution of time (the problem is too stiff for this tolerance)",
    NOT_FINITE: "the state became NaN or infinite",
    AT_POLE: f"a spherical berry's swing stayed within |cos s| < {POLE_STOP:g} of its swing–tilt chart's pole for "
             f"{POLE_CHECKS * POLE_EVERY} steps",
}


def near_pole(y: np.ndarray, berries, dofs) -> tuple[str, float] | None:
    """(name, swing) of the spherical berry nearest its swing–tilt chart's pole (cos s = 0) if one is within POLE of
    it; berries[k]'s swing is y[dofs[k]]."""
    best = None
    for b, k in zip(berries, dofs):
        c = abs(math.cos(y[k]))
        if b.spherical and c < POLE and (best is None or c < best[0]):
            best = (c, b.name, float(y[k]))
    return best and best[1:]


def stopped(status: int, h: float, max_steps: int, pole: tuple[str, float] | None, contact: str | None = None) -> str:
    """Why a run stopped, for its SolverError: a spherical berry at its chart's pole (pole: near_pole()) when the steps
    shrank without end there, the step limit with the step size that needed so many steps (a stiff scene takes
    minutes to reach it: say what makes it slow) and the pairs in contact then (contact: stiffness.contact_hint), or
    the status's text."""
    if pole and status in (MAX_STEPS, STEP_UNDERFLOW, AT_POLE):
        return (f"spherical berry {pole[0]!r} swung to {math.degrees(pole[1]):.4f}°, at the pole of its swing–tilt "
                "chart (singular at ±90°: a twig swung sideways flat, docs/model.md §1): the tilt turns ever faster "
                f"near it and the steps shrank to {h:.3g} s; this model does not pass that pose")
    why = STATUS_TEXT.get(status, f"status {status}")
    if status == MAX_STEPS:
        why += (f" ({max_steps} steps; the step size was {h:.3g} s, {1 / h if h > 0 else math.inf:.3g} steps per "
                "simulated second: a time scale that short, such as a hinge damping or a contact law far stiffer "
                "than the berry's inertia, is stiff for an explicit solver; change it, or allow more steps with "
                "max_steps, solver.max_steps in a scene file)")
        if contact:
            why += f"; {contact}"
    return why


class Solver:
    """One simulation in progress. The model is read-only; everything that changes lives in `state`."""

    def __init__(self, scene: Scene, *, method: str | None = None, rtol: float | None = None,
                 atol: float | None = None, fixed_step: float | None = None, max_steps: int | None = None,
                 skin: float | None = None, locate: bool | None = None, t_start: float = 0.0,
                 driven: bool = False):
        """driven: advance()'s inputs may move and turn the rachis (a face: the FMU, the ROS node), whatever the
        scene's excitation does; otherwise it moves and turns only as far as the scene does (Excitation.moves,
        .turns), and a rachis the scene holds still is left out of the state."""
        s = scene.solver
        scene = scene.driven() if driven else scene
        self.scene = scene
        self.method = method or s.method
        if self.method not in ("event", "paper"):
            raise SolverError(f"method: Solver runs 'event' or 'paper', got {self.method!r} "
                              "(simulate() runs 'reference')")
        refuse_out_of_range(rtol=rtol, atol=atol, fixed_step=fixed_step, max_steps=max_steps)
        if _finite(t_start) is None:
            raise SolverError(f"t_start: expected a finite time in s, got {t_start!r}")
        self.rtol = float(rtol) if rtol is not None else s.rtol
        self.atol = float(atol) if atol is not None else s.atol
        self.fixed_step = float(fixed_step) if fixed_step is not None else s.fixed_step
        #: the Runge–Kutta pair that steps it, by name (INTEGRATORS; a run's stats give it as "integrator")
        self.integrator = integrator_for(self.method, self.rtol, self.fixed_step, scene.model.n_berries, driven,
                                         s.integrator)
        self.tableau = tableau(self.integrator)
        tighter = DOP853_TOLERANCE if self.integrator == "DOP853" else 1.0
        self.max_steps = int(max_steps if max_steps is not None else s.max_steps if s.max_steps is not None else
                             FACE_MAX_STEPS if driven else RUN_MAX_STEPS)
        self.model = scene.model
        self.M = scene.arrays
        self.excitation = scene.excitation.arrays
        self.layout = layout_of(scene)
        n = scene.plane_normal
        self._plane_normal = None if n is None else tuple(float(c) for c in n)  # floats: off_axis without numpy
        if skin is None:
            skin = SKIN_FRACTION * self.model.mean_radius
        th = scene.thresholds
        self.config = np.zeros(1, dtype=st.CONFIG)
        self.config[0] = (tighter * self.rtol, tighter * self.atol, self.fixed_step, s.zeno_window,
                          self.method == "event" if locate is None else locate, math.inf, skin,
                          s.contact_location == "step-control" and self.method == "event", th.bruise_force,
                          th.bruise_energy, th.detachment_force)
        self._closed: list[np.ndarray] = []
        # session.advance and .refresh for the types a face's step passes them (compiled.entry), on the first call
        self._advance = self._refresh = None
        #: at least this many steps per simulated second: set by the stiffest hinge (solver/stiffness.py), or the fixed
        #: step's own (refuse_stiff refuses a span either needs more than max_steps for, before a step)
        self._least_rate = 1.0 / self.fixed_step if self.fixed_step > 0.0 else least_steps(
            self.model, self.tableau, 1.0, self.layout.turning)[0]
        self._session = ses.start(self.M, self.excitation, self.tableau, self.config, initial(self.layout, scene),
                                  float(t_start), np.uint64(self._fingerprint()), s.zeno_max_events)
        # the state's arrays are views on _memory, so that a step's backup and rollback are one copy each
        self.state, self._memory, self._backup = ses.views(self._session)
        self._contact_flags = (self.state.physical.contacts["mode"], self.state.physical.contacts["smooth"])  # touching
        if self._contact_flags[0].any():
            self._refuse_deep(self.state.physical.y)
        self._snapshot: catalogue.Snapshot | None = None  # made by the first snapshot()

    def _refuse_deep(self, y: np.ndarray, apart: np.ndarray | None = None) -> None:
        """Refuse a state y whose pairs overlap by more than MAX_OVERLAP_FRACTION of the smaller radius: deeper, a
        contact law means nothing and the pair is flung apart with energy nobody gave it. Without `apart`, y is the
        start, however the scene was built (a scene file says so on its own keys, scenefile.parse): a SceneError on
        the scene's key. With it (a bool per pair, its mode apart), y is a state given to set_state, and only its
        pairs apart count: a solver that pressed that deep holds the pair in contact, so one apart was not reached
        by a solver: a StateError."""
        depth = overlaps(y, self.M)
        if apart is not None:
            depth = np.where(apart, depth, -np.inf)
        hit = deepest_overlap(depth[None], MAX_OVERLAP_FRACTION * self.model.contact_radius)
        if hit is None:
            return
        _, p, delta, limit = hit
        m = self.model
        if apart is not None:
            raise StateError(f"state physical.y: {m.overlap_words(p, delta, limit, 'given')}, while its contact mode "
                             "says apart (not a state a solver reached); the solver keeps its own")
        pr, nb = m.pairs[p], m.n_berries
        key = f"obstacles[{pr.j - nb}].point" if pr.j >= nb else f"angles[{m.dof[pr.j]}]"
        raise SceneError(key, m.overlap_words(p, delta, limit, "initial"))

    @functools.cached_property
    def _outputs(self) -> tuple[st.Recorder, tuple]:
        """(scratch recorder, now): where step and advance record and what snapshot shows (session.outputs), fetched
        on a face's first call: a run reads neither."""
        return ses.outputs(self._session)

    # --- state -----------------------------------------------------------------------------------
    def _fingerprint(self) -> int:
        """The model, method and settings a state belongs to, as one number."""
        h = hashlib.blake2b(self.scene.digest, digest_size=8)
        h.update(self.config.tobytes())  # CONFIG is packed: its bytes are its fields' bytes, in order
        h.update(self.method.encode())
        return int.from_bytes(h.digest(), "little")

    def get_state(self) -> st.SolverState:
        """A deep copy: restoring it with set_state replays the same trajectory bit for bit."""
        return st.copy(self.state)

    def set_state(self, state: st.SolverState) -> None:
        """Restore a state from get_state of a solver of the same scene and method; anything else, or a
        corrupted state, is refused with a StateError naming the field, and the solver keeps its own."""
        st.check(state, self.state, self.excitation.breaks.shape[0])
        self._refuse_deep(state.physical.y, state.physical.contacts["mode"] == 0)
        st.assign(self.state, state)

    @property
    def t(self) -> float:
        return float(self.state.physical.t[0])

    @property
    def y(self) -> np.ndarray:
        return self.state.physical.y.copy()

    @property
    def angles(self) -> np.ndarray:
        return self.state.physical.y[self.layout.q].copy()

    @property
    def angular_velocities(self) -> np.ndarray:
        return self.state.physical.y[self.layout.w].copy()

    @property
    def touching(self) -> bool:
        """Whether any pair can push now: in contact, or evaluated inline under step control. 0.4 µs, for a face that
        checks what only contact can do (a pair pressed too deep) after every step without a snapshot."""
        return bool(np.count_nonzero(self._contact_flags[0]) or np.count_nonzero(self._contact_flags[1]))

    @property
    def modes(self) -> np.ndarray:
        return self.state.physical.contacts["mode"].copy()

    @property
    def held_input(self) -> tuple[float, ...] | None:
        """The rachis acceleration (ACCEL_COMPONENTS) held since the last advance, or None: the scene's excitation."""
        rec = self.state.input[0]
        return tuple(float(rec[c]) for c in ACCEL_COMPONENTS) if rec["held"] else None

    @property
    def base_accel(self) -> tuple[float, ...]:
        """The rachis acceleration acting now (ACCEL_COMPONENTS: m/s², rad/s², world frame)."""
        held = self.held_input
        if held is not None:
            return held
        return tuple(float(v) for v in base_accel(self.excitation, self.t, self.t))

    @property
    def stats(self) -> dict[str, int | float]:
        return run_stats(self.state.book.counters, self.state.book.totals, self.layout, len(self.model.pairs))

    # --- what the faces report ---------------------------------------------------------------------
    def observe(self, out: obs.Observation | None = None) -> obs.Observation:
        """The observation of the current state (one sample), into `out` if given (reused per step)."""
        m, S = self.model, self.state
        if out is None:
            out = obs.empty(1, m.n_berries, m.n_dof, len(m.pairs))
        obs.observe(S.physical.y[None, :], S.physical.contacts[None, :], np.array([self.base_accel]), self.M, out)
        return out

    def snapshot(self) -> catalogue.Snapshot:
        """The current state as a one-sample Snapshot: what the catalogue's channels are computed from.

        Its arrays are the solver's own (views on the state and buffers refreshed here, like MuJoCo's mjData
        after mj_forward): read them before the next step, copy what you keep. A face pays one compiled call."""
        if self._refresh is None:
            self._refresh = entry(ses.refresh, self._session)
        self._refresh(self._session)
        snap = self._snapshot
        if snap is None:
            m, lay, y = self.model, self.layout, self.state.physical.y
            observation, accel, in_contact = self._outputs[1]
            snap = self._snapshot = catalogue.Snapshot(
                self.state.physical.t, y[None, lay.q], y[None, lay.w], in_contact, accel, displacement(lay, y[None]),
                angular_velocity(lay, y[None]), orientation(lay, y[None]), np.zeros((1, len(LEDGER_TERMS))),
                self.state.book.totals, observation, m.obstacle_pairs)
        ledger(self.layout, self.state.physical.y, out=snap.ledger[0])
        return snap

    def totals(self) -> np.ndarray:
        """What the run has done to the berries so far (state.TOTALS), a copy."""
        return self.state.book.totals.copy()

    # --- stepping --------------------------------------------------------------------------------
    def _integrate(self, t_target: float, recorder: st.Recorder, max_steps: int) -> int:
        return ses.run(self._session, recorder, t_target, max_steps)

    def _closed_into(self, rec: st.Recorder) -> None:
        """Move the impacts that ended out of the recorder."""
        n = int(rec.cursor["n_impacts"][0])
        if n:
            self._closed.append(rec.impacts[:n].copy())
            rec.cursor["n_impacts"] = 0

    def step(self) -> float:
        """Take one accepted step (it may end early at a contact switch or breakpoint); return the new time."""
        self._save()
        status = ses.resume(self._session, math.inf, 1)[0]
        if status not in (DONE, MAX_STEPS):
            self._fail(status)
        self._closed_into(self._outputs[0])
        return self.t

    def dense_output(self) -> Callable[[np.ndarray | float], np.ndarray]:
        """The continuous extension of the last step over [t_prev, t]: y(t) for t in that interval."""
        from .step import dense

        I = self.state.integrator
        t0, h = float(I.clock["t_prev"][0]), float(I.clock["h_last"][0])
        if not h > 0.0:
            raise SolverError("dense_output: no step taken yet (step(), advance() or run() first)")
        y0, q = I.y_prev.copy(), I.dense.copy()

        def y_of(t):
            th = (np.atleast_1d(np.asarray(t, dtype=float)) - t0) / h
            if not np.all((th >= -1e-12) & (th <= 1.0 + 1e-12)):
                raise SolverError(f"t: expected times in the last step, [{t0:.9g}, {t0 + h:.9g}] s, got {t!r}")
            out = np.empty((th.size, y0.size))
            for i, x in enumerate(th):
                dense(x, y0, q, h, out[i])
            return out if np.ndim(t) else out[0]

        return y_of

    def advance(self, dt: float, base_accel: tuple[float, ...] | None = None,
                angular_velocity: tuple[float, float, float] | None = None) -> None:
        """Integrate exactly dt seconds. With base_accel (ACCEL_COMPONENTS: a_x, a_y, a_z in m/s² and α_x, α_y,
        α_z in rad/s², world frame; a pair is the planar (a_x, a_z)) the rachis acceleration is held at that
        value over the interval (zero-order hold, as an FMU input or a ROS message gives it); without it the
        scene's excitation is used. angular_velocity (rad/s, world) sets the rachis' ω at the interval's start
        (a master that gives ω and α: ω is its value, α what it does until the next step). On failure the state
        is left unchanged.

        The common call (a float step, a tuple of six floats, ω None or a tuple of three floats) is checked inline
        and goes to the compiled side as one Session: a face's step costs under 2 µs more than its physics
        (docs/solver.md)."""
        if type(dt) is not float or not 0.0 < dt <= LONGEST_STEP:
            dt = _step_size(dt)
        if base_accel is None:
            held, a = False, _NO_ACCEL
        else:
            held, a = True, base_accel
            if type(a) is not tuple or len(a) != 6 or not (
                    type(a[0]) is float is type(a[1]) is type(a[2]) is type(a[3]) is type(a[4]) is type(a[5])):
                a = _held_accel(base_accel)
        if angular_velocity is None:
            omega_set, omega = False, _NO_OMEGA
        else:
            omega_set, omega = True, angular_velocity
            if type(omega) is not tuple or len(omega) != 3 or not (
                    type(omega[0]) is float is type(omega[1]) is type(omega[2])):
                omega = _angular_velocity(angular_velocity)
        if self._plane_normal is not None and (a[3] or a[4] or a[5] or omega[0] or omega[1] or omega[2]):
            self._check_input(a, omega)  # ranges first, then the plane
        self.refuse_stiff(dt)
        kept = len(self._closed)
        if self._advance is None:
            self._advance = entry(ses.advance, self._session, dt, held, a, omega_set, omega, self.max_steps)
        status, t_target, n_impacts = self._advance(self._session, dt, held, a, omega_set, omega, self.max_steps)
        if status == REFUSED:
            if self.t + dt == self.t:
                raise SolverError(f"dt: {dt!r} s does not move t = {self.t!r} s (below its resolution)")
            self._check_input(a, omega)
            raise SolverError(f"base_accel, angular_velocity: {a}, {omega} refused")  # _check_input said why
        while n_impacts:
            self._closed_into(self._outputs[0])
            if status != IMPACTS_FULL:
                break
            status, t_target, n_impacts = ses.resume(self._session, t_target, self.max_steps - self._steps_since_save())
        if status != DONE:
            del self._closed[kept:]
            self._fail(status)

    def run_span(self, t_end: float | None, output_interval: float | None) -> tuple[float, float]:
        """`run`'s end and output interval (the scene's where None), each refused with a SolverError that names it
        where it is out of range, or where the samples they make would not fit (solver/budget.py)."""
        s = self.scene.solver
        refuse_out_of_range(output_interval=output_interval)
        dt_out = s.output_interval if output_interval is None else float(output_interval)
        end = _finite(s.t_end if t_end is None else t_end)
        if end is None or not 0.0 <= end - self.t <= LONGEST_STEP:
            raise SolverError(f"t_end: expected a time from the solver's t = {self.t:.9g} s to {LONGEST_STEP:g} s "
                              f"after it, got {t_end!r}")
        check_samples(self.model, end - self.t, dt_out, "t_end", "output_interval")
        return end, dt_out

    def _steps_since_save(self) -> int:
        """Accepted steps since the state was last saved (a run's or a step's start): the count now less the one in
        the backup, read at the counters' place in it (for the step limit, after the loop returned early)."""
        counters = self.state.book.counters
        saved = np.frombuffer(self._backup, dtype=counters.dtype, count=1,
                              offset=counters.ctypes.data - self._memory.ctypes.data)
        return int(counters["steps"][0]) - int(saved["steps"][0])

    def refuse_stiff(self, span: float) -> None:
        """A SolverError, before a step, if the stiffest hinge alone (stiffness.refuse_stiff, which names it) or the
        fixed step needs more than max_steps over span; a test of one product when it does not."""
        if span * self._least_rate > self.max_steps:
            if self.fixed_step > 0.0:
                raise SolverError(f"fixed_step: {span:g} s in steps of {self.fixed_step:g} s is "
                                  f"{span / self.fixed_step:.3g} steps, more than max_steps = {self.max_steps}")
            refuse_stiff(self.model, self.tableau, self.integrator, span, self.layout.turning, self.max_steps)

    def _check_input(self, a: tuple[float, ...], omega: tuple[float, float, float]) -> None:
        """Refuse advance()'s input, naming what is wrong: a value out of its bounds (model/excitation.py), a move
        or turn of a rachis that does not move or turn, or, in a planar scene, a turn about another axis than the
        rachis' y."""
        _held_accel(a)
        _angular_velocity(omega)
        if not self.layout.turning and (a[3] or a[4] or a[5] or omega[0] or omega[1] or omega[2]):
            raise SolverError("base_accel, angular_velocity: this solver's rachis does not turn (its scene does "
                              "not turn it); build it with Solver(scene, driven=True) to drive rotation as an input")
        if not self.layout.moving and (a[0] or a[1] or a[2]):
            raise SolverError("base_accel: this solver's rachis does not move (its scene holds it still); build it "
                              "with Solver(scene, driven=True) to drive it as an input")
        n = self._plane_normal
        if n is not None and (off_axis(a[3:], n) or off_axis(omega, n)):
            name = "base_accel" if off_axis(a[3:], n) else "angular_velocity"
            raise SolverError(f"{name}: a planar cluster turns only about the rachis' y axis "
                              f"{tuple(round(float(c), 6) for c in n)} (world; normal to its plane), got "
                              f"{a[3:] if name == 'base_accel' else omega} (use spherical berries for any rotation)")

    def take_impacts(self) -> Impacts:
        """Impacts that ended since the last call (during step() or advance()), oldest first."""
        if not self._closed:
            return NO_IMPACTS  # the common case when a face steps: no new record to build
        rows, self._closed = self._closed, []
        return Impacts.from_records(concat(rows))

    def _save(self) -> None:
        self._backup[:] = self._memory

    def _fail(self, status: int) -> None:
        """Restore the state saved before the call that failed and say why (stopped())."""
        t, S = self.t, self.state
        why = stopped(status, float(S.integrator.clock["h"][0]), self.max_steps,
                      near_pole(S.physical.y, self.model.berries, self.model.dof),
                      contact_hint(self.model, S.physical.contacts, overlaps(S.physical.y, self.M)))
        hint = fixed_step_hint(self.model, self.tableau, self.integrator, self.fixed_step) if (
            status == NOT_FINITE and self.fixed_step > 0.0) else None
        if hint:
            why += f" ({hint})"
        self._memory[:] = self._backup
        raise SolverError(f"integration stopped at t = {t:.9g} s: {why}; the state is left at t = {self.t:.9g} s")

    def run(self, t_end: float | None = None, output_interval: float | None = None,
            progress: Callable[[float, float], None] | None = None) -> Run:
        """Integrate from the current time to t_end, recording samples every output_interval. On failure
        the state is left as it was before the call."""
        t_end, dt_out = self.run_span(t_end, output_interval)
        self.refuse_stiff(t_end - self.t)
        self._save()
        t_start = self.t
        rec = ses.recording(self._session, grid_last(t_start, t_end, dt_out, True) + 2, dt_out, t_end)
        cur = rec.cursor
        start = rec.logged.copy()
        chunks, changes, impacts = [], [], []  # what a full recorder handed over (rare: it is sized for the whole run)
        wall = time.perf_counter()
        # the step limit counts the accepted steps since the save, across the loop's returns (a full recorder
        # returns mid-chunk); a chunk's return lets progress be shown
        chunk, left = 5000, self.max_steps
        while True:
            status = self._integrate(t_end, rec, min(chunk, left))
            if status != DONE:
                left = self.max_steps - self._steps_since_save()
            if status == IMPACTS_FULL:
                impacts.append(rec.impacts[: int(cur["n_impacts"][0])].copy())
                cur["n_impacts"] = 0
                continue
            if status == OUT_FULL:
                n = int(cur["n_out"][0])
                chunks.append(tuple(a[:n].copy() for a in rec[:st.SAMPLED]))
                changes.append(self._changes(rec))
                cur["n_out"], cur["n_changes"] = 0, 0
                continue
            if status == MAX_STEPS:
                if progress:
                    progress(self.t, t_end)
                if left > 0:
                    continue
            break
        if status != DONE:
            self._fail(status)
        wall = time.perf_counter() - wall
        if progress:
            progress(self.t, t_end)
        chunks.append(tuple(a[: int(cur["n_out"][0])] for a in rec[:st.SAMPLED]))
        changes.append(self._changes(rec))
        impacts.append(rec.impacts[: int(cur["n_impacts"][0])])
        t, y, accel, totals = (concat([c[i] for c in chunks]) for i in range(st.SAMPLED))
        stats = self.stats | {"wall_time": wall, "method": self.method, "integrator": self.integrator,
                              "t_start": t_start, "rtol": self.rtol, "atol": self.atol, "fixed_step": self.fixed_step}
        ongoing = open_impacts(self.state.physical.contacts, self.state.book.pair, self.t)
        return Run(self.scene, t, y, ContactLog(start, concat(changes)), accel, totals,
                   Impacts.from_records(concat(impacts), ongoing),
                   self.state.book.pair["peak_force"].copy(), self.state.book.peak_tension.copy(), stats)

    @staticmethod
    def _changes(rec: st.Recorder) -> np.ndarray:
        """The contact changes a recorder holds (each at its sample of the run: loop.record_grid)."""
        return rec.changes[: int(rec.cursor["n_changes"][0])].copy()


def open_impacts(contacts: np.ndarray, book_pair: np.ndarray, t: float) -> np.ndarray:
    """The impacts still going on (pairs' CONTACT and BOOK_PAIR records), as rows that end at t (separation speed
    NaN)."""
    mode = contacts["mode"]
    if not mode.any():
        return np.zeros(0, dtype=st.IMPACT)
    ps = np.flatnonzero(mode)
    rows = np.zeros(len(ps), dtype=st.IMPACT)
    bp = book_pair[ps]
    for f in ("onset", "approach_speed", "bruising"):
        rows[f] = bp[f]
    rows["peak_force"], rows["peak_time"] = bp["impact_peak"], bp["impact_peak_time"]
    rows["pair"], rows["end"], rows["separation_speed"] = ps, t, np.nan
    rows["impulse"] = bp["impulse"] - bp["impulse_at_onset"]
    rows["dissipated"] = bp["dissipated"] - bp["dissipated_at_onset"]
    return rows


def run_stats(counters: np.ndarray, totals: np.ndarray, layout, n_pairs: int) -> dict[str, int | float]:
    """What a run's work was (COUNTERS and TOTALS records, (1,) each), as Run.stats names it: every counter under
    its own name but near_pairs_sum, given per step."""
    every = dict(zip(counters.dtype.names, counters[0].item()))  # one read: a field's costs about a microsecond
    c = {k: every[k] for k in WORK}
    return c | {"impacts": int(totals["collision_count"][0]), "degrees_of_freedom": layout.d, "candidate_pairs": n_pairs,
                "near_pairs_mean": every["near_pairs_sum"] / max(c["steps"], 1)}


def integrator_for(method: str, rtol: float, fixed_step: float, n_berries: int, driven: bool,
                   pinned: str = "auto") -> str:
    """The pair a run steps with, by name: the paper's imitation keeps ode23's; the event method takes the one a
    scene pins (solver.integrator), else the order its tolerance and its scene pay for (DOP853_BELOW,
    DOP853_BELOW_FEW). A fixed step has no tolerance to match and keeps DOPRI5."""
    if method != "event":
        return "ode23"
    if fixed_step > 0.0:
        return "DOPRI5"
    if pinned != "auto":
        return pinned
    below = DOP853_BELOW_FEW if n_berries < FEW_BERRIES and not driven else DOP853_BELOW
    return "DOP853" if rtol < below else "DOPRI5"


def tableau(integrator: str) -> Tableau:
    """The Tableau of a pair integrator_for names (looked up when asked, so that a test may replace one)."""
    return {"DOPRI5": DOPRI5, "DOP853": DOP853, "ode23": BOGACKI_SHAMPINE}[integrator]


def refuse_out_of_range(**given) -> None:
    """A SolverError naming the first argument given (not None) outside the range a scene file's [solver] table holds
    its key to (SolverSettings)."""
    for name, x in given.items():
        if x is None:
            continue
        b = bound(SolverSettings, name)
        counted = name == "max_steps"  # a count of steps: an integer
        v = _finite(x)
        if v is None or not b.holds(v) or (counted and not isinstance(x, Integral)):
            raise SolverError(f"{name}: expected {'an integer' if counted else 'a number'}"
                              f"{b.allowed[len('a number'):]}, got {x!r}")


def _finite(x) -> float | None:
    """x as a finite float, or None for anything else: a bool, a string, NaN, ±inf, an int beyond a float's range."""
    if type(x) is float:  # the common case, without the abstract classes' checks (a microsecond each)
        return x if math.isfinite(x) else None
    if isinstance(x, bool) or not isinstance(x, Real):
        return None
    try:
        v = float(x)
    except OverflowError:
        return None
    return v if math.isfinite(v) else None


def _step_size(dt) -> float:
    """dt as a float, or a SolverError: the checks behind advance's inline one, with the message."""
    v = _finite(dt)
    if v is None or not 0.0 < v <= LONGEST_STEP:
        raise SolverError(f"dt: expected a step in (0, {LONGEST_STEP:g}] s (the longest run, solver.t_end), "
                          f"got {dt!r}")
    return v


_NO_ACCEL = (0.0,) * 6
_NO_OMEGA = (0.0,) * 3


def _held_accel(base_accel) -> tuple[float, ...]:
    """ACCEL_COMPONENTS as floats (a pair is the planar (a_x, a_z)), or a SolverError naming what is wrong."""
    try:
        a = tuple(float(v) for v in base_accel)
    except (TypeError, ValueError):
        a = ()
    if len(a) == 2:
        a = (a[0], 0.0, a[1], 0.0, 0.0, 0.0)
    if len(a) != 6:
        raise SolverError(f"base_accel: expected six numbers ({', '.join(ACCEL_COMPONENTS)}) in m/s² and rad/s², or "
                          f"the planar pair (a_x, a_z), got {base_accel!r}")
    for name, v in zip(ACCEL_COMPONENTS, a):
        bound = MAX_ACCEL if name in ACCEL_COMPONENTS[:3] else MAX_ANGULAR_ACCEL
        if not (math.isfinite(v) and abs(v) <= bound):
            raise SolverError(f"base_accel: {name} = {v!r}; expected a finite value within ±{bound:g} "
                              f"{'m/s²' if name[0] == 'a' and len(name) == 2 else 'rad/s²'}")
    return a


def _angular_velocity(omega) -> tuple[float, float, float]:
    """ω as three floats, or a SolverError naming what is wrong."""
    try:
        w = tuple(float(v) for v in omega)
    except (TypeError, ValueError):
        w = ()
    if len(w) != 3 or not all(math.isfinite(v) and abs(v) <= MAX_ANGULAR_VELOCITY for v in w):
        raise SolverError(f"angular_velocity: expected three finite numbers (ω_x, ω_y, ω_z) within "
                          f"±{MAX_ANGULAR_VELOCITY:g} rad/s, got {omega!r}")
    return w

"""Residuals of measured angles against the event-driven solver, and their Jacobian, for a segment-wise fit.

Unknowns θ = (u, s): the parameters in their transformed scale (params.py) and, for every segment of every
measured series, the state its tracked angles start from (angle and rate). A series is cut into `segments`
pieces of about equal length. Each piece is integrated on its own, from its estimated tracked state; an
untracked angle, which nothing measures to restart from, starts where the previous piece left it (the scene's
initial state in the first piece). The shared parameters tie the pieces together. One segment is single
shooting with an estimated initial state.

Why segments: a collision makes the trajectory after it depend on the parameters through the collision's
timing, so over a long record with many collisions the misfit of a single shot becomes a rugged function
of the parameters (many local minima, a Jacobian that is large and unreliable). Restarting the tracked
berries from estimated states keeps each shot short. This is the segment-wise fit, the simplest sound form
of multiple shooting: the tracked states are not tied across segment boundaries (no continuity constraint),
which gives up a little information at each boundary (the measured frames pin those states anyway) but
keeps every residual a measured angle minus the model's and the statistics of the fit plain; the true
parameters and states reproduce the data exactly, so the estimator stays consistent. An untracked berry is
integrated across the whole record, so the segments do not shorten its shot: track every berry that
collides for a long record with many collisions. Measured (benchmarks/fit_segments.py, docs/fit_and_risk.md):
segments do not always widen the basin of convergence; a fit stuck in a local minimum is flagged by its
structured residuals (estimate.py).

Sensitivities: central finite differences. Adjoint or forward sensitivities of an event-driven solver need
the jump of the sensitivity at every contact onset and release, a second solver beside the first; the
differences reuse the solver as it is. The solution carries an error ε of about the relative tolerance, which
the solver keeps tight (FIT_RTOL); a central difference with step h has truncation error O(h²) and noise
O(ε/h), balanced at h = ε^(1/3) (STEP). A step that changes the sequence of contacts makes one column wrong;
so small a step rarely does, and a parameter whose column is exactly zero is reported as unidentifiable.
"""
from __future__ import annotations

import copy
import dataclasses
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np

from ..errors import GrapefmuError, SceneError, SolverError
from ..model import excitation as exc
from ..model.model import Scene
from ..scenefile import scene_from_dict
from ..solver.solver import Solver
from .measured import Measured
from .params import Parameter, scene_with

#: the solver's tolerances while fitting (tight: the finite differences divide the solution's error by the step)
FIT_RTOL, FIT_ATOL = 1e-10, 1e-12
#: a typical size of an angle (rad) and of an angular velocity (rad/s): the scale of a start state's step
TYPICAL = (0.1, 1.0)
#: the fewest frames a segment may have
MIN_FRAMES = 10


def step_for(rtol: float) -> float:
    """The central difference step in u (a relative step of p) for a solution accurate to about rtol."""
    return float(np.clip(rtol ** (1.0 / 3.0), 1e-6, 1e-2))


@dataclass(frozen=True)
class Segment:
    series: int            # which measured series
    k: int                 # its place in the series (0: the first)
    rows: np.ndarray       # its rows, the first at the segment's start
    until: int | None      # the next segment's first row, where the untracked state is handed on
    free: np.ndarray       # entries of the state (tracked angles, then their rates) estimated for this segment
    offset: int            # where its free entries start in θ


class Shots(NamedTuple):
    residuals: list[np.ndarray]       # per segment: model minus measured, rad, its finite measured angles
    fitted: list[np.ndarray]          # per segment: the model's tracked angles at its rows
    ends: list[np.ndarray | None]     # per segment: the state handed on to the next segment


class Shooting:
    """The residual vector r(θ) (model minus measured, rad, every finite measured angle once) and its Jacobian."""

    def __init__(self, doc: dict[str, Any], base_dir: Path, params: list[Parameter], series: list[Measured],
                 segments: int = 1, rtol: float = FIT_RTOL, atol: float = FIT_ATOL):
        self.doc, self.base_dir, self.params, self.series = copy.deepcopy(doc), base_dir, params, series
        self.rtol, self.atol, self.h = rtol, atol, step_for(rtol)
        self.u0 = np.array([p.start(doc) for p in params])
        self.model = self.scene(self.u0).model
        names = self.model.dof_names
        self.D = len(names)
        self.tracked = [np.array([names.index(d) for d in m.dofs]) for m in series]
        self.segments: list[Segment] = []
        offset = len(params)
        for s, m in enumerate(series):
            pieces = _split(m, segments)
            free = np.r_[self.tracked[s], self.D + self.tracked[s]]
            for k, rows in enumerate(pieces):
                until = int(pieces[k + 1][0]) if k + 1 < len(pieces) else None
                self.segments.append(Segment(s, k, rows, until, free, offset))
                offset += len(free)
        self.size = offset
        self.theta0 = self._start()
        self._cache: tuple[bytes, Shots] | None = None
        self.failures = 0  # trial points where the solver failed
        self.evaluations = 0
        self.progress: Callable[[int, float], None] | None = None  # (evaluations, residual rms in rad)

    # --- the model at θ ----------------------------------------------------------------------------------
    def scene(self, u: np.ndarray, series: int | None = None) -> Scene:
        """The scene with the parameters at u; for a series with a measured gripper motion, that motion."""
        sc = scene_from_dict(scene_with(self.doc, self.params, u), self.base_dir)
        m = None if series is None else self.series[series]
        if m is not None and m.accel is not None:
            rows = np.column_stack([m.t, m.accel])
            sc = dataclasses.replace(sc, excitation=exc.table("csv", rows, f"measured: {m.path.name}"))
        return sc

    def shoot(self, scene: Scene, t: np.ndarray, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Angles and rates of every angle at the times t, integrated from state x at t[0]."""
        dt = float(np.median(np.diff(t)))
        k = (t - t[0]) / dt
        on_grid = np.allclose(k, np.round(k), rtol=0.0, atol=1e-6)
        if not on_grid:
            dt /= 4.0  # samples between frames, then cubic Hermite (angles and rates) to each frame's time
        try:
            sc = dataclasses.replace(scene, angles=tuple(x[:self.D]), angular_velocities=tuple(x[self.D:]))
            solver = Solver(sc, rtol=self.rtol, atol=self.atol, t_start=float(t[0]))
        except SceneError as e:  # a trial start state outside the model's ranges (or overlapping far): a failed trial,
            raise SolverError(f"a trial start state is refused: {e}") from None  # as the solver's are
        run = solver.run(float(t[-1]) + 0.5 * dt, dt)
        q, w = run.angles, run.angular_velocities
        if on_grid:
            idx = np.round(k).astype(int)
            return q[idx], w[idx]
        return _hermite(run.t, q, w, t)

    def shots(self, theta: np.ndarray, redo: range | None = None, base: Shots | None = None) -> Shots:
        """Every segment's shot; with `redo`, only those segments, the others taken from `base`. A segment starts
        from its estimated tracked state and the untracked state the previous segment hands on (the scene's
        initial state for a first segment)."""
        u = theta[:len(self.params)]
        scenes: dict[int, Scene] = {}
        out = Shots([], [], [])
        for n, seg in enumerate(self.segments):
            if redo is not None and n not in redo:
                for mine, theirs in zip(out, base):
                    mine.append(theirs[n])
                continue
            if seg.series not in scenes:
                scenes[seg.series] = self.scene(u, seg.series)
            sc = scenes[seg.series]
            x = sc.initial_state.copy() if seg.k == 0 else out.ends[n - 1].copy()
            x[seg.free] = theta[seg.offset:seg.offset + len(seg.free)]
            m = self.series[seg.series]
            rows = seg.rows if seg.until is None else np.r_[seg.rows, seg.until]
            try:
                q, w = self.shoot(sc, m.t[rows], x)
            except SolverError as e:
                at = ", ".join(f"{p.key} = {float(p.to_p(v)):.4g}" for p, v in zip(self.params, u))
                raise SolverError(f"the solver failed with {at}: {e}") from None
            fitted = q[:len(seg.rows), self.tracked[seg.series]]
            r = fitted - m.angles[seg.rows]
            out.residuals.append(r[np.isfinite(r)])
            out.fitted.append(fitted)
            out.ends.append(None if seg.until is None else np.r_[q[-1], w[-1]])
        return out

    # --- residuals and Jacobian ---------------------------------------------------------------------------
    def residuals(self, theta: np.ndarray) -> np.ndarray:
        """r(θ). A trial point where the solver fails (a start state with berries deep in each other, say) gets
        residuals of π rad, far worse than any point least_squares has accepted, so it retreats from it."""
        key = np.asarray(theta, float).tobytes()
        if self._cache is None or self._cache[0] != key:
            try:
                self._cache = (key, self.shots(np.asarray(theta, float)))
                self.evaluations += 1
                if self.progress is not None:
                    r = np.concatenate(self._cache[1].residuals)
                    self.progress(self.evaluations, float(np.sqrt(np.mean(r * r))) if len(r) else 0.0)
            except SolverError:
                if self._cache is None:
                    raise
                self.failures += 1
                return np.full(sum(len(b) for b in self._cache[1].residuals), np.pi)
        return np.concatenate(self._cache[1].residuals)

    def jacobian(self, theta: np.ndarray) -> np.ndarray:
        """Central differences. A parameter's column re-runs every segment; a start state's column its own
        segment and, when the series leaves an angle untracked (whose state is handed on), the later ones."""
        theta = np.asarray(theta, float)
        base = self.shots(theta)
        sizes = np.cumsum([0] + [len(b) for b in base.residuals])
        J = np.zeros((sizes[-1], self.size))
        P = len(self.params)
        for j in range(self.size):
            redo = None
            h = self.h
            if j >= P:
                n = next(n for n, s in enumerate(self.segments) if s.offset <= j < s.offset + len(s.free))
                seg = self.segments[n]
                last = n + 1
                if len(self.tracked[seg.series]) < self.D:
                    while last < len(self.segments) and self.segments[last].series == seg.series:
                        last += 1
                redo = range(n, last)
                h *= max(abs(theta[j]), TYPICAL[int(seg.free[j - seg.offset] >= self.D)])
            cols = []
            for sign in (1.0, -1.0):
                th = theta.copy()
                th[j] += sign * h
                cols.append(self.shots(th, redo, base).residuals)
            rows = range(len(self.segments)) if redo is None else redo
            for n in rows:
                J[sizes[n]:sizes[n + 1], j] = (cols[0][n] - cols[1][n]) / (2 * h)
        return J

    def fitted(self, theta: np.ndarray) -> list[np.ndarray]:
        """The model's tracked angles at each segment's rows."""
        return self.shots(np.asarray(theta, float)).fitted

    # --- starting point ------------------------------------------------------------------------------------
    def _start(self) -> np.ndarray:
        """θ to start from: the parameters from the scene; a tracked angle and its rate from the frames around its
        segment's start (_angle_and_rate)."""
        theta = np.zeros(self.size)
        theta[:len(self.params)] = self.u0
        for seg in self.segments:
            m = self.series[seg.series]
            for n in range(len(m.dofs)):
                theta[seg.offset + n], theta[seg.offset + len(m.dofs) + n] = _angle_and_rate(
                    m.t, m.angles[:, n], int(seg.rows[0]))
        return theta


def _split(m: Measured, segments: int) -> list[np.ndarray]:
    """Rows of a series cut into about equal spans of time, each of at least MIN_FRAMES frames."""
    n = len(m.t)
    if n < segments * MIN_FRAMES:
        raise GrapefmuError(f"--segments {segments}: {m.path} has {n} frames; each segment needs at least "
                            f"{MIN_FRAMES}")
    edges = np.searchsorted(m.t, np.linspace(m.t[0], m.t[-1], segments + 1)[1:-1])
    return [np.arange(a, b) for a, b in zip(np.r_[0, edges], np.r_[edges, n])]


def _angle_and_rate(t: np.ndarray, q: np.ndarray, k: int, half: int = 2) -> tuple[float, float]:
    """A start for an angle and its rate at frame k: a quadratic through the tracked frames within `half` frames
    of it (centred where the series allows: a swing turns by a radian in a few frames, so a longer or one-sided
    window biases the rate), taken at t[k]."""
    lo, hi = max(k - half, 0), min(k + half + 1, len(t))
    if hi - lo < 2 * half + 1:  # at an end of the series: as many frames on the one side there is
        lo, hi = (0, min(2 * half + 1, len(t))) if lo == 0 else (max(len(t) - 2 * half - 1, 0), len(t))
    ok = np.arange(lo, hi)[np.isfinite(q[lo:hi])]
    if len(ok) < 3:
        near = np.flatnonzero(np.isfinite(q))
        return float(q[near[np.argmin(np.abs(near - k))]]), 0.0
    c = np.polyfit(t[ok] - t[k], q[ok], 2)
    return float(c[2]), float(c[1])


def _hermite(ts: np.ndarray, q: np.ndarray, w: np.ndarray, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Cubic Hermite interpolation of angles (values and derivatives known at the samples) to the times t."""
    k = np.clip(np.searchsorted(ts, t, side="right") - 1, 0, len(ts) - 2)
    h = (ts[k + 1] - ts[k])[:, None]
    s = ((t - ts[k])[:, None]) / h
    h00, h10, h01, h11 = 2 * s**3 - 3 * s**2 + 1, s**3 - 2 * s**2 + s, -2 * s**3 + 3 * s**2, s**3 - s**2
    qi = h00 * q[k] + h10 * h * w[k] + h01 * q[k + 1] + h11 * h * w[k + 1]
    d00, d10, d01, d11 = 6 * s**2 - 6 * s, 3 * s**2 - 4 * s + 1, -6 * s**2 + 6 * s, 3 * s**2 - 2 * s
    wi = (d00 * q[k] + d01 * q[k + 1]) / h + d10 * w[k] + d11 * w[k + 1]
    return qi, wi

"""Base excitation: the motion of the rachis held by the gripper, as its acceleration (a(t), α(t)) in the world
frame (physics/excitation.ACCEL_COMPONENTS) from an initial orientation and angular velocity.

Every kind compiles to one of three numeric forms that physics/excitation.py evaluates:
a constant, a windowed chirp
(sine, sweep and half-sine impulse are chirps), or a piecewise-linear table
(jerk-limited pick-and-place moves and CSV files). Each form lists its breakpoints,
where a(t) or its derivative jumps; the solver lands a step on every one of them.
"""
from __future__ import annotations

import csv
import functools
import io
import math
from dataclasses import dataclass, field, replace
from numbers import Real
from pathlib import Path
from typing import NamedTuple

import numpy as np

from ..errors import SceneError
from .bounds import Bound

CONSTANT, CHIRP, TABLE = 0, 1, 2

#: the largest rachis motion any scene or face accepts (beyond any gripper or robot wrist, so a unit mistake):
#: linear acceleration m/s² (about 100 g), angular acceleration rad/s², angular velocity rad/s (about 1000 rpm)
MAX_ACCEL, MAX_ANGULAR_ACCEL, MAX_ANGULAR_VELOCITY = 1e3, 1e4, 1e2


class ExcitationArrays(NamedTuple):
    """What the compiled core reads: kind code, parameters, table rows (t, a_x, a_y, a_z, α_x, α_y, α_z),
    breakpoints."""

    kind: int
    par: np.ndarray
    table: np.ndarray
    breaks: np.ndarray


@dataclass(frozen=True)
class Excitation:
    """A validated excitation. `kind` is the scene's name for it; `arrays` is its compiled form. `defined_until`:
    the time after which the scene does not say what the gripper does (a CSV's last row, without `after`);
    a run past it is refused (check_covers). `orientation` (the quaternion (x, y, z, w) of R, world from rachis)
    and `angular_velocity` (ω, world, rad/s) are the rachis' at the start; it starts at the world origin at rest
    in translation."""

    kind: str
    arrays: ExcitationArrays
    description: str = ""
    defined_until: float = math.inf
    key: str = "excitation"   # the scene key that gives a table (file, text, moves), named when it is refused
    orientation: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 1.0)
    angular_velocity: tuple[float, float, float] = (0.0, 0.0, 0.0)
    driven: bool = False  # a face's inputs may move and turn the rachis, whatever this excitation does
    #: the CSV text a csv or pose-table excitation was read from: a recording carries it in its scene (scene_toml)
    text: str = field(default="", repr=False)

    @functools.cached_property
    def turns(self) -> bool:
        """Whether the rachis' orientation is ever other than level: it starts turned or turning, the excitation
        turns it, or a face may (`driven`). A run's state carries ω and the orientation only then. Cached (the
        excitation is frozen): every Solver and layout asks, several times a run."""
        return self._any(slice(3, 6)) or any(w != 0.0 for w in self.angular_velocity) or any(
            c != 0.0 for c in self.orientation[:3])

    @functools.cached_property
    def moves(self) -> bool:
        """Whether the rachis ever leaves the origin or turns: a run's state carries its ḃ and b only then (the
        paper's scenes hold it still)."""
        return self.turns or self._any(slice(0, 3))

    def _any(self, columns: slice) -> bool:
        """Whether a face drives the rachis or any of these acceleration components is ever non-zero."""
        a = self.arrays
        rows = a.table[:, 1:7] if a.kind == TABLE else a.par[:6]
        return bool(self.driven or np.any(rows[..., columns] != 0.0))

    def starting(self, orientation=None, angular_velocity=None) -> "Excitation":
        """This excitation from another initial orientation (quaternion x, y, z, w) or angular velocity."""
        return replace(self, orientation=tuple(map(float, orientation if orientation is not None else self.orientation)),
                       angular_velocity=tuple(map(float, angular_velocity if angular_velocity is not None
                                                  else self.angular_velocity)))


def rotation_matrix(qx, qy, qz, qw):
    """R (row-major, 9 numbers) of the quaternion (x, y, z, w), normalised here: the one formula, in plain Python
    for the model's checks and compiled into the core's rachis frame (physics/kinematics.py)."""
    s = 2.0 / (qx * qx + qy * qy + qz * qz + qw * qw)
    return (1.0 - s * (qy * qy + qz * qz), s * (qx * qy - qz * qw), s * (qx * qz + qy * qw),
            s * (qx * qy + qz * qw), 1.0 - s * (qx * qx + qz * qz), s * (qy * qz - qx * qw),
            s * (qx * qz - qy * qw), s * (qy * qz + qx * qw), 1.0 - s * (qx * qx + qy * qy))


def quaternion_from_rpy(roll: float, pitch: float, yaw: float) -> tuple[float, float, float, float]:
    """The quaternion (x, y, z, w) of fixed-axis roll, pitch, yaw (REP-103: R = R_z(yaw) R_y(pitch) R_x(roll))."""
    from scipy.spatial.transform import Rotation
    return tuple(float(c) for c in Rotation.from_euler("xyz", [roll, pitch, yaw]).as_quat())


#: the shortest step the solver takes, per second of max(1 s, |t|) (1.6e-14 s up to t = 1 s): a step its error control
#: would make shorter ends the run, "the step size fell below the resolution of time" (solver/loop.py), and a table's
#: rows, on each of which it lands a step, must lie at least this far apart (check_row_spacing)
TIME_RESOLUTION = 16e-15

#: what a CSV excitation does after its last row (the scene's `after`): keep the last row's acceleration, or zero
AFTER = ("hold", "zero")
#: the time of the row that carries a held last value on "forever" (beyond any run's t_end)
FOREVER = 1e9


def check_covers(ex: Excitation, t_end: float, t_key: str) -> None:
    """Refuse a run to t_end (named by t_key) past the end of a table the scene gives no `after` for."""
    if t_end > ex.defined_until * (1 + 1e-12) + 1e-12:
        raise SceneError(ex.key, f"the CSV ends at {ex.defined_until:g} s, before the run's end {t_end:g} s "
                                 f"({t_key}); say what follows its last row with after = \"hold\" (keep its "
                                 f"acceleration) or after = \"zero\" in [excitation], or extend the file")


def check_times(t: np.ndarray, path: str, key: str) -> None:
    """Refuse a table (its file or text at `path`, under the scene key `key`) whose times do not start at or after 0 s
    and increase strictly from row to row, naming the row (counted from 1, after any header)."""
    back = np.flatnonzero(np.diff(t) <= 0.0)
    if back.size:
        n = int(back[0]) + 1  # 0-based: the row not after the one above it
        raise SceneError(key, f"{path} row {n + 1} column time: {float(t[n])!r} s is not after row {n}'s "
                              f"{float(t[n - 1])!r} s (times must increase strictly: sort the rows, drop repeated ones)")
    if t[0] < 0:
        raise SceneError(key, f"{path} row 1 column time: {float(t[0])!r} s; the table must start at or after 0 s")


def check_row_spacing(t: np.ndarray, path: str, key: str) -> None:
    """Refuse a table whose rows (times sorted, from 0 s) come closer together than the solver steps, naming the row.
    The solver lands a step on every row (each is a breakpoint), and its error control takes none shorter than
    TIME_RESOLUTION · max(1 s, t) (1.6e-14 s up to t = 1 s; solver/loop.py). Rows closer than that (5e-324 or 1e-300
    s apart) make the starting step toward the next row overflow initial_step's probe to 0 s, which the solver
    refuses as a step below the resolution of time, a reason about stiffness that names no key (it once took 10⁷
    steps of 0 s to the step limit). A first row after 0 s is held as far from the run's start (the table is zero
    before it). A table sampled at 1 kHz or 10 kHz is ten orders of magnitude clear of the floor; one 1e-20 s apart
    that happened to run is refused too: no recorded signal is sampled at 6e13 Hz. A time repeated on the next row
    is one breakpoint (a staircase's doubled knot: zero_order_hold); a time before the row above's is refused."""
    rows = np.flatnonzero(np.concatenate([[True], np.diff(t) != 0.0]))  # each breakpoint's first row
    t = t[rows]
    start = np.concatenate([[0.0], t[:-1]]) if t[0] > 0.0 else t[:-1]
    end = t if t[0] > 0.0 else t[1:]
    least = TIME_RESOLUTION * np.maximum(1.0, start)
    bad = np.flatnonzero(end - start < least)
    if bad.size:
        k = int(bad[0])
        row = int(rows[k if t[0] > 0.0 else k + 1]) + 1  # the later row, counted from 1 as the other errors count them
        what = "the run's start" if t[0] > 0.0 and k == 0 else f"row {row - 1}'s {float(start[k])!r} s"
        raise SceneError(key, f"{path} row {row} column time: {float(end[k])!r} s is {end[k] - start[k]:.3g} s after "
                              f"{what}; rows must be at least {least[k]:.3g} s apart ({TIME_RESOLUTION:g} s per "
                              "second of max(1 s, time): the shortest step the solver takes, and it lands one on "
                              "every row)")


def vector3(v) -> tuple[float, float, float]:
    """A linear acceleration as (x, y, z): a 2-vector is the planar (x, z)."""
    v = tuple(float(c) for c in v)
    return (v[0], 0.0, v[1]) if len(v) == 2 else v


_NO_TABLE = np.zeros((1, 7))


def constant(accel=(0.0, 0.0, 0.0), angular_accel=(0.0, 0.0, 0.0)) -> Excitation:
    """The rachis accelerating at a constant a (m/s², a 2-vector is (x, z)) and α (rad/s²), world frame."""
    par = np.array([*vector3(accel), *angular_accel], dtype=float)
    return Excitation("none" if not par.any() else "constant",
                      ExcitationArrays(CONSTANT, par, _NO_TABLE, np.zeros(0)))


def chirp(kind: str, amplitude, f_start: float, f_stop: float, start: float, duration: float,
          angular_amplitude=(0.0, 0.0, 0.0)) -> Excitation:
    """(a, α) = (amplitude, angular_amplitude) sin(2π(f₀τ + ½(f₁ − f₀)τ²/T)) for τ = t − start in [0, T)."""
    amp = (*vector3(amplitude), *(float(c) for c in angular_amplitude))
    par = np.array([*amp, f_start, f_stop, start, duration])
    breaks = np.array([start, start + duration])
    turn = f", angular {tuple(amp[3:])} rad/s²" if any(amp[3:]) else ""
    desc = f"{kind}: amplitude {tuple(amp[:3])} m/s²{turn}, {f_start:g}→{f_stop:g} Hz from {start:g} s for {duration:g} s"
    return Excitation(kind, ExcitationArrays(CHIRP, par, _NO_TABLE, breaks), desc)


def impulse(peak, start: float, duration: float, angular_peak=(0.0, 0.0, 0.0)) -> Excitation:
    """A half-sine acceleration pulse: a chirp at 1/(2·duration) Hz over half a period."""
    f = 0.5 / duration
    ex = chirp("impulse", peak, f, f, start, duration, angular_peak)
    return Excitation("impulse", ex.arrays, f"impulse: half-sine {tuple(vector3(peak))} m/s² peak, {duration:g} s at "
                                            f"{start:g} s")


def table(kind: str, rows: np.ndarray, description: str = "") -> Excitation:
    """A piecewise-linear table of rows (t, a_x, a_y, a_z, α_x, α_y, α_z); rows (t, a_x, a_z) are planar."""
    rows = np.asarray(rows, dtype=float)
    if rows.shape[1] == 3:
        rows = np.column_stack([rows[:, 0], rows[:, 1], np.zeros(len(rows)), rows[:, 2], np.zeros((len(rows), 3))])
    rows = np.ascontiguousarray(rows)
    return Excitation(kind, ExcitationArrays(TABLE, np.zeros(10), rows, rows[:, 0].copy()), description)


def _unit_move_profile(jerk_fraction: float) -> tuple[np.ndarray, np.ndarray]:
    """Normalised knots (u in [0, 1]) and accelerations of one jerk-limited rest-to-rest move:
    a trapezoidal acceleration pulse then its mirror, ramps lasting `jerk_fraction` of the move."""
    j = jerk_fraction
    u = np.array([0.0, j, 0.5 - j, 0.5, 0.5 + j, 1.0 - j, 1.0])
    a = np.array([0.0, 1.0, 1.0, 0.0, -1.0, -1.0, 0.0])
    return u, a


def integrate_table(rows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Exact velocity and displacement at the knots of a piecewise-linear acceleration table, from rest, for each
    column after the time."""
    t, a = rows[:, 0], rows[:, 1:]
    v = np.zeros_like(a)
    x = np.zeros_like(a)
    for k in range(1, len(t)):
        h = t[k] - t[k - 1]
        v[k] = v[k - 1] + 0.5 * h * (a[k - 1] + a[k])
        x[k] = x[k - 1] + h * v[k - 1] + h * h * (a[k - 1] / 3.0 + a[k] / 6.0)
    return v, x


#: a pick-and-place move's acceleration ramps, as a fraction of its duration: at most a quarter (four ramps fill the
#: move), at least 0.001 (a scene's move lasts at least 1e-3 s, so a ramp 1e-6 s, far from the 1e-15 s within which
#: pick_and_place merges knots and from the solver's step floor, TIME_RESOLUTION: ramps that short were dropped, and
#: a move ended off its displacement and still moving, tests/test_scene_errors.py)
JERK_FRACTION = Bound(1e-3, 0.25)


def pick_and_place(moves, start: float = 0.0, jerk_fraction: float = 0.125) -> Excitation:
    """Rest-to-rest moves in sequence, each (displacement, duration) or (displacement, duration, rotation):
    displacement (dx, dy, dz) in m (a pair is the planar (dx, dz)), rotation a rotation vector (rad, world axes:
    the rachis turns by |rotation| about that fixed axis during the move; a tilt, a swing round).

    A move of zero displacement and rotation is a dwell. The linear and the angular acceleration are piecewise
    linear and share one profile, so jerk is bounded, the gripper starts and ends every move at rest, and the
    rachis follows the moves exactly (to the solver's tolerance: a turn about a fixed axis integrates exactly).
    """
    if isinstance(jerk_fraction, bool) or not isinstance(jerk_fraction, Real) or not JERK_FRACTION.holds(
            jerk_fraction):
        raise SceneError("excitation.jerk_fraction", f"expected {JERK_FRACTION.allowed}, got {jerk_fraction!r}")
    u, shape = _unit_move_profile(jerk_fraction)
    _, x_unit = integrate_table(np.column_stack([u, shape]))
    reach = x_unit[-1, 0]  # displacement of a unit-peak, unit-duration move
    rows = [[0.0] * 7] if start > 0 else []
    t0 = start
    for move in moves:
        d, dur = vector3(move[0]), float(move[1])
        turn = np.asarray(move[2] if len(move) > 2 else (0.0, 0.0, 0.0), dtype=float)
        per_peak = np.array([*d, *turn]) / (reach * dur * dur)  # each component's peak acceleration
        for uk, sk in zip(u, shape):
            tk = t0 + uk * dur
            if rows and abs(rows[-1][0] - tk) < 1e-15:
                continue
            rows.append([tk, *(per_peak * sk)])
        t0 += dur
    desc = f"pick-and-place: {len(moves)} moves, {t0 - start:g} s from {start:g} s"
    return replace(table("pick-and-place", np.array(rows), desc), key="excitation.moves")


def read_csv(text: str, path: str, key: str, hold: bool = False, after: str | None = None) -> Excitation:
    """A CSV (its text, read from `path`: the file, or the scene key that holds it inline) of time, ax, az, or of
    time, ax, ay, az, alpha_x, alpha_y, alpha_z (m/s², rad/s², world frame; a header row allowed); linear in
    between (or held from each row to the next with hold = true, as a sampled controller output is), zero before
    the first row. After the last row: its acceleration kept (after = "hold"), zero (after = "zero"), or, without
    `after`, undefined: a run that goes past it is refused (check_covers)."""
    raw = _csv_rows(text, path, key, "CSV of time, ax, az")
    if raw and not _is_number(raw[0][0]):
        raw = raw[1:]
    if len(raw) < 2:
        raise SceneError(key, f"{path}: need at least two rows of time, ax, az")
    rows = []
    width = len(raw[0])
    for n, r in enumerate(raw, start=1):
        if len(r) != width or width not in (3, 7) or not all(_is_number(c) for c in r):
            raise SceneError(key, f"{path} row {n}: expected three numbers time, ax, az or seven time, ax, ay, az, "
                                  f"alpha_x, alpha_y, alpha_z (as in row 1), got {r!r}")
        vals = [float(c) for c in r]
        if not all(math.isfinite(v) for v in vals):
            raise SceneError(key, f"{path} row {n}: values must be finite, got {r!r}")
        rows.append(vals)
    arr = np.array(rows)
    check_times(arr[:, 0], path, key)
    check_row_spacing(arr[:, 0], path, key)
    if hold:
        arr = zero_order_hold(arr)
    last = float(arr[-1, 0])
    if after == "hold":
        arr = np.vstack([arr, [max(FOREVER, 2 * last), *arr[-1, 1:]]])
    desc = (f"csv: {Path(path).name}, {len(rows)} rows{' (held)' if hold else ''}"
            + (f", then {after}" if after else ""))
    ex = table("csv", arr, desc)
    return Excitation(ex.kind, ex.arrays, ex.description, math.inf if after else last, key, text=text)


#: a pose table's columns: time and position, then an orientation as fixed-axis roll, pitch, yaw (REP-103) or a
#: quaternion
POSE_COLUMNS = ("time", "x", "y", "z")
ORIENTATIONS = (("roll", "pitch", "yaw"), ("qx", "qy", "qz", "qw"))


#: sub-intervals per row interval of a pose table that turns about a moving axis (its α is not piecewise linear
#: there, and the compiled table is): benchmarks/pose_table_error.py gives the error this leaves
POSE_TURN_SUBDIVISION = 4


def read_pose_table(text: str, path: str, key: str) -> Excitation:
    """The gripper's recorded poses (CSV with a header: time, x, y, z and roll, pitch, yaw or qx, qy, qz, qw; m,
    rad, s; its text, read from `path`, a file or the scene key that holds it inline) as the rachis motion.

    Positions: a cubic spline with zero velocity at both ends (C2: its acceleration is piecewise linear, so the
    excitation is exactly a linear acceleration table and the rachis follows the spline to the solver's
    tolerance; the spline's error against a smooth motion sampled every h is O(h⁴)). Orientations: the rotation
    vector φ(t) of R₀ᵀ R(t) (R₀ the first row's; unwrapped through ±π) by the same clamped spline, so the
    orientation R₀ exp(φ(t)) is C2 with zero angular velocity at both ends. The rachis' angular acceleration is
    α = R ω̇_b, ω_b = J_r(φ) φ̇ (J_r the right Jacobian of SO(3)): piecewise linear for a turn about one fixed
    axis (exact, like the positions); about a moving axis it is tabulated at POSE_TURN_SUBDIVISION points per
    row interval and linear in between. The world frame is the table's, shifted so that the rachis starts at its
    origin; it starts in the first row's orientation; before the first row and after the last it rests."""
    from scipy.interpolate import CubicSpline
    from scipy.spatial.transform import Rotation

    raw = _csv_rows(text, path, key, "CSV pose table")
    if not raw:
        raise SceneError(key, f"{path}: empty; expected a header {', '.join(POSE_COLUMNS)}, then roll, pitch, yaw "
                              "or qx, qy, qz, qw")
    header = [c.strip() for c in raw[0]]
    orientation = next((o for o in ORIENTATIONS if header == [*POSE_COLUMNS, *o]), None)
    if orientation is None:
        raise SceneError(key, f"{path}: header {', '.join(header)}; expected {', '.join(POSE_COLUMNS)} and then "
                              f"{', '.join(ORIENTATIONS[0])} (rad, fixed axes) or {', '.join(ORIENTATIONS[1])}")
    if len(raw) < 3:
        raise SceneError(key, f"{path}: need at least two rows of poses")
    rows = []
    for n, r in enumerate(raw[1:], start=1):
        if len(r) != len(header):
            raise SceneError(key, f"{path} row {n}: expected {len(header)} values, got {len(r)}")
        for c, cell in zip(header, r):
            if not _is_number(cell) or not math.isfinite(float(cell)):
                raise SceneError(key, f"{path} row {n} column {c}: expected a finite number, got {cell!r}")
        rows.append([float(c) for c in r])
    arr = np.array(rows)
    t = arr[:, 0]
    check_times(t, path, key)
    if orientation == ORIENTATIONS[1]:
        norm = np.linalg.norm(arr[:, 4:8], axis=1)
        bad = np.flatnonzero(np.abs(norm - 1.0) > 1e-6)
        if bad.size:
            raise SceneError(key, f"{path} row {bad[0] + 1} column qw: the quaternion's norm is {norm[bad[0]]:.9g}; "
                                  "expected a unit quaternion (within 1e-6)")
        rot = Rotation.from_quat(arr[:, 4:8])
    else:
        rot = Rotation.from_euler("xyz", arr[:, 4:7])
    phi = _unwrapped((rot[0].inv() * rot).as_rotvec())
    try:
        with np.errstate(all="ignore"):
            spline = CubicSpline(t, arr[:, 1:4], bc_type="clamped")
            turn = CubicSpline(t, phi, bc_type="clamped")
            accel = spline(t, 2)
    except ValueError:
        accel = np.full((len(t), 3), math.nan)
    untimely = SceneError(key, f"{path} column time: the times ({t[0]:g} to {t[-1]:g} s, steps down to "
                               f"{np.diff(t).min():g} s) are too close together or too far apart to interpolate")
    if not np.isfinite(accel).all():  # steps of 1e-323 s, or a table spanning 1e155 s: no spline follows them
        raise untimely
    check_row_spacing(t, path, key)  # poses 1e-300 s apart that the spline follows, standing still
    worst = int(np.argmax(np.abs(accel).max(axis=1)))
    if np.abs(accel[worst]).max() > MAX_ACCEL:
        raise SceneError(key, f"{path} row {worst + 1} columns x, y, z: following these positions needs "
                              f"{np.abs(accel[worst]).max():.3g} m/s² (more than {MAX_ACCEL:g}): a jump the "
                              "interpolation cannot follow (a glitch, or positions in mm?)")
    axis = phi[np.argmax(np.linalg.norm(phi, axis=1))]
    fixed_axis = not axis.any() or np.abs(np.cross(phi, axis)).max() <= 1e-12 * max(np.linalg.norm(axis), 1.0)
    knots = t if fixed_axis else np.concatenate(
        [np.linspace(a, b, POSE_TURN_SUBDIVISION, endpoint=False) for a, b in zip(t[:-1], t[1:])] + [t[-1:]])
    try:
        with np.errstate(all="ignore"):
            alpha = _angular_accel(turn, rot[0], knots)
    except ValueError:  # the spline's rotation vectors overflowed (a span of 1e155 s or more)
        raise untimely from None
    if not np.isfinite(alpha).all():
        raise untimely
    worst = int(np.argmax(np.abs(alpha).max(axis=1)))
    if np.abs(alpha[worst]).max() > MAX_ANGULAR_ACCEL:
        row = int(np.searchsorted(t, knots[worst], side="right"))
        raise SceneError(key, f"{path} row {row} columns {', '.join(orientation)}: following these orientations needs "
                              f"{np.abs(alpha[worst]).max():.3g} rad/s² (more than {MAX_ANGULAR_ACCEL:g}): a jump the "
                              "interpolation cannot follow (a glitch, or angles in degrees?)")
    desc = (f"pose table: {Path(path).name}, {len(t)} poses from {t[0]:g} to {t[-1]:g} s, cubic splines of position "
            f"and rotation vector{'' if fixed_axis else f' (α at {POSE_TURN_SUBDIVISION} points per row)'}")
    ex = table("pose-table", np.column_stack([knots, spline(knots, 2), alpha]), desc)
    q0 = tuple(float(c) for c in rot[0].as_quat())
    return Excitation(ex.kind, ex.arrays, ex.description, math.inf, key, q0, text=text)


def _unwrapped(phi: np.ndarray) -> np.ndarray:
    """Rotation vectors made continuous: each row the one of its equivalents û (θ + 2πk), k any integer, nearest the
    previous row's (as_rotvec keeps θ = |φ| ≤ π, so a turn through π would jump), so a table may turn any number of
    times. The identity's (θ = 0) are the multiples of 2π along any axis: along the previous row's."""
    out = phi.copy()
    for k in range(1, len(out)):
        prev, theta = out[k - 1], float(np.linalg.norm(out[k]))
        if theta > 0.0:
            u = out[k] / theta
        elif prev.any():
            u = prev / np.linalg.norm(prev)
        else:
            continue
        turns = round((float(u @ prev) - theta) / (2.0 * math.pi))  # the nearest, or one beside it
        out[k] = min((u * (theta + 2.0 * math.pi * m) for m in (turns - 1, turns, turns + 1)),
                     key=lambda c: float(np.linalg.norm(c - prev)))
    return out


def _body_rate(phi: np.ndarray, dphi: np.ndarray) -> np.ndarray:
    """ω_b = J_r(φ) φ̇ (rows), the body angular velocity of R₀ exp(φ)."""
    theta = np.linalg.norm(phi, axis=1, keepdims=True)
    small = theta < 1e-6
    th = np.where(small, 1.0, theta)
    a = np.where(small, 0.5 - theta ** 2 / 24.0, (1.0 - np.cos(th)) / th ** 2)
    b = np.where(small, 1.0 / 6.0 - theta ** 2 / 120.0, (th - np.sin(th)) / th ** 3)
    c1 = np.cross(phi, dphi)
    return dphi - a * c1 + b * np.cross(phi, c1)


def _angular_accel(turn, r0, t: np.ndarray) -> np.ndarray:
    """α(t) = R ω̇_b (world frame) of the orientation R₀ exp(φ(t)), φ the spline `turn`: ω̇_b by a central
    difference of the exact ω_b (Rω̇_b: Ṙ ω_b = R (ω_b × ω_b) = 0), inside the spline's own pieces."""
    from scipy.spatial.transform import Rotation
    h = 1e-6 * max(float(t[-1] - t[0]), 1e-3)
    lo, hi = np.maximum(t - h, t[0]), np.minimum(t + h, t[-1])
    wdot = (_body_rate(turn(hi), turn(hi, 1)) - _body_rate(turn(lo), turn(lo, 1))) / (hi - lo)[:, None]
    return (r0 * Rotation.from_rotvec(turn(t))).apply(wdot)


def zero_order_hold(rows: np.ndarray) -> np.ndarray:
    """A staircase as a piecewise-linear table: each value repeated at the next row's time.
    The solver picks the piece from the step's start, so the duplicated knot is never ambiguous."""
    t, a = rows[:, 0], rows[:, 1:]
    out = np.empty((2 * len(rows) - 1, rows.shape[1]))
    out[0::2, 0] = t
    out[0::2, 1:] = a
    out[1::2, 0] = t[1:]
    out[1::2, 1:] = a[:-1]
    return out


def _csv_rows(text: str, path: str, key: str, what: str) -> list[list[str]]:
    """The rows of a CSV text, comment lines (#) left out; a malformed one is a SceneError on `key`."""
    try:
        return [r for r in csv.reader(io.StringIO(text, newline="")) if r and not r[0].lstrip().startswith("#")]
    except csv.Error as exc:
        raise SceneError(key, f"{path}: not a {what} ({exc})") from None


def _is_number(s: str) -> bool:
    try:
        float(s)
    except ValueError:
        return False
    return True

"""Base excitation: the acceleration a(t) = (a_x, a_z) of the rachis held by the gripper.

Every kind compiles to one of three numeric forms that physics/excitation.py evaluates:
a constant, a windowed chirp
(sine, sweep and half-sine impulse are chirps), or a piecewise-linear table
(jerk-limited pick-and-place moves and CSV files). Each form lists its breakpoints,
where a(t) or its derivative jumps; the solver lands a step on every one of them.
"""
from __future__ import annotations

import csv
import math
from dataclasses import dataclass
from pathlib import Path
from typing import NamedTuple

import numpy as np

from ..errors import SceneError

CONSTANT, CHIRP, TABLE = 0, 1, 2


class ExcitationArrays(NamedTuple):
    """What the compiled core reads: kind code, parameters, table rows (t, a_x, a_z), breakpoints."""

    kind: int
    par: np.ndarray
    table: np.ndarray
    breaks: np.ndarray


@dataclass(frozen=True)
class Excitation:
    """A validated excitation. `kind` is the scene's name for it; `arrays` is its compiled form. `defined_until`:
    the time after which the scene does not say what the gripper does (a CSV's last row, without `after`);
    a run past it is refused (check_covers)."""

    kind: str
    arrays: ExcitationArrays
    description: str = ""
    defined_until: float = math.inf
    key: str = "excitation"   # the scene key to name when a run goes past defined_until


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


def constant(ax: float = 0.0, az: float = 0.0) -> Excitation:
    par = np.zeros(6)
    par[0], par[1] = ax, az
    return Excitation("none" if ax == az == 0.0 else "constant",
                      ExcitationArrays(CONSTANT, par, np.zeros((1, 3)), np.zeros(0)))


def chirp(kind: str, amplitude: tuple[float, float], f_start: float, f_stop: float,
          start: float, duration: float) -> Excitation:
    par = np.array([amplitude[0], amplitude[1], f_start, f_stop, start, duration])
    breaks = np.array([start, start + duration])
    desc = f"{kind}: amplitude {amplitude} m/s², {f_start:g}→{f_stop:g} Hz from {start:g} s for {duration:g} s"
    return Excitation(kind, ExcitationArrays(CHIRP, par, np.zeros((1, 3)), breaks), desc)


def impulse(peak: tuple[float, float], start: float, duration: float) -> Excitation:
    """A half-sine acceleration pulse: a chirp at 1/(2·duration) Hz over half a period."""
    f = 0.5 / duration
    ex = chirp("impulse", peak, f, f, start, duration)
    return Excitation("impulse", ex.arrays, f"impulse: half-sine {peak} m/s² peak, {duration:g} s at {start:g} s")


def table(kind: str, rows: np.ndarray, description: str = "") -> Excitation:
    rows = np.ascontiguousarray(rows, dtype=float)
    return Excitation(kind, ExcitationArrays(TABLE, np.zeros(6), rows, rows[:, 0].copy()), description)


def _unit_move_profile(jerk_fraction: float) -> tuple[np.ndarray, np.ndarray]:
    """Normalised knots (u in [0, 1]) and accelerations of one jerk-limited rest-to-rest move:
    a trapezoidal acceleration pulse then its mirror, ramps lasting `jerk_fraction` of the move."""
    j = jerk_fraction
    u = np.array([0.0, j, 0.5 - j, 0.5, 0.5 + j, 1.0 - j, 1.0])
    a = np.array([0.0, 1.0, 1.0, 0.0, -1.0, -1.0, 0.0])
    return u, a


def integrate_table(rows: np.ndarray, v0: tuple[float, float] = (0.0, 0.0)) -> tuple[np.ndarray, np.ndarray]:
    """Exact velocity and displacement at the knots of a piecewise-linear acceleration table."""
    t, a = rows[:, 0], rows[:, 1:3]
    v = np.zeros_like(a)
    x = np.zeros_like(a)
    v[0] = v0
    for k in range(1, len(t)):
        h = t[k] - t[k - 1]
        v[k] = v[k - 1] + 0.5 * h * (a[k - 1] + a[k])
        x[k] = x[k - 1] + h * v[k - 1] + h * h * (a[k - 1] / 3.0 + a[k] / 6.0)
    return v, x


def pick_and_place(moves: list[tuple[tuple[float, float], float]], start: float = 0.0,
                   jerk_fraction: float = 0.125) -> Excitation:
    """Rest-to-rest moves in sequence, each (displacement (dx, dy) in m, duration in s).

    A move of zero displacement is a dwell. Acceleration is piecewise linear, so jerk is
    bounded and the gripper starts and ends every move at rest.
    """
    u, shape = _unit_move_profile(jerk_fraction)
    _, x_unit = integrate_table(np.column_stack([u, shape, np.zeros_like(u)]))
    reach = x_unit[-1, 0]  # displacement of a unit-peak, unit-duration move
    rows = [[0.0, 0.0, 0.0]] if start > 0 else []
    t0 = start
    for (dx, dy), dur in moves:
        peak = math.hypot(dx, dy) / (reach * dur * dur)
        ux, uy = (dx, dy) if peak == 0 else (dx / math.hypot(dx, dy), dy / math.hypot(dx, dy))
        for uk, sk in zip(u, shape):
            tk = t0 + uk * dur
            if rows and abs(rows[-1][0] - tk) < 1e-15:
                continue
            rows.append([tk, peak * sk * ux, peak * sk * uy])
        t0 += dur
    desc = f"pick-and-place: {len(moves)} moves, {t0 - start:g} s from {start:g} s"
    return table("pick-and-place", np.array(rows), desc)


def read_csv(path: Path, key: str, hold: bool = False, after: str | None = None) -> Excitation:
    """A CSV of time, ax, az (header row allowed); linear in between (or held from each row to the
    next with hold = true, as a sampled controller output is), zero before the first row. After the last
    row: its acceleration kept (after = "hold"), zero (after = "zero"), or, without `after`, undefined: a run
    that goes past it is refused (check_covers)."""
    raw = _csv_rows(path, key, "CSV of time, ax, az")
    if raw and not _is_number(raw[0][0]):
        raw = raw[1:]
    if len(raw) < 2:
        raise SceneError(key, f"{path}: need at least two rows of time, ax, az")
    rows = []
    for n, r in enumerate(raw, start=1):
        if len(r) != 3 or not all(_is_number(c) for c in r):
            raise SceneError(key, f"{path} row {n}: expected three numbers time, ax, az, got {r!r}")
        vals = [float(c) for c in r]
        if not all(math.isfinite(v) for v in vals):
            raise SceneError(key, f"{path} row {n}: values must be finite, got {r!r}")
        rows.append(vals)
    arr = np.array(rows)
    if np.any(np.diff(arr[:, 0]) <= 0):
        raise SceneError(key, f"{path}: time must increase strictly from row to row")
    if arr[0, 0] < 0:
        raise SceneError(key, f"{path}: time must start at or after 0 s")
    if hold:
        arr = zero_order_hold(arr)
    last = float(arr[-1, 0])
    if after == "hold":
        arr = np.vstack([arr, [max(FOREVER, 2 * last), *arr[-1, 1:]]])
    desc = f"csv: {path.name}, {len(rows)} rows{' (held)' if hold else ''}" + (f", then {after}" if after else "")
    ex = table("csv", arr, desc)
    return Excitation(ex.kind, ex.arrays, ex.description, math.inf if after else last, key)


#: a pose table's columns: time and position, then an orientation as fixed-axis roll, pitch, yaw (REP-103) or a
#: quaternion
POSE_COLUMNS = ("time", "x", "y", "z")
ORIENTATIONS = (("roll", "pitch", "yaw"), ("qx", "qy", "qz", "qw"))
#: the largest acceleration a pose table may ask for, m/s² (beyond it the positions jump: a unit or a glitch)
POSE_MAX_ACCEL = 1e3


def read_pose_table(path: Path, key: str) -> Excitation:
    """The gripper's recorded poses (CSV with a header: time, x, y, z and roll, pitch, yaw or qx, qy, qz, qw; m,
    rad, s) as the rachis motion. Positions are interpolated by a cubic spline with zero velocity at both ends
    (C2: its acceleration is piecewise linear, so the excitation is exactly a linear acceleration table and the
    rachis follows the spline to the solver's tolerance); the spline's error against a smooth motion sampled
    every h is O(h⁴). Before the first row and after the last the gripper rests, and the rachis' displacement is
    counted from the first row's position (the world frame is the rachis frame at t = 0).

    The rachis does not yet turn or move sideways (the 6-DoF rachis of issue 13 is not built): a table whose
    orientation or y changes is refused, naming the row and column."""
    from scipy.interpolate import CubicSpline

    raw = _csv_rows(path, key, "CSV pose table")
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
    for n in range(1, len(t)):
        if t[n] <= t[n - 1]:
            raise SceneError(key, f"{path} row {n + 1} column time: {t[n]:g} s is not after row {n}'s {t[n - 1]:g} s "
                                  "(times must increase strictly: sort the rows, drop repeated ones)")
    if t[0] < 0:
        raise SceneError(key, f"{path} row 1 column time: {t[0]:g} s; the table must start at or after 0 s")
    if orientation == ORIENTATIONS[1]:
        norm = np.linalg.norm(arr[:, 4:8], axis=1)
        bad = np.flatnonzero(np.abs(norm - 1.0) > 1e-6)
        if bad.size:
            raise SceneError(key, f"{path} row {bad[0] + 1} column qw: the quaternion's norm is {norm[bad[0]]:.9g}; "
                                  "expected a unit quaternion (within 1e-6)")
        q = arr[:, 4:8] * np.sign(np.sum(arr[:, 4:8] * arr[0, 4:8], axis=1))[:, None]  # q and −q: the same turn
        change = np.abs(q - q[0])
    else:
        change = np.abs(arr[:, 4:7] - arr[0, 4:7])
    for columns, moved, what in ((orientation, change, "turns"), (("y",), np.abs(arr[:, 2:3] - arr[0, 2]),
                                                                  "moves sideways")):
        rows_moved = np.flatnonzero(moved.max(axis=1) > 1e-9)
        if rows_moved.size:
            n = int(rows_moved[0])
            column = columns[int(np.argmax(moved[n] > 1e-9))]
            raise SceneError(key, f"{path} row {n + 1} column {column}: the gripper {what} here; this version moves "
                                  "the rachis in x and z only (rotation and lateral motion: the 6-DoF rachis, not "
                                  "built yet)")
    spline = CubicSpline(t, arr[:, [1, 3]], bc_type="clamped")
    accel = spline(t, 2)
    worst = int(np.argmax(np.abs(accel).max(axis=1)))
    if np.abs(accel[worst]).max() > POSE_MAX_ACCEL:
        raise SceneError(key, f"{path} row {worst + 1} columns x, z: following these positions needs "
                              f"{np.abs(accel[worst]).max():.3g} m/s² (more than {POSE_MAX_ACCEL:g}): a jump the "
                              "interpolation cannot follow (a glitch, or positions in mm?)")
    desc = f"pose table: {path.name}, {len(t)} poses from {t[0]:g} to {t[-1]:g} s, cubic spline"
    ex = table("pose-table", np.column_stack([t, accel]), desc)
    return Excitation(ex.kind, ex.arrays, ex.description, math.inf, key)


def zero_order_hold(rows: np.ndarray) -> np.ndarray:
    """A staircase as a piecewise-linear table: each value repeated at the next row's time.
    The solver picks the piece from the step's start, so the duplicated knot is never ambiguous."""
    t, a = rows[:, 0], rows[:, 1:]
    out = np.empty((2 * len(rows) - 1, 3))
    out[0::2, 0] = t
    out[0::2, 1:] = a
    out[1::2, 0] = t[1:]
    out[1::2, 1:] = a[:-1]
    return out


def _csv_rows(path: Path, key: str, what: str) -> list[list[str]]:
    """The rows of a CSV file, comment lines (#) left out; a file that cannot be read is a SceneError on `key`."""
    try:
        with open(path, newline="", encoding="utf-8") as fh:
            return [r for r in csv.reader(fh) if r and not r[0].lstrip().startswith("#")]
    except OSError as exc:
        raise SceneError(key, f"cannot read {what} {path}: {exc.strerror or exc}") from None
    except (UnicodeDecodeError, csv.Error) as exc:
        raise SceneError(key, f"{path}: not a UTF-8 {what} ({exc})") from None


def _is_number(s: str) -> bool:
    try:
        float(s)
    except ValueError:
        return False
    return True

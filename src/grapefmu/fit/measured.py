"""Measured time series (tracked twig angles, optionally the gripper's acceleration) read from CSV and checked.

The columns are the simulator's own file columns (results/catalogue.py), so a CSV that `grapefmu simulate`
writes is also valid input: the time, one angle column per tracked angle of the scene, and optionally both
rachis acceleration columns. Any other column is ignored. Each problem names the file, the column and the
row (rows count from 1 below the header; the line adds the header and comments):

- errors: no time column or no angle column, an angle column of an angle the scene does not have, an angle
  column in another unit, a cell that is not a number, a missing or non-finite time, time that does not
  increase from row to row or starts before 0 s, an angle beyond ±π (degrees written by mistake), a missing
  acceleration;
- warnings (the fit goes on): a missing angle (an empty or NaN cell: the tracker lost the berry there; that
  sample is left out) and a gap in time longer than GAP_FACTOR median frame intervals (frames dropped).
"""
from __future__ import annotations

import csv
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import DataError
from ..model.bounds import bound
from ..model.excitation import MAX_ACCEL
from ..model.model import ANGLE, Model, SolverSettings
from ..results.catalogue import channel, file_column

#: a step in time longer than this many median frame intervals is reported as a gap
GAP_FACTOR = 1.5
#: s: the latest frame time, a scene's longest run (a time of 1e8 s asked for gigabytes of samples)
MAX_TIME = bound(SolverSettings, "t_end").hi
#: at most this many rows are named in one message (then "and N more")
NAMED_ROWS = 5


def time_column() -> str:
    return file_column("time", "s")


def angle_column(dof: str) -> str:
    return channel("angle").file_column(dof)


def accel_columns() -> tuple[str, str]:
    return channel("base_ax").file_column(""), channel("base_az").file_column("")


@dataclass(frozen=True)
class Measured:
    """One measured series: sample times (s), the tracked angles (rad, NaN where the tracker lost the berry)
    and, if measured, the rachis acceleration (m/s², (a_x, a_z) per row)."""

    path: Path
    t: np.ndarray                 # (S,)
    dofs: tuple[str, ...]         # the scene's angle names, one per column of `angles`
    angles: np.ndarray            # (S, K)
    accel: np.ndarray | None      # (S, 2)
    warnings: tuple[str, ...] = ()

    @property
    def samples(self) -> int:
        """Angle values the fit can use."""
        return int(np.isfinite(self.angles).sum())


def _rows(rows: list[int], lines: list[int]) -> str:
    """Rows (0-based) named as `row 3 (line 4)`, a handful at most."""
    named = ", ".join(f"row {r + 1} (line {lines[r]})" for r in rows[:NAMED_ROWS])
    return named + (f" and {len(rows) - NAMED_ROWS} more" if len(rows) > NAMED_ROWS else "")


def read_measured(path: str | Path, model: Model) -> Measured:
    """Read and check one CSV against the scene's angles; a DataError names the file, column and row."""
    path = Path(path)
    try:
        with open(path, newline="", encoding="utf-8") as fh:
            numbered = [(n, r) for n, r in enumerate(csv.reader(fh), start=1)
                        if r and not r[0].lstrip().startswith("#")]
    except OSError as e:
        raise DataError(f"{path}: cannot read the measured CSV: {e.strerror or e}") from None
    except (UnicodeDecodeError, csv.Error) as e:
        raise DataError(f"{path}: not a UTF-8 CSV ({e})") from None
    if not numbered:
        raise DataError(f"{path}: empty; expected a header row ({time_column()}, {angle_column('<angle>')}, ...) "
                        "and one row per frame")
    header = [h.strip() for h in numbered[0][1]]
    body, lines = [r for _, r in numbered[1:]], [n for n, _ in numbered[1:]]
    where = {h: k for k, h in enumerate(header)}
    twice = next((h for h in where if h and header.count(h) > 1), None)
    if twice:  # which copy is the measurement? (the last one silently won)
        cols = [k + 1 for k, h in enumerate(header) if h == twice]
        raise DataError(f"{path}: column {twice} appears {len(cols)} times in the header (columns "
                        f"{', '.join(map(str, cols))}); keep one")
    tcol = time_column()
    if tcol not in where:
        raise DataError(f"{path}: no {tcol} column in the header {', '.join(header[:8])}; expected {tcol}, "
                        f"{angle_column('<angle>')} ... (docs/fit_and_risk.md)")
    dofs = [d for d in model.dof_names if angle_column(d) in where]
    _check_angle_names(path, header, model)
    if not dofs:
        raise DataError(f"{path}: no angle column; expected one or more of "
                        f"{', '.join(angle_column(d) for d in model.dof_names)}")
    if len(body) < 3:
        raise DataError(f"{path}: {len(body)} row(s); a fit needs a series of frames")
    for r, row in enumerate(body):
        if len(row) != len(header):
            raise DataError(f"{path}: {_rows([r], lines)}: {len(row)} cells, the header has {len(header)}")

    def numbers(col: str) -> np.ndarray:
        out = np.empty(len(body))
        k = where[col]
        for r, row in enumerate(body):
            cell = row[k].strip()
            if cell == "":
                out[r] = np.nan
                continue
            try:
                out[r] = float(cell)
            except ValueError:
                raise DataError(f"{path}: {col} {_rows([r], lines)}: {cell[:40]!r} is not a number") from None
        return out

    warnings: list[str] = []
    t = numbers(tcol)
    bad = np.flatnonzero(~np.isfinite(t)).tolist()
    if bad:
        raise DataError(f"{path}: {tcol} {_rows(bad, lines)}: missing or not finite; every frame needs its time")
    if t[0] < 0:
        raise DataError(f"{path}: {tcol} {_rows([0], lines)}: {t[0]:g} s; time starts at or after 0 s, the scene's "
                        "clock (subtract the camera's offset)")
    late = np.flatnonzero(t > MAX_TIME).tolist()
    if late:
        raise DataError(f"{path}: {tcol} {_rows(late, lines)}: {t[late[0]]:g} s; at most {MAX_TIME:g} s, a scene's "
                        "longest run (solver.t_end)")
    back = np.flatnonzero(np.diff(t) <= 0).tolist()
    if back:
        r = back[0] + 1
        raise DataError(f"{path}: {tcol} {_rows([r], lines)}: {t[r]:.9g} s is not after the previous row's "
                        f"{t[r - 1]:.9g} s; time must increase from row to row (sort the rows by time, drop "
                        f"repeated frames){f'; {len(back)} rows in all' if len(back) > 1 else ''}")
    dt = np.diff(t)
    frame = float(np.median(dt))
    gaps = np.flatnonzero(dt > GAP_FACTOR * frame).tolist()
    if gaps:
        first = gaps[0]
        warnings.append(f"{path}: {tcol} {_rows([g + 1 for g in gaps], lines)}: a gap in time ({dt[first]:.4g} s "
                        f"before row {first + 2}, about {round(dt[first] / frame) - 1} frame(s) missing at the "
                        f"median interval {frame:.4g} s); the fit uses the frames there are")
    angles = np.column_stack([numbers(angle_column(d)) for d in dofs])
    for k, d in enumerate(dofs):
        col = angle_column(d)
        beyond = np.flatnonzero(np.abs(angles[:, k]) > ANGLE.hi).tolist()
        if beyond:
            r = beyond[0]
            raise DataError(f"{path}: {col} {_rows(beyond, lines)}: {angles[r, k]:g} is beyond ±π rad; angles are "
                            f"in radians (were these degrees? multiply by π/180)")
        lost = np.flatnonzero(np.isnan(angles[:, k])).tolist()
        if lost:
            warnings.append(f"{path}: {col} {_rows(lost, lines)}: missing (empty or NaN); "
                            f"{len(lost)} sample(s) left out of the fit")
        if np.all(np.isnan(angles[:, k])):
            raise DataError(f"{path}: {col}: no value in any row")
    accel = None
    have = [c for c in accel_columns() if c in where]
    if have:
        if len(have) == 1:
            missing = next(c for c in accel_columns() if c not in where)
            raise DataError(f"{path}: {have[0]} without {missing}; give both rachis accelerations or neither")
        accel = np.column_stack([numbers(c) for c in accel_columns()])
        for k, col in enumerate(accel_columns()):
            bad = np.flatnonzero(~np.isfinite(accel[:, k])).tolist()
            if bad:
                raise DataError(f"{path}: {col} {_rows(bad, lines)}: missing or not finite; a measured gripper "
                                "motion needs every frame (or leave both acceleration columns out)")
            beyond = np.flatnonzero(np.abs(accel[:, k]) > MAX_ACCEL).tolist()
            if beyond:
                raise DataError(f"{path}: {col} {_rows(beyond, lines)}: {accel[beyond[0], k]:g} m/s²; at most "
                                f"±{MAX_ACCEL:g} m/s², the bound every face uses")
    return Measured(path, t, tuple(dofs), angles, accel, tuple(warnings))


def _check_angle_names(path: Path, header: list[str], model: Model) -> None:
    """An angle column must be one of the scene's angles, in radians."""
    known = {angle_column(d) for d in model.dof_names}
    for h in header:
        if not h.startswith("angle_") or h in known:
            continue
        name = h.removeprefix("angle_")
        for suffix in ("_deg", "_degrees", "_rad"):
            name = name.removesuffix(suffix)
        if name in model.dof_names:
            raise DataError(f"{path}: column {h}: angles are read in radians, as {angle_column(name)}")
        raise DataError(f"{path}: column {h}: the scene has no angle {name!r}; its angle columns are "
                        f"{', '.join(sorted(known))}")

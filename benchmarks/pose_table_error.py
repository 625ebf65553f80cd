"""The pose table's interpolation error (docs/scenes.md): a 6 cm minimum-jerk move in 0.5 s, sampled at 100 Hz
and at 50 Hz into pose tables, read by grapefmu (read_pose_table), and the rachis displacement its
acceleration table gives (integrated exactly, on a fine grid) against the analytic motion. The ratio of the two
errors is the scheme's order in the sample spacing (16 for h⁴).
Run: .venv/bin/python benchmarks/pose_table_error.py"""
from __future__ import annotations

import tempfile
from pathlib import Path

import numpy as np

from grapefmu.model.excitation import integrate_table, read_pose_table

T, D = 0.5, 0.06


def motion(t):
    s = t / T
    return D * (10 * s**3 - 15 * s**4 + 6 * s**5)


def error(hz: int, folder: Path) -> float:
    knots = np.arange(0.0, T + 1e-9, 1.0 / hz)
    path = folder / f"poses_{hz}.csv"
    path.write_text("time,x,y,z,roll,pitch,yaw\n" + "".join(f"{float(t)!r},{float(x)!r},0,0,0,0,0\n"
                                                            for t, x in zip(knots, motion(knots))))
    table = read_pose_table(path, "excitation.file").arrays.table
    fine = np.linspace(0.0, T, 20001)  # the acceleration is linear between knots: exact at any inserted time
    rows = np.column_stack([fine, *(np.interp(fine, table[:, 0], table[:, c]) for c in (1, 2))])
    return float(np.abs(integrate_table(rows)[1][:, 0] - motion(fine)).max())


def main() -> None:
    with tempfile.TemporaryDirectory() as d:
        errors = {hz: error(hz, Path(d)) for hz in (100, 50)}
    for hz, e in errors.items():
        print(f"sampled at {hz:3d} Hz: largest displacement error {e:.2g} m")
    print(f"ratio {errors[50] / errors[100]:.1f} (h⁴: 16)")


if __name__ == "__main__":
    main()

"""The pose table's interpolation error (docs/scenes.md): a minimum-jerk move in 0.5 s (6 cm along x, 2 cm along y,
−3 cm along z) with a turn (0.5 rad of pitch; or 0.3 rad roll, 0.5 pitch, 0.4 yaw at once: an axis that moves),
sampled at 100 Hz and at 50 Hz into pose tables, read by grapefmu (read_pose_table) and simulated (one berry,
rtol 1e-10): the rachis' displacement and orientation against the analytic motion. The ratio of the two errors
is the scheme's order in the sample spacing (16 for h⁴; the turn about a moving axis also carries the error of
its α tabulated at 4 points per row and linear in between, h²: 4).
Run: .venv/bin/python benchmarks/pose_table_error.py"""
from __future__ import annotations

import tempfile
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from grapefmu import simulate
from grapefmu.scenefile import scene_from_dict

T = 0.5
MOVE = np.array([0.06, 0.02, -0.03])  # m
TURNS = {"pitch only (fixed axis)": np.array([0.0, 0.5, 0.0]), "roll, pitch, yaw (moving axis)": np.array([0.3, 0.5, 0.4])}


def profile(t):
    s = np.clip(t / T, 0.0, 1.0)
    return 10 * s**3 - 15 * s**4 + 6 * s**5


def errors(hz: int, rpy: np.ndarray, folder: Path) -> tuple[float, float]:
    """(largest displacement error m, largest orientation error rad) over the move."""
    knots = np.arange(0.0, T + 1e-9, 1.0 / hz)
    u = profile(knots)[:, None]
    path = folder / f"poses_{hz}.csv"
    np.savetxt(path, np.column_stack([knots, u * MOVE, u * rpy]), delimiter=",", header="time,x,y,z,roll,pitch,yaw",
               comments="")
    doc = {"name": "pose", "berries": [{"name": "a", "kind": "spherical", "mass": 0.01, "radius": 0.01,
                                        "twig_length": 0.03, "hinge": [0.0, 0.0, 0.0], "hinge_stiffness": 1e-3,
                                        "hinge_damping": 2e-5}],
           "excitation": {"kind": "pose-table", "file": str(path)},
           "solver": {"t_end": T, "rtol": 1e-10, "atol": 1e-13, "output_interval": 1e-3}}
    run = simulate(scene_from_dict(doc, folder))
    u = profile(run.t)[:, None]
    turn = Rotation.from_euler("xyz", u * rpy).inv() * Rotation.from_quat(run.base_orientation)
    return float(np.abs(run.base_displacement - u * MOVE).max()), float(turn.magnitude().max())


def main() -> None:
    with tempfile.TemporaryDirectory() as d:
        for name, rpy in TURNS.items():
            e = {hz: errors(hz, rpy, Path(d)) for hz in (100, 50)}
            print(f"{name}:")
            for hz, (dx, dr) in e.items():
                print(f"  sampled at {hz:3d} Hz: displacement error {dx:.2g} m, orientation error {dr:.2g} rad")
            print(f"  ratio 50/100 Hz: displacement {e[50][0] / e[100][0]:.1f}, orientation {e[50][1] / e[100][1]:.1f}")


if __name__ == "__main__":
    main()

"""Pick-and-place moves (docs/scenes.md, [excitation]): each move takes the gripper by its displacement and turns it
by its rotation vector in its duration, from rest to rest. The reference is the scene's own moves (where each move
ends and the sum of them), not the profile the code builds."""
from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from grapefmu import simulate

from .conftest import dual, scene

START = 0.05
MOVES = [((0.12, -0.04), 0.3, 0.4), ((0.0, 0.0), 0.1, 0.0), ((-0.05, 0.02), 0.2, -0.1)]  # (dx, dz) m, T s, turn rad


def test_each_move_ends_where_its_displacement_and_rotation_say_at_rest():
    doc = dual(angles=(0.0, 0.3), excitation={"kind": "pick-and-place", "start": START, "moves": [
        {"displacement": list(d), "duration": T, "rotation": [0.0, r, 0.0]} for d, T, r in MOVES]},
        solver={"t_end": 0.8, "rtol": 1e-10, "atol": 1e-13, "output_interval": 0.01})
    run = simulate(scene(doc))
    ends = START + np.cumsum([T for _, T, _ in MOVES])
    where = np.cumsum([[d[0], 0.0, d[1]] for d, _, _ in MOVES], axis=0)
    turned = np.cumsum([r for _, _, r in MOVES])
    for t_end, x, pitch in zip(ends, where, turned):
        k = int(np.argmin(np.abs(run.t - t_end)))
        assert abs(run.t[k] - t_end) < 1e-9
        assert np.abs(run.base_displacement[k] - x).max() < 1e-8, (t_end, run.base_displacement[k], x)
        got = Rotation.from_quat(run.base_orientation[k])
        assert (Rotation.from_euler("y", pitch).inv() * got).magnitude() < 1e-8
    before = run.t <= START
    assert np.abs(run.base_displacement[before]).max() == 0.0  # still until the first move starts
    after = run.t >= ends[-1]
    assert np.abs(run.base_displacement[after] - where[-1]).max() < 1e-8  # at rest after the last
    assert np.abs(run.base_angular_velocity[after]).max() < 1e-8

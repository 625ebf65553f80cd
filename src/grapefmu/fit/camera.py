"""Synthetic "camera" data: a scene simulated, its twig angles sampled at a frame rate with tracking noise.

What a tracked swing test gives: angles at each frame's time (a global shutter: the angle at that instant,
no motion blur), each with independent Gaussian noise of `noise` rad (1 mrad: a marker tracked to about
0.03 mm at 30 mm from the hinge), optionally the gripper's acceleration as the robot logs it (noise-free).
The columns are the simulator's file columns, so `grapefmu fit` reads the file as it reads measured data.

    python -m grapefmu.fit.camera SCENE -o data.csv [--rate 100] [--noise 1e-3] [--seed 1] [--angles left,right]
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from ..model.model import Scene
from ..results.writers import atomic_path, check_target
from .measured import accel_columns, angle_column, time_column
from .shooting import FIT_ATOL, FIT_RTOL

#: the defaults: a 100 Hz camera, 1 mrad tracking noise
RATE_HZ, NOISE_RAD = 100.0, 1e-3


def camera_data(scene: Scene, *, rate: float = RATE_HZ, noise: float = NOISE_RAD, seed: int = 0,
                angles: list[str] | None = None, gripper: bool = False, t_end: float | None = None
                ) -> dict[str, np.ndarray]:
    """Columns of a synthetic measured CSV: the frame times from 0 s, the chosen angles (default: all) with
    noise, and with `gripper` the rachis acceleration at each frame."""
    from ..solver.api import simulate

    names = scene.model.dof_names
    chosen = angles or names
    for a in chosen:
        if a not in names:
            from ..errors import GrapefmuError
            raise GrapefmuError(f"--angles: the scene has no angle {a!r}; its angles: {', '.join(names)}")
    run = simulate(scene, t_end, output_interval=1.0 / rate, rtol=FIT_RTOL, atol=FIT_ATOL)
    rng = np.random.default_rng(seed)
    cols = {time_column(): run.t}
    for a in chosen:
        cols[angle_column(a)] = run.angles[:, names.index(a)] + rng.normal(0.0, noise, len(run.t))
    if gripper:
        for c, k in zip(accel_columns(), (0, 2)):  # (a_x, a_z) of ACCEL_COMPONENTS: the fit is planar
            cols[c] = run.accel[:, k]
    return cols


def write_csv(cols: dict[str, np.ndarray], path: str | Path) -> None:
    with atomic_path(path) as tmp:
        np.savetxt(tmp, np.column_stack(list(cols.values())), delimiter=",", header=",".join(cols), comments="",
                   fmt="%.10g")


def main(argv: list[str] | None = None) -> int:
    from ..errors import GrapefmuError
    from ..scenefile import load_scene

    ap = argparse.ArgumentParser(prog="python -m grapefmu.fit.camera", description=__doc__.split("\n\n")[0])
    ap.add_argument("scene", help="scene TOML (its initial state, excitation and solver.t_end)")
    ap.add_argument("-o", "--output", required=True, help="the CSV to write")
    ap.add_argument("--rate", type=float, default=RATE_HZ, help="frames per second (default: %(default)s)")
    ap.add_argument("--noise", type=float, default=NOISE_RAD, help="tracking noise, rad (default: %(default)s)")
    ap.add_argument("--seed", type=int, default=1, help="noise seed (default: %(default)s)")
    ap.add_argument("--angles", help="comma-separated angles to track (default: all)")
    ap.add_argument("--gripper", action="store_true", help="add the rachis acceleration columns")
    a = ap.parse_args(argv)
    try:
        if not (np.isfinite(a.rate) and 0 < a.rate <= 1e5 and np.isfinite(a.noise) and a.noise >= 0):
            raise GrapefmuError(f"--rate {a.rate} / --noise {a.noise}: a rate in (0, 1e5] Hz and a noise ≥ 0 rad")
        out = check_target(a.output, (".csv",), "--output")
        cols = camera_data(load_scene(a.scene), rate=a.rate, noise=a.noise, seed=a.seed,
                           angles=a.angles.split(",") if a.angles else None, gripper=a.gripper)
        write_csv(cols, out)
    except GrapefmuError as e:
        print(f"{ap.prog}: {e}", file=sys.stderr)
        return 2
    print(f"wrote {out}: {len(cols[time_column()])} frames at {a.rate:g} Hz, noise {a.noise:g} rad")
    return 0


if __name__ == "__main__":
    sys.exit(main())

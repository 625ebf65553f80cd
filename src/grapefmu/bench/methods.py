"""Each method runs one scene at one setting and returns its angles on the 1 ms grid, impact onsets
and peak force where it has them, and its cost. A method that fails returns the reason instead."""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np

from ..errors import GrapefmuError
from ..physics.excitation import accel
from ..scenefile import scene_toml
from ..solver.api import simulate

GRID = 1e-3


@dataclass
class Outcome:
    angles: np.ndarray | None = None     # (n, N) on the 1 ms grid
    final: np.ndarray | None = None      # final angles and rates
    onsets: np.ndarray | None = None     # impact onset times, if the method knows them
    peak_force: float = math.nan
    rhs: int | None = None
    failure: str | None = None
    extra: dict = field(default_factory=dict)


def _from_run(run) -> Outcome:
    return Outcome(run.angles, np.r_[run.angles[-1], run.angular_velocities[-1]], run.impacts.onset,
                   float(run.peak_force.max()) if run.peak_force.size else 0.0, run.stats.get("rhs_evaluations"))


def grapefmu_event(scene, rtol):
    return _from_run(simulate(scene, method="event", rtol=rtol, atol=rtol * 1e-2, output_interval=GRID))


def paper_fixed(scene, h):
    return _from_run(simulate(scene, method="paper", fixed_step=h, output_interval=GRID, cross_check=False))


def scipy_events(scene, integrator, rtol):
    from ..solver.reference import simulate_reference
    run = simulate_reference(scene, rtol=rtol, atol=rtol * 1e-2, output_interval=GRID, integrator=integrator,
                             max_step=math.inf)
    return _from_run(run)


def scipy_lean(scene, integrator, rtol):
    """The lean scipy driver (bench/lean.py): the best peer we can write; no peak-force search."""
    from .lean import simulate_lean
    r = simulate_lean(scene, rtol=rtol, atol=rtol * 1e-2, integrator=integrator, output_interval=GRID)
    d = scene.model.n_dof
    return Outcome(r.y[:, :d], r.final[: 2 * d], r.onsets, math.nan, r.rhs_evaluations)


def mujoco_mjcf(scene, integrator: str, dt: float) -> str:
    """The scene in MJCF: the rod fixed, hinges about −y so that + swings toward +x, point-mass berries
    (explicit inertial, negligible rotational inertia), and one contact pair per berry pair whose soft
    contact takes our stiffness and damping directly (negative solref). Everything is in the rod frame:
    the base acceleration enters as a time-varying gravity (see mujoco_run)."""
    m = scene.model
    bodies = []
    for b in m.berries:
        bodies.append(f'''
    <body name="{b.name}" pos="{b.hinge_x} 0 0">
      <joint name="j_{b.name}" type="hinge" axis="0 -1 0" stiffness="{b.hinge_stiffness}" damping="{b.hinge_damping}"/>
      <inertial pos="0 0 {-b.twig_length}" mass="{b.mass}" diaginertia="1e-12 1e-12 1e-12"/>
      <geom name="g_{b.name}" type="sphere" size="{b.radius}" pos="0 0 {-b.twig_length}" contype="0" conaffinity="0"/>
    </body>''')
    pairs = []
    for p in m.pairs:
        k, c = p.law.stiffness, p.law.damping
        pairs.append(f'    <pair geom1="g_{m.berries[p.i].name}" geom2="g_{m.berries[p.j].name}" condim="1" '
                     f'solref="{-k} {-c}" solimp="0.99 0.99 0.001 0.5 2"/>')
    return f'''<mujoco>
  <option timestep="{dt}" integrator="{integrator}" gravity="0 0 {-m.gravity}"/>
  <worldbody>{''.join(bodies)}
  </worldbody>
  <contact>
{chr(10).join(pairs)}
  </contact>
</mujoco>'''


def mujoco_run(scene, integrator, dt):
    import mujoco
    model = mujoco.MjModel.from_xml_string(mujoco_mjcf(scene, integrator, dt))
    data = mujoco.MjData(model)
    n = scene.model.n_berries
    data.qpos[:n] = scene.angles
    data.qvel[:n] = scene.angular_velocities
    t_end = scene.solver.t_end
    steps = int(round(t_end / dt))
    per = max(1, int(round(GRID / dt)))
    ex = scene.excitation
    g = scene.model.gravity
    varying = ex.kind != "none"
    out = [data.qpos[:n].copy()]
    if varying:  # the inertial field changes every step: one call per step
        acc = accel(ex, np.arange(steps) * dt)
        for k in range(steps):
            model.opt.gravity[:] = (-acc[k, 0], 0.0, -g - acc[k, 1])
            mujoco.mj_step(model, data)
            if (k + 1) % per == 0:
                out.append(data.qpos[:n].copy())
    else:  # constant gravity: let MuJoCo take a whole grid interval per call
        for _ in range(steps // per):
            mujoco.mj_step(model, data, per)
            out.append(data.qpos[:n].copy())
    if not np.all(np.isfinite(np.array(out))):
        return Outcome(failure="NaN in the state")
    angles = np.array(out)
    return Outcome(angles, np.r_[data.qpos[:n], data.qvel[:n]], None, math.nan, steps * (4 if integrator == "RK4" else 1))


def _once(fn) -> tuple[Outcome, float]:
    """fn's outcome and wall time; a failure it raises becomes an outcome that says why."""
    try:
        t = time.perf_counter()
        out = fn()
        return out, time.perf_counter() - t
    except (GrapefmuError, FloatingPointError, ValueError, RuntimeError) as e:
        return Outcome(failure=f"{type(e).__name__}: {str(e)[:120]}"), math.nan


def interleaved(fns, repeats: int, budget: float) -> list[tuple[Outcome, float]]:
    """Each fn's outcome and wall time: a warm-up round, then up to `repeats` rounds that run every fn once in turn,
    the minimum of its rounds (its warm-up's time if it sat them out: a fn sits out the rounds left once its runs
    took more than `budget` seconds in all, and every round after a failure). Interleaved, as the issue measures:
    back to back, a sub-millisecond compiled run is timed in a state of the caches that only its own repetition
    leaves (1.2–1.6× faster on the paper collision than right after a scipy run; docs/bench_notes.md)."""
    first = [_once(fn) for fn in fns]
    spent = [t for _, t in first]
    best = [math.inf] * len(fns)
    for _ in range(repeats):
        for k, fn in enumerate(fns):
            if first[k][0].failure or not spent[k] <= budget:
                continue
            out, t = _once(fn)
            if out.failure:
                first[k] = (out, t)
                continue
            spent[k] += t
            best[k] = min(best[k], t)
    return [(out, t if out.failure or best[k] == math.inf else best[k]) for k, (out, t) in enumerate(first)]


def fmu_fmpy(scene):
    """The scene's FMU through fmpy at 1 ms steps, in a separate process (build, then run); the excitation
    is sampled and held every 1 ms, so scenes with excitation differ from the reference by that hold."""
    import json
    import subprocess
    import sys
    import tempfile
    with tempfile.TemporaryDirectory() as d:
        path = f"{d}/scene.toml"
        with open(path, "w") as fh:
            fh.write(scene_toml(scene))
        r = subprocess.run([sys.executable, "-m", "grapefmu_fmu.bench_run", path], capture_output=True, text=True)
    if r.returncode != 0 or "JSON:" not in r.stdout:
        return Outcome(failure=f"FMU run failed: {(r.stderr or r.stdout)[-200:]}"), math.nan
    res = json.loads(r.stdout.split("JSON:", 1)[1].splitlines()[0])
    angles = np.array(res["angles"])
    return Outcome(angles, np.r_[angles[-1], np.full(angles.shape[1], np.nan)], None, math.nan, None), res["wall"]

"""What one step of the compiled loop costs, stage by stage (docs/bench_notes.md, "Where a step's time goes"):
each stage of `loop.integrate` called alone in a compiled loop from one mid-run state (the scene run to 30 % of
its end), so that its arithmetic is timed without the rest of the step. The minimum of 7 repeats of n calls.
A stage alone runs with warm caches and learned branches: the sum is a lower bound on a step inside the loop
(benchmarks/run_breakdown.py measures the loop itself). The samples are filled first as the loop fills them (the
step's ends by the loop, the inner points by the broad phase); kinematics is not part of the certificate since
the loop hands the step's start to it.
Run: .venv/bin/python benchmarks/step_stages.py [collision | cluster N] [rtol]"""
from __future__ import annotations

import sys
import time

import numba as nb

from grapefmu.bench.scale import scene as scale_scene
from grapefmu.bench.scenes import bench_scenes, build
from grapefmu.physics.dynamics import rhs
from grapefmu.physics.kinematics import kinematics
from grapefmu.solver.broadphase import quiet, sample
from grapefmu.solver.events import N_SAMPLES
from grapefmu.solver.loop import buffers
from grapefmu.solver.sampling import sample_step
from grapefmu.solver.solver import Solver
from grapefmu.solver.step import dense_coefficients, error_norm, rk_step


@nb.njit
def t_rhs(n, M, X, TB, S, config, Z, h, sampled):
    P, B = S.physical, S.broad_phase
    for _ in range(n):
        rhs(P.t[0], P.t[0], P.y, S.integrator.f, P.contacts, M, X, S.input[0], Z.W, B.near, B.count[0])


@nb.njit
def t_kinematics(n, M, X, TB, S, config, Z, h, sampled):
    for _ in range(n):
        kinematics(S.physical.y, M, Z.W.berry)


@nb.njit
def t_rk_step(n, M, X, TB, S, config, Z, h, sampled):
    P, I, B = S.physical, S.integrator, S.broad_phase
    args = (P.contacts, M, X, S.input[0], Z.W, B.near, B.count[0])
    for _ in range(n):
        rk_step(P.t[0], h, P.t[0] + h, P.y, I.f, args, TB, I.stages, Z.ynew, Z.tmp, Z.acc)


@nb.njit
def t_error_norm(n, M, X, TB, S, config, Z, h, sampled):
    s = 0.0
    for _ in range(n):
        s += error_norm(h, S.physical.y, Z.ynew, TB, S.integrator.stages, config[0], Z.err, Z.scale, Z.acc)
    return s


@nb.njit
def t_dense_coefficients(n, M, X, TB, S, config, Z, h, sampled):
    P, I, B = S.physical, S.integrator, S.broad_phase
    args = (P.contacts, M, X, S.input[0], Z.W, B.near, B.count[0])
    for _ in range(n):
        dense_coefficients(P.t[0], h, P.y, args, TB, I.stages, I.dense, Z.tmp, Z.acc)


@nb.njit
def t_quiet(n, M, X, TB, S, config, Z, h, sampled):
    s = 0.0
    for _ in range(n):
        s += quiet(S.physical.y, S.integrator.dense, h, M, S.physical.contacts, S.broad_phase, config[0],
                   Z.samples[0], Z.travel, Z.suspect)
    return s


@nb.njit
def t_sample_step(n, M, X, TB, S, config, Z, h, kind):
    """kind: 0 a quiet step, 1 a sampled one, 2 a quiet step whose start the last step sampled (its end)."""
    P, B, Bk = S.physical, S.broad_phase, S.book
    for _ in range(n):
        sample_step(P.t[0], h, 1.0, P.y, S.integrator.dense, M, X, S.input[0], P.contacts, B.near, B.count[0],
                    Bk.totals, Bk.pair, Bk.peak_tension, config[0], Z.W, Z.work, Z.fbuf, Z.pwbuf, Z.cls, Z.tension,
                    Z.pushing, Z.samples, kind == 1, kind == 2, Z.reach)


STAGES = [("one RHS", t_rhs, False), ("kinematics (stage 1 alone)", t_kinematics, False),
          ("rk_step (the stages' RHS)", t_rk_step, False), ("error_norm", t_error_norm, False),
          ("dense_coefficients", t_dense_coefficients, False), ("quiet (travel bound)", t_quiet, False),
          ("sample_step, quiet step (left out where sampling.tensions_bounded holds)", t_sample_step, 0),
          ("sample_step, sampled step", t_sample_step, 1),
          ("sample_step, quiet step after a whole one (likewise)", t_sample_step, 2)]


def main(argv: list[str]) -> None:
    if argv[:1] == ["cluster"]:
        name, sc = f"cluster {argv[1]}", scale_scene("cluster", int(argv[1]))
        argv = argv[2:]
    else:
        name, sc = "paper collision", build(bench_scenes()["paper collision"])
        argv = argv[1:] if argv[:1] == ["collision"] else argv
    rtol = float(argv[0]) if argv else 1e-6
    s = Solver(sc, rtol=rtol, atol=rtol / 100)
    s.run(t_end=0.3 * sc.solver.t_end)  # the stages below write only scratch, the dense output and peaks
    M, X, TB, S, config, Z = s.M, s.excitation, s.tableau, s.state, s.config, buffers(s.M, s.layout.size, False)
    h = float(S.integrator.clock["h_last"][0])
    # the step's samples as the loop leaves them: its ends (the loop's) and the inner points (the broad phase's)
    kinematics(S.physical.y, M, Z.samples[0])
    kinematics(S.physical.y + h * S.integrator.dense.sum(axis=1), M, Z.samples[N_SAMPLES])
    sample(S.physical.y, S.integrator.dense, h, M, Z.work, Z.samples)
    n = max(200, int(2e5 / sc.model.n_berries))
    print(f"{name}, rtol {rtol:g}: {sc.model.n_berries} berries, {S.physical.y.shape[0]} state components, "
          f"{S.integrator.stages.shape[0]} stages, {int(S.broad_phase.count[0])} near pairs; minimum of 7 × {n} calls")
    print("| stage | ns a call |\n|---|---|")
    for label, f, sampled in STAGES:
        f(2, M, X, TB, S, config, Z, h, sampled)
        best = float("inf")
        for _ in range(7):
            t = time.perf_counter()
            f(n, M, X, TB, S, config, Z, h, sampled)
            best = min(best, time.perf_counter() - t)
        print(f"| {label} | {best / n * 1e9:.0f} |")


if __name__ == "__main__":
    main(sys.argv[1:])

"""Where a step's time goes inside the compiled loop itself (docs/bench_notes.md): `loop.integrate`'s source with a
cycle-counter probe between its sections, compiled here (not cached) and run over a whole scene from a fresh
Solver, as `Solver.run` runs it (1 ms output grid). Unlike benchmarks/step_stages.py, which times each stage alone
with warm caches, this sees the loop as it runs: its branches, its caches, the steps rejected. A probe costs a
few nanoseconds (printed: the empty section between two probes); the rest is each section's share, in ns per
accepted step, the minimum over repeats of each section's total.
Run: .venv/bin/python benchmarks/loop_sections.py ["paper collision" | cluster N] [rtol] [--repeats 20]"""
from __future__ import annotations

import argparse
import inspect
import textwrap
import time

import numba as nb
import numpy as np
from llvmlite import ir
from numba.core import cgutils, types
from numba.extending import intrinsic

from grapefmu.bench.scale import scene as scale_scene
from grapefmu.bench.scenes import bench_scenes, build
from grapefmu.solver import loop
from grapefmu.solver import session as ses
from grapefmu.solver.solver import Solver


@intrinsic
def rdtsc(typingctx):
    """The processor's cycle counter (llvm.readcyclecounter)."""
    def codegen(context, builder, signature, args):
        fn = cgutils.get_or_insert_function(builder.module, ir.FunctionType(ir.IntType(64), []),
                                            "llvm.readcyclecounter")
        return builder.call(fn, [])
    return types.int64(), codegen


#: (a line of integrate, the section that ran since the last probe): a probe goes before each line
PROBES = [
    ("while P.t[0] < t_target:", None),  # the clock starts
    ("t0 = P.t[0]", "loop head, step control, rejected steps' tails"),
    ("rk_step(t0, h, t_new,", "breakpoints, step size"),
    ("cnt.rhs_evaluations += ns", "rk_step (the stages)"),
    ("# the berries at the step's end are the FSAL stage's", "error_norm"),
    ("q = I.dense", "dense_coefficients"),
    ("# --- broad phase, then the earliest contact switch", "start kinematics"),
    ("sampled = far < 0.0", "quiet"),
    ("cnt.near_pairs_sum += B.count[0]", "keep_valid"),
    ("t_commit = t_new if not event", "find_event"),
    ("ended = sample_step(t0, h, theta_e,", "record_grid"),
    ("# --- commit", "sample_step"),
    ("if Z.drifted.shape[0] > 0:", "commit"),
    ("cnt.steps += 1", "drift"),
    ("opened = Bk.totals[0].collision_count", "(empty: a probe's own cost)"),
    ("# a whole step's end was sampled", "switch_modes"),
    ("if changed or event or (bi < nbreak", "early rebuild"),
    ("if not fixed:\n            # PI control", "derivative after a switch, or the FSAL copy"),
]


def probed_integrate():
    """loop.integrate with a probe before each PROBES line, taking the section totals T (cycles) last."""
    src = textwrap.dedent(inspect.getsource(loop.integrate))
    src = src.replace("@jit\n", "", 1).replace("t_target, max_steps):", "t_target, max_steps, _T):", 1)
    for k, (line, _) in enumerate(PROBES):
        assert src.count(line) == 1, line
        at = src.index(line)
        indent = src[src.rindex("\n", 0, at) + 1:at]
        probe = "_t = rdtsc()" if k == 0 else f"_now = rdtsc(); _T[{k}] += _now - _t; _t = _now"
        src = src[:at] + probe + "\n" + indent + src[at:]
    space = dict(vars(loop), rdtsc=rdtsc, np=np)
    exec(compile(src, "<probed integrate>", "exec"), space)
    return nb.njit(error_model="numpy")(space["integrate"])


def main() -> None:
    p = argparse.ArgumentParser()
    p.add_argument("scene", nargs="*", default=["paper collision"])
    p.add_argument("--rtol", type=float, default=1e-6)
    p.add_argument("--repeats", type=int, default=20)
    a = p.parse_args()
    if a.scene[0] == "cluster":
        name, sc = f"cluster {a.scene[1]}", scale_scene("cluster", int(a.scene[1]), a.rtol)
    else:
        name, sc = a.scene[0], build(bench_scenes()[a.scene[0]])
    integrate = probed_integrate()
    t_end, dt = sc.solver.t_end, 1e-3
    best = np.full(len(PROBES), np.inf)
    rate = 0.0
    for r in range(a.repeats + 1):
        s = Solver(sc, rtol=a.rtol, atol=a.rtol / 100)
        R = ses.recording(s._session, int(t_end / dt) + 2, dt, t_end)
        Z = loop.buffers(s.M, s.layout.size, False)
        T = np.zeros(len(PROBES), dtype=np.int64)
        c0, w0 = rdtsc_py(), time.perf_counter()
        status = integrate(s.M, s.excitation, s.tableau, s.state, s.config, R, Z, t_end, 10 ** 9, T)
        c1, w1 = rdtsc_py(), time.perf_counter()
        assert status == loop.DONE, status
        if r:  # the first compiles
            best = np.minimum(best, T)
            rate = max(rate, (c1 - c0) / (w1 - w0))
    st = s.stats
    n = st["steps"]
    ns = best / rate * 1e9 / n
    print(f"{name}, rtol {a.rtol:g}: {n} steps ({st['quiet_steps']} quiet, {st['spared_steps']} spared, "
          f"{st['rejected']} rejected), "
          f"{st['rhs_evaluations']} RHS evaluations; cycle counter {rate / 1e9:.2f} GHz; minimum of {a.repeats}")
    print("| section | ns a step | share |\n|---|---|---|")
    for (_, label), v in zip(PROBES[1:], ns[1:]):
        print(f"| {label} | {v:.0f} | {100 * v / ns[1:].sum():.0f} % |")
    print(f"| all | {ns[1:].sum():.0f} | |")


@nb.njit
def _rdtsc():
    return rdtsc()


def rdtsc_py() -> int:
    return _rdtsc()


if __name__ == "__main__":
    main()

"""How many reference-count operations numba's compiled code still makes per step (docs/solver.md, "Reference
counts"): numba's runtime is built with counting functions that also add one to a counter, and a run of each scene
reads it before and after. The counter's address is compiled into the code, so this process compiles into a
temporary numba cache of its own (a few minutes) and never into the checkout's.
Run: .venv/bin/python benchmarks/refcount_ops.py"""
from __future__ import annotations

import ctypes
import os
import tempfile

os.environ["NUMBA_CACHE_DIR"] = tempfile.mkdtemp(prefix="grapefmu-refcount-ops-")  # before numba reads it

from llvmlite import ir  # noqa: E402
from numba.core.runtime import nrtdynmod  # noqa: E402

import grapefmu.physics.compiled  # noqa: E402,F401  (its plain counts first; the counting ones replace them below)

COUNT = ctypes.c_int64(0)


def _counting_inc_dec(module, op, ordering):
    """nrt_atomic_add / nrt_atomic_sub as compiled.py's plain ones, adding one to COUNT as well."""
    word = nrtdynmod._word_type
    fn = ir.Function(module, ir.FunctionType(word, [word.as_pointer()]), name=f"nrt_atomic_{op}")
    [ptr] = fn.args
    b = ir.IRBuilder(fn.append_basic_block())
    cell = b.inttoptr(ir.Constant(word, ctypes.addressof(COUNT)), word.as_pointer())
    b.store(b.add(b.load(cell), ir.Constant(word, 1)), cell)
    new = getattr(b, op)(b.load(ptr), ir.Constant(word, 1))
    b.store(new, ptr)
    b.ret(new)
    return fn


nrtdynmod._define_atomic_inc_dec = _counting_inc_dec  # numba's runtime has not started yet: it builds these

from grapefmu.bench.scale import scene  # noqa: E402
from grapefmu.bench.scenes import bench_scenes, build  # noqa: E402
from grapefmu.solver.islands import Islands  # noqa: E402
from grapefmu.solver.solver import Solver  # noqa: E402


def main() -> None:
    cases = [("paper collision, rtol 1e-6", build(bench_scenes()["paper collision"]), Solver),
             ("10-berry cluster", scene("cluster", 10), Solver), ("100-berry cluster", scene("cluster", 100), Solver),
             ("100-berry cluster in islands", scene("cluster", 100), Islands)]
    print("| scene | steps | reference-count operations | per step |\n|---|---|---|---|")
    for name, sc, how in cases:
        kw = {"rtol": 1e-6, "atol": 1e-8} if how is Solver and "collision" in name else {}
        how(sc, **kw).run()  # compiled
        before = COUNT.value
        run = how(sc, **kw).run()
        ops = COUNT.value - before
        steps = run.stats["steps"]
        print(f"| {name} | {steps} | {ops} | {ops / steps:.0f} |")


if __name__ == "__main__":
    main()

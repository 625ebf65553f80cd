"""numba's reference counts are plain increments in grapefmu's process, inlined into the machine code
(physics/compiled.py): safe only while no compiled function releases the GIL, and it must not change a single number
nor keep anything alive. The cache is stamped with every core source and with how references are counted."""
from __future__ import annotations

import ast
import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import grapefmu
from grapefmu.bench.scenes import bench_scenes

ROOT = Path(__file__).resolve().parents[1]

RUN = """
import gc, json, weakref, numpy as np, grapefmu
from numba.core.runtime import rtsys
from grapefmu.physics.compiled import PLAIN_REFCOUNTS
from grapefmu.bench.scenes import bench_scenes, build
out = {"plain": PLAIN_REFCOUNTS}
for name in ("paper collision", "pick and place"):
    run = grapefmu.simulate(build(bench_scenes()[name]), rtol=1e-8, atol=1e-10, output_interval=1e-3)
    out[name] = [run.y.tolist(), run.impacts.onset.tolist(), run.peak_force.tolist(), run.stats["steps"]]
    recorded = weakref.ref(run.y.base if run.y.base is not None else run.y)
    del run
    gc.collect()
    out[name + ": run's memory freed"] = recorded() is None
before = rtsys.get_allocation_stats()
for _ in range(3):
    grapefmu.simulate(build(bench_scenes()["shaken stiff pair"]), rtol=1e-6, atol=1e-8)
gc.collect()
after = rtsys.get_allocation_stats()
out["numba allocations not freed"] = (after.alloc - before.alloc) - (after.free - before.free)
print(json.dumps(out))
"""


def test_no_compiled_function_releases_the_gil():
    """The precondition of plain counts: no nogil, parallel or prange anywhere in the compiled code's packages."""
    offenders = []
    for base in ("src", "fmu_build", "ros_node"):
        for path in (ROOT / base).rglob("*.py"):
            for node in ast.walk(ast.parse(path.read_text())):
                if isinstance(node, ast.keyword) and node.arg in ("nogil", "parallel") and not (
                        isinstance(node.value, ast.Constant) and node.value.value is False):
                    offenders.append(f"{path.relative_to(ROOT)}:{node.lineno} {node.arg}")
                name = getattr(node, "id", getattr(node, "attr", ""))
                if isinstance(node, ast.Name | ast.Attribute) and name == "prange":
                    offenders.append(f"{path.relative_to(ROOT)}:{node.lineno} prange")
    assert not offenders, offenders


def _run(atomic: bool, cache: Path) -> dict:
    env = {**os.environ, "PYTHONPATH": str(ROOT / "src"), "NUMBA_NRT_STATS": "1"}
    env.pop("GRAPEFMU_ATOMIC_REFCOUNTS", None)
    if atomic:  # its counts are compiled into its functions: a cache of its own
        env["GRAPEFMU_ATOMIC_REFCOUNTS"] = "1"
        env["NUMBA_CACHE_DIR"] = str(cache)
    out = subprocess.run([sys.executable, "-c", RUN], env=env, capture_output=True, text=True, timeout=600, check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def test_plain_counts_are_on_and_change_no_number(tmp_path):
    """The same runs in a process with numba's atomic counts (GRAPEFMU_ATOMIC_REFCOUNTS=1) and one with plain counts:
    identical trajectories, impacts and peaks, bit for bit; and in both, numba frees what it holds: a run's arrays
    go when the run does, and every allocation numba's runtime made in three runs is freed by their end (numba's
    counters, NUMBA_NRT_STATS). numba's own plain-count switch froze every count above zero: a 2 s run leaked
    0.46 MB."""
    plain, atomic = _run(False, tmp_path), _run(True, tmp_path)
    assert plain.pop("plain") is True and atomic.pop("plain") is False
    assert plain == atomic
    for name in ("paper collision", "pick and place"):
        assert plain[name + ": run's memory freed"]
    assert plain["numba allocations not freed"] == 0


INLINED = r"""
import json
import numpy as np
from numba import njit
from numba.core.runtime import rtsys
import grapefmu.physics.compiled  # inlines the counts into what numba compiles from now on

@njit
def ones(n):
    return np.ones(n)

@njit
def total(n):
    s = 0.0
    for i in range(n):
        s += ones(i % 3 + 1).sum()  # each array made in the call is dropped after its sum: a decrement
    return s

total(1)  # compiled, numba's runtime started
before = rtsys.get_allocation_stats()
value = total(1000)
after = rtsys.get_allocation_stats()
library = total.overloads[total.signatures[0]].library
calls = lambda text: text.count("call void @NRT_incref(") + text.count("call void @NRT_decref(")
print(json.dumps({"value": value, "in its machine code": calls(library.get_llvm_str()),
                  "in what callers link": calls(str(library._get_module_for_linking())),
                  "not freed": (after.alloc - before.alloc) - (after.free - before.free)}))
"""


def test_the_counts_are_inlined_where_they_run_and_calls_where_callers_prune():
    """physics/compiled._counts_inlined: no call to NRT_incref or NRT_decref is left in a function's machine code,
    the module its callers link in keeps them (numba prunes counts across an inlined callee by those calls), the
    result is right and every array made is freed (numba's counters)."""
    env = {**os.environ, "PYTHONPATH": str(ROOT / "src"), "NUMBA_NRT_STATS": "1"}
    out = subprocess.run([sys.executable, "-c", INLINED], env=env, capture_output=True, text=True, timeout=300,
                         check=True)
    got = json.loads(out.stdout.strip().splitlines()[-1])
    assert got["value"] == 334 * 1 + 333 * 2 + 333 * 3
    assert got["in its machine code"] == 0
    assert got["in what callers link"] > 0
    assert got["not freed"] == 0


def test_the_fmus_import_path_loads_no_scipy_integrate():
    """Importing scipy.integrate inside a C host's embedded Python made the host's exit crash on a corrupted heap
    (tests/test_fmu_hardening.py); what the FMU imports to step and report must not load it."""
    code = ("import sys, grapefmu, grapefmu_fmu.core, grapefmu_fmu.fmi2, grapefmu_fmu.fmi3\n"
            "from grapefmu import Solver\nfrom grapefmu.scenefile import load_scene\n"
            f"s = Solver(load_scene({str(ROOT / 'scenes' / 'default.toml')!r}), driven=True)\n"
            "s.advance(1e-3, (1.0, 0.0, 0.0, 0.0, 0.0, 0.0)); s.snapshot()\n"
            "print(sorted(m for m in sys.modules if m.startswith('scipy.integrate')))")
    env = {**os.environ, "PYTHONPATH": f"{ROOT / 'src'}{os.pathsep}{ROOT / 'fmu_build'}"}
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=600, check=True)
    assert out.stdout.strip().splitlines()[-1] == "[]"


ISLANDS_RUN = """
import numba.core.event as ev
compiled = []
class Listener(ev.Listener):
    def on_start(self, event):
        compiled.append(event.data["dispatcher"].py_func.__qualname__)
    def on_end(self, event):
        pass
ev.register("numba:compile", Listener())
from grapefmu.bench.scale import scene
from grapefmu.solver.islands import Islands
it = Islands(scene("cluster", 10))
it.run(0.3)
print(it.formed, sorted(set(compiled)))
"""


def test_a_second_process_runs_islands_without_compiling():
    """Islands keep their sessions in a numba list that cached compiled functions build and change (session.listed,
    put, take_last): a typed list's methods called from Python are compiled anew in every process (1.5 to 3 s before
    each process's first islands run). After a first process has filled numba's cache, a second one compiles
    nothing (numba's compile events; loading from the cache raises none)."""
    env = {**os.environ, "PYTHONPATH": str(ROOT / "src")}
    for _ in range(2):
        out = subprocess.run([sys.executable, "-c", ISLANDS_RUN], env=env, capture_output=True, text=True,
                             timeout=900, check=True)
    formed, compiled = out.stdout.strip().splitlines()[-1].split(" ", 1)
    assert int(formed) > 3  # islands formed and retired: the list was built and changed
    assert compiled == "[]", compiled


_CACHED = r'''
import numpy as np
from grapefmu.solver.drift import components
components(3, np.array([0]), np.array([1]), np.empty(3, np.int64))
print(sum(components.stats.cache_hits.values()), sum(components.stats.cache_misses.values()))
'''


def test_an_edit_to_any_core_source_retires_every_cached_function(tmp_path):
    """numba checks a cached function against its own file only, but its machine code holds what it calls or
    inlines from other files: the cache is stamped with every core source as well (physics/compiled.STAMP). A
    function whose own file did not change is loaded from the cache until another core file changes, then compiled
    again."""
    pkg = tmp_path / "pkg"
    shutil.copytree(Path(grapefmu.__file__).parent, pkg / "grapefmu", ignore=shutil.ignore_patterns("__pycache__"))
    env = {**os.environ, "PYTHONPATH": str(pkg), "NUMBA_CACHE_DIR": str(tmp_path / "cache")}

    def run() -> tuple[int, int]:
        out = subprocess.run([sys.executable, "-c", _CACHED], env=env, capture_output=True, text=True, timeout=300)
        assert out.returncode == 0, out.stderr
        hits, misses = map(int, out.stdout.split())
        return hits, misses

    assert run() == (0, 1)   # compiled
    assert run() == (1, 0)   # loaded: drift.py is unchanged
    with open(pkg / "grapefmu/physics/kinematics.py", "a") as f:
        f.write("\n# an edit elsewhere in the core\n")
    assert run() == (0, 1)   # compiled again, though drift.py is still unchanged
    assert run() == (1, 0)


BOUNDS = r"""
import json, sys
import numpy as np
import grapefmu
from grapefmu import Solver, load_scene
from grapefmu.bench.scale import scene as scale_scene
from grapefmu.bench.scenes import bench_scenes, build
from grapefmu.solver.islands import Islands
scenes = sys.argv[1]
out = {}

def keep(name, run):
    out[name] = [run.y.tolist(), run.impacts.onset.tolist(), run.peak_force.tolist(), run.totals.tolist()]

for name, s in bench_scenes().items():  # both pairs: DOPRI5 at 1e-5, DOP853 at 1e-10
    for rtol in (1e-5, 1e-10):
        keep(f"{name} at {rtol}", grapefmu.simulate(build(s), rtol=rtol, atol=rtol * 1e-2))
keep("paper method", grapefmu.simulate(load_scene(f"{scenes}/default.toml"), 1.0, method="paper"))
keep("fixed step", grapefmu.simulate(load_scene(f"{scenes}/default.toml"), 1.0, fixed_step=2e-4))
keep("obstacles", grapefmu.simulate(load_scene(f"{scenes}/setdown_fast.toml")))
keep("cluster", grapefmu.simulate(scale_scene("cluster", 30), 0.3))
keep("islands", Islands(scale_scene("cluster", 30)).run(0.3))
s = Solver(load_scene(f"{scenes}/default.toml"), driven=True)  # as the FMU's and the node's (a planar scene
for k in range(400):                                                 # turns about the rachis' y axis only)
    s.advance(1e-3, base_accel=(3.0 * np.sin(0.05 * k), -2.0, 1.0, 0.0, 20.0 * np.cos(0.02 * k), 0.0),
              angular_velocity=(0.0, 0.5 * np.sin(0.03 * k), 0.0))
out["advance"] = [s.state.physical.y.tolist(), s.take_impacts().onset.tolist()]
print(json.dumps(out))
"""


def test_no_compiled_function_indexes_out_of_bounds(tmp_path):
    """The core compiled with numba's bounds checks (NUMBA_BOUNDSCHECK=1, in a cache of its own) runs every benchmark
    scene with both pairs, the paper method, a fixed step, obstacles, a cluster with one step size and in islands,
    and a turning rachis driven through advance(), without an index out of range, and computes the same numbers,
    bit for bit, as the core without them. Why: without the checks an index out of range writes into whatever lies
    beyond the array (a stale cache once did: free(): invalid pointer, physics/compiled._stamped), and the crash
    comes later, elsewhere, or at the process's exit."""
    env = {**os.environ, "PYTHONPATH": str(ROOT / "src")}
    checked = {**env, "NUMBA_BOUNDSCHECK": "1", "NUMBA_CACHE_DIR": str(tmp_path / "cache")}

    def run(e: dict) -> str:
        r = subprocess.run([sys.executable, "-c", BOUNDS, str(ROOT / "scenes")], env=e, capture_output=True,
                           text=True, timeout=1200)
        assert r.returncode == 0, r.stderr[-3000:]
        return r.stdout.strip().splitlines()[-1]

    plain, bounded = run(env), run(checked)
    assert len(json.loads(plain)) == 2 * len(bench_scenes()) + 6
    assert plain == bounded  # as text: every float's repr, NaN and infinities included

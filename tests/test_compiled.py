"""numba's reference counts are plain increments in grapefmu's process (physics/compiled.py): safe only while no
compiled function releases the GIL, and it must not change a single number."""
from __future__ import annotations

import ast
import json
import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

RUN = """
import json, numpy as np, grapefmu
from grapefmu.physics.compiled import PLAIN_REFCOUNTS
from grapefmu.bench.scenes import bench_scenes, build
out = {"plain": PLAIN_REFCOUNTS}
for name in ("paper collision", "pick and place"):
    run = grapefmu.simulate(build(bench_scenes()[name]), rtol=1e-8, atol=1e-10, output_interval=1e-3)
    out[name] = [run.y.tolist(), run.impacts.onset.tolist(), run.peak_force.tolist(), run.stats["steps"]]
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
                if isinstance(node, ast.Name | ast.Attribute) and getattr(node, "id", getattr(node, "attr", "")) == "prange":
                    offenders.append(f"{path.relative_to(ROOT)}:{node.lineno} prange")
    assert not offenders, offenders


def _run(atomic: bool) -> dict:
    env = {**os.environ, "PYTHONPATH": str(ROOT / "src")}
    env.pop("GRAPEFMU_ATOMIC_REFCOUNTS", None)
    if atomic:
        env["GRAPEFMU_ATOMIC_REFCOUNTS"] = "1"
    out = subprocess.run([sys.executable, "-c", RUN], env=env, capture_output=True, text=True, timeout=600, check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def test_plain_counts_are_on_and_change_no_number():
    """The same runs in a process with numba's atomic counts (GRAPEFMU_ATOMIC_REFCOUNTS=1) and one with plain counts:
    identical trajectories, impacts and peaks, bit for bit."""
    plain, atomic = _run(False), _run(True)
    assert plain.pop("plain") is True and atomic.pop("plain") is False
    assert plain == atomic


def test_the_fmus_import_path_loads_no_scipy_integrate():
    """Importing scipy.integrate inside a C host's embedded Python made the host's exit crash on a corrupted heap
    (tests/test_fmu_hardening.py); what the FMU imports to step and report must not load it."""
    code = ("import sys, grapefmu, grapefmu_fmu.core, grapefmu_fmu.fmi2, grapefmu_fmu.fmi3\n"
            "from grapefmu import Solver\nfrom grapefmu.scenefile import load_scene\n"
            f"s = Solver(load_scene({str(ROOT / 'scenes' / 'default.toml')!r}), turning=True)\n"
            "s.advance(1e-3, (1.0, 0.0, 0.0, 0.0, 0.0, 0.0)); s.snapshot()\n"
            "print(sorted(m for m in sys.modules if m.startswith('scipy.integrate')))")
    env = {**os.environ, "PYTHONPATH": f"{ROOT / 'src'}{os.pathsep}{ROOT / 'fmu_build'}"}
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=600, check=True)
    assert out.stdout.strip().splitlines()[-1] == "[]"

"""How often a Python host that used the FMU aborts at exit (docs/reliability.md, "A Python host ends normally after
using the FMU"): each version's FMU is instantiated, stepped and freed five times in a fresh process that then exits
normally, N times; a run that ends in SIGABRT counts. The same work without the FMU is the control.
Run: .venv/bin/python benchmarks/fmu_exit_aborts.py [N]   (default 16)"""
from __future__ import annotations

import os
import subprocess
import sys
import tempfile
from pathlib import Path

CONTROL = """
from grapefmu_fmu.core import FmuCore
from grapefmu.scenefile import default_scene_path
import pythonfmu3, fmpy  # noqa: F401
for k in range(5):
    c = FmuCore(default_scene_path())
    c.initialize()
    c.step(0.0, 1e-3)
    c.output("angle_left")
"""


def aborts(args: list[str], n: int) -> int:
    return sum(subprocess.run([sys.executable, *args], capture_output=True).returncode < 0 for _ in range(n))


def main() -> None:
    n = int(sys.argv[1]) if len(sys.argv) > 1 else 16
    with tempfile.TemporaryDirectory() as d:
        os.environ["TMPDIR"] = d  # fmpy's extract makes a directory per FMU and never removes it: here, it goes with d
        rows = []
        for v in (2, 3):
            fmu = Path(d) / f"default{v}.fmu"
            subprocess.run([sys.executable, "-m", "grapefmu", "build-fmu", "-o", str(fmu), "--fmi", str(v)], check=True,
                           capture_output=True)
            rows.append((f"FMI {v}.0 FMU, 5 instances", aborts(["-m", "grapefmu_fmu.exit_host", str(fmu), str(v)], n)))
        rows.append(("the same work without an FMU", aborts(["-c", CONTROL], n)))
    print(f"processes that aborted at exit, of {n}:")
    for label, k in rows:
        print(f"  {label:<32} {k}")


if __name__ == "__main__":
    main()

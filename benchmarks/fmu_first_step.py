"""How long a new process waits before its first FMU step: instantiate + initialize + first doStep, through
fmpy, in a fresh per-user cache (GRAPEFMU_CACHE), three ways:
  first use   - the FMU on a machine where it never ran (the compiled core shipped in the FMU is loaded),
  second use  - a new process after that (the cache that survives extraction),
  cold        - as on a CPU the shipped core does not fit: the shipped cache removed, so numba compiles.
Run: .venv/bin/python benchmarks/fmu_first_step.py"""
from __future__ import annotations

import os
import subprocess
import sys
import tempfile
import zipfile
from pathlib import Path

WORKER = """
import sys, time
t0 = time.perf_counter()
from fmpy import extract, read_model_description
from fmpy.fmi2 import FMU2Slave
path = sys.argv[1]
md = read_model_description(path)
vr = {v.name: v.valueReference for v in md.modelVariables}
f = FMU2Slave(guid=md.guid, unzipDirectory=extract(path), modelIdentifier=md.coSimulation.modelIdentifier,
              instanceName="a")
f.instantiate(); f.setupExperiment(startTime=0.0); f.enterInitializationMode(); f.exitInitializationMode()
f.setReal([vr["base_ax"]], [1.0]); f.doStep(0.0, 1e-3)
print("SECONDS", time.perf_counter() - t0)
f.terminate(); f.freeInstance()
"""


def first_step(python: str, fmu: Path, cache: Path) -> float:
    env = {**os.environ, "GRAPEFMU_CACHE": str(cache)}
    out = subprocess.run([python, "-c", WORKER, str(fmu)], capture_output=True, text=True, env=env, check=True)
    return float(out.stdout.split("SECONDS", 1)[1])


def main() -> None:
    with tempfile.TemporaryDirectory() as d:
        os.environ["TMPDIR"] = d  # fmpy's extract makes a directory per FMU and never removes it: here, it goes with d
        d = Path(d)
        fmu = d / "default.fmu"
        subprocess.run([sys.executable, "-m", "grapefmu", "build-fmu", "-o", str(fmu)], check=True, capture_output=True)
        # a Python with only fmpy and the FMU's own requirements, as a co-simulation user has
        subprocess.run([sys.executable, "-m", "venv", str(d / "venv")], check=True)
        python = str(d / "venv" / "bin" / "python")
        (d / "req.txt").write_bytes(zipfile.ZipFile(fmu).read("resources/requirements.txt"))
        subprocess.run([python, "-m", "pip", "install", "-q", "fmpy", "-r", str(d / "req.txt")], check=True,
                       capture_output=True)
        cache = d / "cache"
        rows = [("first use on this machine", first_step(python, fmu, cache)),
                ("second use (new process)", first_step(python, fmu, cache))]
        for f in cache.rglob("*.nb[ic]"):
            f.unlink()
        rows += [("cold: nothing compiled (other CPU)", first_step(python, fmu, cache)),
                 ("after the cold run (new process)", first_step(python, fmu, cache))]
    print("new process: instantiate + initialize + first 1 ms doStep, fmpy, FMI 2.0, default scene")
    for label, s in rows:
        print(f"  {label:<38} {s:7.2f} s")


if __name__ == "__main__":
    main()

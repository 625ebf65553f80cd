"""Where a run's time goes, compiled functions by name: `perf` samples a process that runs a scene again and again,
and a perf map (/tmp/perf-<pid>.map) names numba's machine code, which perf otherwise shows as bare [JIT]
addresses. numba keeps a function's object code in memory only when it compiles it in that process, so the child
compiles into an empty cache directory first (a few minutes); functions inlined into their callers count as the
caller. What perf still cannot name is numba's runtime (reference counts: a few hex addresses close together).
Needs `perf` (linux-tools) and permission to attach (perf_event_paranoid ≤ 1, or root).
`islands N` runs the cluster of N berries in multirate islands (Islands(scene).run()).
Run: .venv/bin/python benchmarks/perf_compiled.py [collision | cluster N | islands N] [--seconds 8] [--rtol 1e-6]"""
from __future__ import annotations

import argparse
import os
import re
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
CHILD = r'''
import gc, os, re, subprocess, sys, tempfile, time
import grapefmu
from numba.core.registry import CPUDispatcher
from grapefmu.bench.scale import scene as scale_scene
from grapefmu.bench.scenes import bench_scenes, build
from grapefmu.solver.islands import Islands
from grapefmu.solver.solver import Solver
which, n, rtol, seconds, ready = sys.argv[1], sys.argv[2], float(sys.argv[3]), float(sys.argv[4]), sys.argv[5]
sc = build(bench_scenes()["paper collision"]) if which == "collision" else scale_scene("cluster", int(n))
kw = dict(rtol=rtol, atol=rtol / 100)
run = (lambda: Islands(sc, **kw).run(output_interval=1e-3)) if which == "islands" else (
    lambda: Solver(sc, **kw).run(output_interval=1e-3))
run()  # compiles everything a run uses
names = {}
for obj in gc.get_objects():
    try:
        if not isinstance(obj, CPUDispatcher):
            continue
    except ReferenceError:  # a weak proxy whose object is gone
        continue
    for cres in obj.overloads.values():
        lib = cres.library
        code = getattr(lib, "_compiled_object", None)
        if not code:
            continue
        with tempfile.NamedTemporaryFile(suffix=".o", delete=False) as fh:
            fh.write(code)
        nm = subprocess.run(["nm", "-S", "--defined-only", fh.name], capture_output=True, text=True).stdout
        os.unlink(fh.name)
        for line in nm.splitlines():
            parts = line.split()
            if len(parts) != 4 or parts[2] not in "tT":
                continue
            try:
                addr = lib.get_pointer_to_function(parts[3])
            except Exception:
                continue
            if addr:
                names[addr] = (int(parts[1], 16), parts[3])
def short(mangled):
    rest, out = mangled[3:] if mangled.startswith("_ZN") else "", []
    while rest[:1].isdigit():
        k = len(rest) - len(rest.lstrip("0123456789"))
        n = int(rest[:k]); out.append(rest[k:k + n]); rest = rest[k + n:]
    return ".".join(out) or mangled
with open(f"/tmp/perf-{os.getpid()}.map", "w") as fh:
    for a in sorted(names):
        fh.write(f"{a:x} {names[a][0]:x} {short(names[a][1])}\n")
open(ready, "w").write(str(os.getpid()))
t0, runs = time.perf_counter(), 0
while time.perf_counter() - t0 < seconds:
    run()
    runs += 1
print(f"{runs} runs, {(time.perf_counter() - t0) / runs * 1e3:.3f} ms each (under perf)")
'''


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("scene", nargs="*", default=["collision"])
    ap.add_argument("--seconds", type=float, default=8.0)
    ap.add_argument("--rtol", type=float, default=1e-6)
    ap.add_argument("--top", type=int, default=30)
    a = ap.parse_args()
    which, n = (a.scene[0], a.scene[1]) if a.scene[0] in ("cluster", "islands") else ("collision", "0")
    if not shutil.which("perf"):
        sys.exit("perf_compiled: `perf` is not installed (linux-tools)")
    work = Path(tempfile.mkdtemp(prefix="grapefmu-perf-"))
    ready, data = work / "ready", work / "perf.data"
    env = {**os.environ, "NUMBA_CACHE_DIR": str(work / "numba"), "PYTHONPATH": str(ROOT / "src")}
    child = subprocess.Popen([sys.executable, "-c", CHILD, which, n, str(a.rtol), str(a.seconds + 2), str(ready)],
                             env=env)
    print("compiling into an empty cache (a few minutes) ...", flush=True)
    while not ready.exists():
        if child.poll() is not None:
            sys.exit(f"perf_compiled: the child stopped ({child.returncode})")
        time.sleep(0.5)
    pid = ready.read_text()
    subprocess.run(["perf", "record", "-q", "-F", "4999", "-p", pid, "-o", str(data), "--", "sleep", str(a.seconds)],
                   check=True)
    child.wait()
    for sort, top in (("dso", 8), ("dso,symbol", a.top)):
        out = subprocess.run(["perf", "report", "-i", str(data), "--no-children", "--sort", sort, "--stdio", "-q"],
                             capture_output=True, text=True).stdout
        print(f"--- by {sort}")
        for line in out.splitlines()[:top]:
            print(re.sub(r"(\s+-)+\s*$", "", re.sub(r"\s{2,}", "  ", line.strip())))
    Path(f"/tmp/perf-{pid}.map").unlink(missing_ok=True)
    shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    main()

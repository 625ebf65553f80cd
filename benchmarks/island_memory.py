"""What an islands run holds in memory: the pick-and-place cluster of N berries (rtol 1e-6) run for each duration
in multirate islands, each in a fresh process, its peak resident memory less what the process held before the run
(the compiled code loaded by a 10-berry run first), against the size of the run's own sample arrays. An island's
recorder holds one window (handover.flush), so the memory grows as the run's own arrays do (docs/solver.md,
"Multirate islands").
Run: .venv/bin/python benchmarks/island_memory.py [N] [seconds ...]   (default: 300 1 4)"""
from __future__ import annotations

import subprocess
import sys

CHILD = r'''
import resource, sys, time
from grapefmu.bench.scale import scene
from grapefmu.solver.islands import Islands
n, t_end = int(sys.argv[1]), float(sys.argv[2])
Islands(scene("cluster", 10)).run()
before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
t = time.perf_counter()
run = Islands(scene("cluster", n)).run(t_end)
t = time.perf_counter() - t
grew = (resource.getrusage(resource.RUSAGE_SELF).ru_maxrss - before) / 1024
print(f"{n} berries, {t_end:g} s simulated: peak resident memory +{grew:.0f} MB (the run's samples "
      f"{run.y.nbytes / 2**20:.0f} MB), {t:.2f} s")
'''


def main(argv: list[str]) -> None:
    n = argv[0] if argv else "300"
    for seconds in argv[1:] or ["1", "4"]:
        subprocess.run([sys.executable, "-c", CHILD, n, seconds], check=True)


if __name__ == "__main__":
    main(sys.argv[1:])

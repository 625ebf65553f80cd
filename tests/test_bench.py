"""`grapefmu bench --quick` runs end to end, so the benchmark cannot rot. Correctness of the harness only:
no assertion here is about time."""
from __future__ import annotations

import math
import re
import subprocess
import sys

from grapefmu.bench.harness import Row, cost_at


def test_quick_bench_reports_every_method_against_agreeing_references(tmp_path):
    out = tmp_path / "benchmarks.md"
    r = subprocess.run([sys.executable, "-m", "grapefmu", "bench", "--quick", "--out", str(out), "--plots",
                        str(tmp_path / "plots")], capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr[-2000:]
    text = out.read_text()
    assert "grapefmu bench --quick" in text and "cores" in text
    for scene in ("paper collision", "grazing"):
        assert f"## {scene}" in text
        assert (tmp_path / "plots" / f"{scene.replace(' ', '_')}.png").stat().st_size > 5000
        agree = float(re.search(rf"## {scene}.*?\| reference check \| [^|]* \| — \| ([0-9.e+-]+)", text, re.S).group(1))
        assert agree <= 1e-10
        rows = re.findall(rf"\| grapefmu event \| rtol ([0-9.e-]+) \| [0-9.]+ \| ([0-9.e+-]+) \|",
                          text.split(f"## {scene}")[1].split("## ")[0])
        errors = [float(e) for _, e in rows]
        assert len(errors) == 3 and errors[0] > errors[1] > errors[2]  # tighter tolerance, smaller error
        assert errors[1] < 1e-4
    for method in ("paper (ode23 check at step ends)", "scipy DOP853+events"):
        assert method in text


def test_cost_interpolation_and_failures():
    rows = [Row("s", "m", "a", 1e-3, 1e-4, 0, 1, 1, 0, 0, 10), Row("s", "m", "b", 1e-2, 1e-8, 0, 1, 1, 0, 0, 10),
            Row("s", "m", "c", math.nan, math.nan, math.nan, None, 1, math.nan, math.nan, None, failure="x")]
    c = cost_at(rows, 1e-6)
    assert math.isclose(c, math.sqrt(1e-3 * 1e-2), rel_tol=1e-12)  # halfway in log error, halfway in log cost
    assert math.isnan(cost_at(rows, 1e-10))  # never reached: not extrapolated

"""A CSV acceleration table (docs/scenes.md, [excitation] kind = "csv"): linear between rows, zero before the first,
and after the last what `after` says. The reference is a fine quadrature of the table as the docs describe it, not
the table the code compiles."""
from __future__ import annotations

import numpy as np
import pytest
from scipy.integrate import cumulative_trapezoid

from grapefmu import simulate

from .conftest import dual, scene

ROWS = np.array([[0.02, 0.0, 0.0], [0.05, 3.0, -1.0], [0.1, -2.0, 2.0], [0.15, 0.5, 0.0], [0.2, 1.0, -0.5]])


@pytest.mark.parametrize("after", ["zero", "hold"])
def test_the_rachis_follows_a_csv_table_then_what_after_says(after):
    text = "time,ax,az\n" + "".join(f"{float(t)!r},{float(a)!r},{float(b)!r}\n" for t, a, b in ROWS)
    doc = dual(berries=dual(d0=0.2)["berries"], excitation={"kind": "csv", "text": text, "after": after},
               solver={"t_end": 0.3, "rtol": 1e-10, "atol": 1e-13, "output_interval": 0.005})
    run = simulate(scene(doc))
    end = ROWS[-1, 0]
    t = np.sort(np.concatenate([np.linspace(0.0, 0.3, 30001), ROWS[:, 0], [end]]))  # the last row twice: its jump
    jump = np.searchsorted(t, end, side="right") - 1
    for col, axis in ((1, 0), (2, 2)):
        a = np.where((t >= ROWS[0, 0]) & (t <= end), np.interp(t, ROWS[:, 0], ROWS[:, col]), 0.0)
        a[jump:] = np.where(t[jump:] >= end, ROWS[-1, col] if after == "hold" else 0.0, a[jump:])
        x = cumulative_trapezoid(cumulative_trapezoid(a, t, initial=0.0), t, initial=0.0)
        assert np.abs(run.base_displacement[:, axis] - np.interp(run.t, t, x)).max() < 1e-8
        k = run.t < end  # at the last row itself a sample reports the piece before it
        assert np.abs(run.accel[k, axis] - np.interp(run.t[k], ROWS[:, 0], ROWS[:, col], left=0.0)).max() < 1e-12

"""Single shooting against the segment-wise fit on a long record with collisions, from a poor start
(docs/fit_and_risk.md, the method's Segments item). 6 s of the dual system released from −0.8 rad (4 collisions;
both angles, 100 Hz, 1 mrad), five parameters started 1.5–4 times off the truth; for each number of segments:
the residual σ̂, the evaluations, the wall time, each estimate's distance from the truth in standard errors,
and how many residual traces the fit flagged as structured (a local minimum).
Run: .venv/bin/python benchmarks/fit_segments.py"""
from __future__ import annotations

import copy
import time
from pathlib import Path

import numpy as np

from grapefmu.fit import fit, parameters
from grapefmu.fit.camera import camera_data
from grapefmu.fit.measured import Measured, angle_column, time_column
from grapefmu.scenefile import scene_from_dict

KYOHO = {"mass": 0.011, "radius": 0.0135, "twig_length": 0.03, "hinge_damping": 2.6e-5}
TRUTH = {"berries": [{"name": "left", **KYOHO, "hinge_x": -0.015, "hinge_stiffness": 1.3e-3, "angle": -0.8},
                     {"name": "right", **KYOHO, "mass": 0.012, "radius": 0.014, "twig_length": 0.04, "hinge_x": 0.015,
                      "hinge_stiffness": 0.8e-3, "angle": 0.0}],
         "contact": {"law": "kelvin-voigt", "stiffness": 3500.0, "restitution": 0.42}, "solver": {"t_end": 6.0}}
TRUE = {"berries[0].hinge_stiffness": 1.3e-3, "berries[1].hinge_stiffness": 0.8e-3,
        "berries[*].hinge_damping": 2.6e-5, "contact.stiffness": 3500.0, "contact.restitution": 0.42}


def main() -> None:
    cols = camera_data(scene_from_dict(copy.deepcopy(TRUTH), Path.cwd()), seed=4)
    data = Measured(Path("long.csv"), cols[time_column()], ("left", "right"),
                    np.column_stack([cols[angle_column(d)] for d in ("left", "right")]), None)
    start = copy.deepcopy(TRUTH)
    for b in start["berries"]:
        b["hinge_stiffness"], b["hinge_damping"] = 2.0e-3, 1.2e-5
    start["contact"].update(stiffness=800.0, restitution=0.7)
    params = parameters(list(TRUE), start)
    print("| segments | σ̂ (mrad) | evaluations | wall (s) | (estimate − truth) / standard error "
          "| structured residuals |")
    print("|---|---|---|---|---|---|")
    for segments in (1, 2, 3, 6):
        t = time.perf_counter()
        res = fit(start, Path.cwd(), params, [data], segments=segments)
        z = ", ".join(f"{(e.value - TRUE[e.key]) / e.se:+.1f}" for e in res.estimates)
        flagged = sum("structured" in w for w in res.warnings)
        print(f"| {segments} | {1e3 * res.sigma:.2f} | {res.iterations} | {time.perf_counter() - t:.1f} | {z} | "
              f"{flagged or 'none'} |")


if __name__ == "__main__":
    main()

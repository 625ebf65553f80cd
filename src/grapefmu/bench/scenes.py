"""The benchmark scenes (issue 5): each a scene dict built from the dual-twig–berry defaults."""
from __future__ import annotations

import math
from pathlib import Path

from ..scenefile import scene_from_dict

KYOHO = {"mass": 0.011, "radius": 0.0135, "twig_length": 0.03, "hinge_stiffness": 1e-3, "hinge_damping": 2e-5}


def _dual(angles=(0.0, 0.0), d0=0.03, contact=None, excitation=None, t_end=2.0, left=None, right=None):
    lb = {"name": "left", **KYOHO, "hinge_x": -d0 / 2, "angle": angles[0], **(left or {})}
    rb = {"name": "right", **KYOHO, "hinge_x": d0 / 2, "angle": angles[1], **(right or {})}
    doc = {"berries": [lb, rb], "solver": {"t_end": t_end}}
    if contact is not False:
        doc["contact"] = contact or {"law": "kelvin-voigt", "stiffness": 2000.0, "restitution": 0.5}
    if excitation:
        doc["excitation"] = excitation
    return doc


def _graze_angle(pen=1e-6, d0=0.03, r=0.0135, length=0.03) -> float:
    """Release angle of the right berry whose swing overlaps the hanging left one by `pen` (m)."""
    from scipy.optimize import brentq
    return -brentq(lambda q: 2 * r - math.hypot(d0 + length * math.sin(q), length * (1 - math.cos(q))) - pen, -0.5, 0)


def bench_scenes(quick: bool = False) -> dict[str, dict]:
    s = {
        "free swing": _dual((-math.pi / 4, math.pi / 4), contact=False),
        "paper collision": _dual((0.0, math.pi / 4)),
        "stiff contact": _dual((0.0, math.pi / 4), contact={"law": "kelvin-voigt", "stiffness": 2e5, "restitution": 0.5},
                               t_end=1.0),
        "pre-compressed shaken": _dual(d0=0.026, excitation={"kind": "sine", "amplitude": [3.0, 2.0], "frequency": 5.0}),
        "grazing": _dual((0.0, _graze_angle()), left={"hinge_damping": 0.0}, right={"hinge_damping": 0.0}, t_end=1.0),
        "pick and place": _dual(right={"mass": 0.012, "radius": 0.014, "twig_length": 0.04},
                                excitation={"kind": "pick-and-place", "start": 0.1, "moves": [
                                    {"displacement": [0.0, 0.1], "duration": 0.4},
                                    {"displacement": [0.3, 0.0], "duration": 0.6},
                                    {"displacement": [0.0, -0.1], "duration": 0.4}]}),
        # stiff pedicels (11.7 and 10.5 Hz) nearly touching, shaken sideways at 6 Hz and 2 g: about 230 impacts
        # in 10 s (a sweep over hinge stiffness, frequency and amplitude found no softer pair above 90)
        "shaken stiff pair": _dual(d0=0.0272, left={"hinge_stiffness": 0.05}, right={"hinge_stiffness": 0.04},
                                   excitation={"kind": "sine", "amplitude": [20.0, 0.0], "frequency": 6.0}, t_end=10.0),
    }
    if quick:
        return {k: s[k] for k in ("paper collision", "grazing")}
    return s


def build(doc: dict):
    return scene_from_dict(doc, Path.cwd())

"""Random valid scenes across the documented ranges (docs/scenes.md), run by `Solver.run` with a step limit of
MAX_STEPS: every run must end with finite samples, or be refused by the scene (SceneError), or stop with a
SolverError that says why (a hinge too stiff for the step limit, refused before a step; the step limit of a stiff
scene; a spherical berry at its chart's pole). Anything else
(an exception of another kind, a NaN in the samples) is printed with its seed and scene, and counted. A finished
run whose energy ledger does not close to its tolerance (results/trust.py: the warning the run itself gives) is
counted too, with the tightest rtol among them: the conservation law as an independent check of the result; so is
one warned of a pair pressed beyond the depth a contact law holds at (results/trust.py, overlap_warning), and a run
stopped at the step limit prints the first pair it names in contact (stiffness.contact_hint).
docs/reliability.md gives the figures of one run.
Run: .venv/bin/python benchmarks/valid_scene_fuzz.py [first_seed] [count]   (default 150 300)
     .venv/bin/python benchmarks/valid_scene_fuzz.py --converge SEED   (a warned run again at tighter tolerances)"""
from __future__ import annotations

import copy
import math
import random
import sys
import time
import traceback
from collections import Counter
from pathlib import Path

import numpy as np

from grapefmu.errors import SceneError, SolverError
from grapefmu.results.trust import ledger_assessment, ledger_warning, overlap_warning
from grapefmu.scenefile import scene_from_dict
from grapefmu.solver.solver import Solver

MAX_STEPS = 300_000  # a stiff scene ends here in about a second instead of minutes at the default 10⁷


def logu(r: random.Random, lo: float, hi: float) -> float:
    """Uniform in log between lo and hi: each decade of a range as likely as another."""
    return math.exp(r.uniform(math.log(lo), math.log(hi)))


def signed(r: random.Random, lo: float, hi: float) -> float:
    return r.uniform(-1, 1) * logu(r, lo, hi)


def draw(r: random.Random) -> dict:
    """A scene document: 1–4 berries in a row on the rod (planar or, three times in ten, spherical), any contact
    law, gravity, tolerance and length of run, an excitation of each kind, now and then a floor."""
    n = r.choice([1, 2, 2, 3, 4])
    spherical = r.random() < 0.3
    berries, x = [], 0.0
    for k in range(n):
        radius = logu(r, 1e-3, 0.05)
        twig = min(radius * logu(r, 1.05, 20), 1.0)
        b = {"name": f"b{k}", "mass": logu(r, 1e-4, 10), "radius": radius, "twig_length": twig, "hinge_x": x,
             "hinge_stiffness": r.choice([0.0, logu(r, 1e-6, 1000)]),
             "hinge_damping": r.choice([0.0, logu(r, 1e-8, 1000)])}
        x += r.uniform(0.5, 2.2) * radius * 2
        if spherical:
            b.update(kind="spherical", angle=[r.uniform(-1.3, 1.3), r.uniform(-1.0, 1.0)],
                     angular_velocity=[signed(r, 1e-3, 1000), signed(r, 1e-3, 1000)])
        else:
            b.update(angle=r.uniform(-3.1, 3.1), angular_velocity=signed(r, 1e-3, 1000))
        berries.append(b)
    law = r.choice(["kelvin-voigt", "hertz", "hunt-crossley"])
    contact = {"law": law, "stiffness": logu(r, 1e-3, 1e9 if law == "kelvin-voigt" else 1e12)}
    if r.random() < 0.5:
        contact["restitution"] = r.uniform(0.01, 1.0)
    elif law == "kelvin-voigt":
        contact["damping"] = logu(r, 1e-6, 1e6)
    elif law == "hunt-crossley":
        contact["damping"] = r.uniform(0, 1000)
    doc = {"berries": berries, "contact": contact, "gravity": r.uniform(0, 100),
           "solver": {"t_end": r.choice([0.05, 0.2, 1.0]), "rtol": logu(r, 1e-12, 1e-2)}}
    doc["solver"]["atol"] = doc["solver"]["rtol"] * 1e-2
    kind = r.choice(["none", "sine", "impulse", "constant", "pick-and-place"])
    if kind == "sine":
        doc["excitation"] = {"kind": "sine", "amplitude": [signed(r, 1e-2, 1000), 0.0, signed(r, 1e-2, 1000)],
                             "frequency": logu(r, 0.1, 200)}
    elif kind == "impulse":
        doc["excitation"] = {"kind": "impulse", "peak": [r.uniform(-1000, 1000), 0.0, r.uniform(-1000, 1000)],
                             "start": 0.01, "duration": logu(r, 1e-4, 0.1)}
    elif kind == "constant":
        doc["excitation"] = {"kind": "constant", "accel": [r.uniform(-1000, 1000), 0.0, r.uniform(-1000, 1000)]}
    elif kind == "pick-and-place":
        doc["excitation"] = {"kind": "pick-and-place", "moves": [{
            "displacement": [r.uniform(-0.3, 0.3), 0.0, r.uniform(-0.3, 0.3)], "rotation": [0.0, r.uniform(-1, 1), 0.0],
            "duration": logu(r, 0.02, 1)}]}
    if r.random() < 0.3:
        doc["obstacles"] = [{"name": "floor", "kind": "plane", "point": [0, 0, -r.uniform(0.0, 0.5)], "normal": [0, 0, 1],
                             "law": "hunt-crossley", "stiffness": logu(r, 1e2, 1e9), "restitution": r.uniform(0.1, 1)}]
    return doc


def kind(e: SolverError) -> str:
    text = str(e)
    if "at the pole of its swing–tilt chart" in text:
        return "stopped: a spherical berry at its chart's pole"
    if "too stiff" in text:
        return "refused before a step: a hinge too stiff for the step limit (solver/stiffness.py)"
    if "step limit" in text:
        return "stopped: the step limit (stiff)"
    return "stopped: " + text.split(": ", 1)[1].split(";")[0]


def main(first: int = 150, count: int = 300) -> None:
    seen: Counter[str] = Counter()
    warned: list[float] = []  # the rtol of each finished run whose ledger warned
    wall = time.perf_counter()
    for s in range(first, first + count):
        doc = draw(random.Random(s))
        try:
            sc = scene_from_dict(copy.deepcopy(doc), Path.cwd())
            run = Solver(sc, max_steps=MAX_STEPS).run()
        except SceneError:
            seen["refused by the scene"] += 1
            continue
        except SolverError as e:
            seen[kind(e)] += 1
            if "step limit" in str(e):  # the stiffest hinge: its damping's time scale m l²/c against the step
                tau = min((b.mass * b.twig_length ** 2 / b.hinge_damping, b.name) for b in sc.model.berries
                          if b.hinge_damping > 0) if any(b.hinge_damping > 0 for b in sc.model.berries) else None
                h = str(e).split("the step size was ", 1)[1].split(",")[0]
                touching = str(e).split("in contact when it stopped: ", 1)  # the first pair named (contact_hint)
                print(f"seed {s}: stopped at the step limit with steps of {h}; the stiffest hinge's m l²/c: "
                      f"{f'{tau[0]:.3g} s ({tau[1]})' if tau else 'none'}; "
                      f"{'in contact: ' + touching[1].split('); ')[0] + ')' if len(touching) > 1 else 'no pair touching'}")
            continue
        except Exception:
            seen["DEFECT: another exception"] += 1
            print(f"seed {s}: {doc}")
            traceback.print_exc()
            continue
        if all(np.isfinite(np.asarray(a, dtype=float)).all() for a in (run.y, run.accel)):
            seen["finished, finite"] += 1
            if ledger_warning(run):  # energy not conserved to the accuracy asked for: the run says so
                seen["  of them, warned that the energy ledger misses"] += 1
                warned.append(sc.solver.rtol)
                print(f"seed {s}: the ledger misses by {ledger_assessment(run)[0]:.2g} at rtol {sc.solver.rtol:.2g}")
            deep = overlap_warning(run)
            if deep:  # pressed beyond the depth any contact law holds at: the run says so
                seen["  of them, warned of a pair pressed beyond 0.2 of its radius"] += 1
                print(f"seed {s}: {deep.split(', where')[0]}")
        else:
            seen["DEFECT: non-finite samples"] += 1
            print(f"seed {s}: non-finite samples: {doc}")
    print(f"seeds {first}..{first + count - 1}, {time.perf_counter() - wall:.0f} s:")
    for what, n in sorted(seen.items(), key=lambda kv: kv[0].strip()):
        print(f"  {what}: {n}")
    if warned:
        print(f"  the tightest rtol among the warned: {min(warned):.2g}")


def converge(seed: int) -> None:
    """Seed's scene again at rtol 1e-6, 1e-8, 1e-10 and 1e-12: whether a ledger that missed closes as the tolerance
    tightens (the method converging), or does not (a defect)."""
    sc = scene_from_dict(draw(random.Random(seed)), Path.cwd())
    for rtol in (sc.solver.rtol, 1e-6, 1e-8, 1e-10, 1e-12):
        run = Solver(sc, rtol=rtol, atol=rtol * 1e-2).run()
        print(f"seed {seed}, rtol {rtol:.2g}: the ledger misses by {ledger_assessment(run)[0]:.2g}")


if __name__ == "__main__":
    if sys.argv[1:2] == ["--converge"]:
        converge(int(sys.argv[2]))
    else:
        main(*(int(a) for a in sys.argv[1:3]))

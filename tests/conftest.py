"""Scene builders shared by the tests: the paper's dual system with every value overridable."""
from __future__ import annotations

import copy
import math
import os
import shutil
import tempfile
from pathlib import Path

import pytest

from grapefmu.scenefile import scene_from_dict

# every process a test starts prints its Python stack if it crashes (pytest does so for its own): a segfault seen once
# in CI, at the exit of an interrupted `grapefmu simulate`, left only its exit code
os.environ.setdefault("PYTHONFAULTHANDLER", "1")

# fmpy's `extract` unpacks each FMU into a fresh temporary directory that nobody removes (37 MB each, 23 a session):
# every temporary file of the session and of the processes it starts goes under one root, removed at the end.
# pytest's own tmp_path stays where it was, so a failed test's files can still be read.
os.environ.setdefault("PYTEST_DEBUG_TEMPROOT", tempfile.gettempdir())
_SESSION_TMP = tempfile.mkdtemp(prefix="grapefmu-tests-")
os.environ["TMPDIR"] = tempfile.tempdir = _SESSION_TMP


def pytest_sessionfinish(session, exitstatus):
    shutil.rmtree(_SESSION_TMP, ignore_errors=True)

KYOHO = {"mass": 0.011, "radius": 0.0135, "twig_length": 0.03, "hinge_stiffness": 1e-3, "hinge_damping": 2e-5}


def dual(left: dict | None = None, right: dict | None = None, contact: dict | None = None, d0: float = 0.03,
         angles=(-math.pi / 4, math.pi / 4), **top) -> dict:
    """The dual-twig–berry system as a scene dict (hinges at ∓d0/2)."""
    lb = {"name": "left", **KYOHO, "hinge_x": -d0 / 2, "angle": angles[0]}
    rb = {"name": "right", **KYOHO, "hinge_x": d0 / 2, "angle": angles[1]}
    lb.update(left or {})
    rb.update(right or {})
    doc = {"berries": [lb, rb], "contact": {"law": "kelvin-voigt", "stiffness": 2000.0, "restitution": 0.5}}
    if contact is not None:
        doc["contact"] = contact
    doc.update(top)
    return doc


def one_planar_berry(yaw: float, excitation: str = "", kind: str = "none") -> str:
    """The TOML of a scene of one planar berry on a rachis started turned `yaw` about z (its y axis, about which alone
    a planar scene turns, is then (−sin yaw, cos yaw, 0) in the world), its excitation of `kind` with the further
    keys `excitation` (TOML lines)."""
    return f"""name = "yawed"
[[berries]]
name = "b"
mass = 0.011
radius = 0.0135
twig_length = 0.03
hinge_x = 0.0
hinge_damping = 2.0e-5
[excitation]
kind = "{kind}"
orientation = [0.0, 0.0, {yaw!r}]
{excitation}
"""


def scene(doc: dict):
    return scene_from_dict(copy.deepcopy(doc), Path.cwd())


@pytest.fixture
def collision_scene():
    return scene(dual(solver={"t_end": 2.0}))


def build_fmu(out: Path, fmi: int, scene: str | None = None) -> Path:
    """`grapefmu build-fmu` in a process of its own (a build and a simulation must not share one), from the repository
    root: the default scene, or `scene` (a path from the root)."""
    import subprocess
    import sys
    subprocess.run([sys.executable, "-m", "grapefmu", "build-fmu", *([scene] if scene else []), "-o", str(out),
                    "--fmi", str(fmi)], check=True, cwd=Path(__file__).resolve().parents[1], capture_output=True)
    return out

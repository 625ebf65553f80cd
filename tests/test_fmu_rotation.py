"""The FMU's 6-DoF rachis: its linear and angular acceleration (held over each step) and angular velocity (set at
each step's start) as inputs, its initial orientation as parameters. A spherical cluster on a turning gripper
follows `simulate` through the FMU to what the hold allows; an initial orientation set as parameters gives the
run of the scene that has it."""
from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from grapefmu import simulate
from grapefmu.scenefile.toml_out import dumps

from .conftest import scene
from .fmu_driver import assert_hold_error, fed_from, named_outputs

pytest.importorskip("fmpy")
ROOT = Path(__file__).resolve().parents[1]
STOP = 0.5
RPY = (0.4, -0.25, 1.0)  # rad: roll, pitch, yaw (fixed axes)


def spherical(excitation: dict | None = None) -> dict:
    """Two spherical berries far enough apart never to touch (no impact amplifies a difference)."""
    doc = {"name": "turning", "berries": [
        {"name": "a", "kind": "spherical", "mass": 0.011, "radius": 0.0135, "twig_length": 0.03,
         "hinge": [-0.1, 0.0, 0.0], "hinge_stiffness": 1e-3, "hinge_damping": 2e-5, "angle": [0.1, -0.05]},
        {"name": "b", "kind": "spherical", "mass": 0.012, "radius": 0.014, "twig_length": 0.04,
         "hinge": [0.1, 0.02, 0.0], "hinge_stiffness": 1e-3, "hinge_damping": 2e-5, "angle": [0.2, 0.1]}],
        "contact": {"law": "hertz", "effective_modulus": 1e6},
        "solver": {"t_end": STOP, "rtol": 1e-10, "atol": 1e-13}}
    if excitation is not None:
        doc["excitation"] = excitation
    return doc


ANGLES = [f"angle_{b}_{c}" for b in "ab" for c in ("swing", "tilt")]


def build(doc: dict, out: Path) -> Path:
    (out.parent / f"{out.stem}.toml").write_text(dumps(doc))
    subprocess.run([sys.executable, "-m", "grapefmu", "build-fmu", str(out.parent / f"{out.stem}.toml"), "-o",
                    str(out)], check=True, capture_output=True, cwd=ROOT)
    return out


def test_a_turning_gripper_gives_simulates_trajectory_through_the_fmu_to_what_the_hold_allows(tmp_path):
    """The rachis turns about all three axes from a tilted start while it shakes: simulate integrates the sine
    exactly; the FMU (its orientation parameters the scene's start) gets (a, α) at each step's start, held, and
    ω there from simulate's run. The difference is the hold's: it halves when the step halves (2 ms → 1 ms) and
    what remains after cancelling that first-order term is a small fraction of it."""
    ex = {"kind": "sine", "amplitude": [2.0, 1.0, -1.5], "angular_amplitude": [3.0, -2.0, 4.0], "frequency": 2.0,
          "orientation": list(RPY), "angular_velocity": [0.5, -0.3, 0.8]}
    doc = spherical(ex)
    run = simulate(scene(doc), output_interval=1e-3)
    assert np.abs(run.base_angular_velocity - run.base_angular_velocity[0]).max() > 0.2  # rad/s: it really turns
    fmu = build(doc, tmp_path / "turning.fmu")  # the scene's orientation: the parameters' start values
    sc = scene(doc)
    differences = {}
    for dt in (2e-3, 1e-3):
        got = named_outputs(fmu, fed_from(sc.excitation, run, dt, STOP), STOP, dt, ANGLES, tmp_path)
        k = np.rint(got[:, 0] / 1e-3).astype(int)
        differences[dt] = got[:, 1:] - run.angles[k]
    assert_hold_error(differences)
    assert np.abs(run.angles - run.angles[0]).max() > 0.1  # rad: the berries really swung


def test_the_initial_orientation_parameters_give_the_scenes_run_with_that_orientation(tmp_path):
    """A spherical cluster's FMU built with the rachis level, started at RPY by its parameters and held still,
    swings as simulate of the scene whose rachis starts at RPY (gravity turned into the rachis frame); left at
    its start values it gives the level scene's run."""
    fmu = build(spherical(), tmp_path / "still.fmu")
    zero = np.column_stack([np.arange(0.0, STOP - 1e-9, 1e-2), np.zeros((50, 6))])
    params = dict(zip(("rachis_roll", "rachis_pitch", "rachis_yaw"), RPY))
    tilted = named_outputs(fmu, zero, STOP, 1e-3, ANGLES, tmp_path, params)
    ref = simulate(scene(spherical({"kind": "none", "orientation": list(RPY)})), output_interval=1e-3)
    np.testing.assert_allclose(tilted[:, 1:], ref.angles[1:], atol=1e-8)  # the solver's tolerance (rtol 1e-10)
    assert np.abs(ref.angles - ref.angles[0]).max() > 0.1  # rad: the tilt set the berries swinging
    level = named_outputs(fmu, zero, STOP, 1e-3, ANGLES, tmp_path)
    np.testing.assert_allclose(level[:, 1:], simulate(scene(spherical()), output_interval=1e-3).angles[1:],
                               atol=1e-8)

"""`grapefmu fit` (issue 15): known parameters recovered from synthetic camera data within their standard errors,
an unidentifiable parameter flagged, bad measured CSVs named by column and row, the command end to end."""
from __future__ import annotations

import copy
import json
import math
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from grapefmu.errors import DataError
from grapefmu.fit import fit, parameters, read_measured
from grapefmu.fit.camera import camera_data
from grapefmu.fit.measured import Measured
from grapefmu.scenefile import scene_from_dict

from .conftest import KYOHO, dual

ROOT = Path(__file__).resolve().parents[1]
#: the truth: the dual system released from −0.5 rad, colliding several times in 1.2 s (twigs of their own stiffness)
TRUTH = dual(left={"hinge_stiffness": 1.3e-3, "hinge_damping": 2.6e-5}, right={"hinge_stiffness": 0.8e-3,
             "hinge_damping": 2.6e-5, "mass": 0.012, "radius": 0.014, "twig_length": 0.04},
             contact={"law": "kelvin-voigt", "stiffness": 3500.0, "restitution": 0.42},
             angles=(-0.5, 0.0), solver={"t_end": 1.2})
TRUE = {"berries[0].hinge_stiffness": 1.3e-3, "berries[1].hinge_stiffness": 0.8e-3,
        "berries[*].hinge_damping": 2.6e-5, "contact.stiffness": 3500.0, "contact.restitution": 0.42}


def guess(doc: dict) -> dict:
    """The fit's starting point: docs/parameters.md's defaults, not the truth."""
    g = copy.deepcopy(doc)
    for b in g["berries"]:
        b["hinge_stiffness"], b["hinge_damping"] = KYOHO["hinge_stiffness"], KYOHO["hinge_damping"]
    g["contact"].update(stiffness=2000.0, restitution=0.5)
    return g


def measured(doc: dict, seed: int, angles: list[str] | None = None) -> Measured:
    """Synthetic camera data: 100 Hz, 1 mrad noise."""
    cols = camera_data(scene_from_dict(copy.deepcopy(doc), Path.cwd()), rate=100.0, noise=1e-3, seed=seed,
                       angles=angles)
    dofs = tuple(angles or ("left", "right"))
    return Measured(Path(f"seed{seed}.csv"), cols["time_s"], dofs,
                    np.column_stack([cols[f"angle_{d}_rad"] for d in dofs]), None)


def test_known_parameters_are_recovered_within_two_standard_errors_in_20_seeded_trials():
    """Every parameter identifiable in every trial, and each within 2 standard errors of the truth in at least
    18 of 20 trials (2 standard errors cover 95 % if the errors are honest: too small ones fail this)."""
    start = guess(TRUTH)
    params = parameters(list(TRUE), start)
    inside = {k: 0 for k in TRUE}
    z = {k: [] for k in TRUE}
    for seed in range(20):
        res = fit(start, Path.cwd(), params, [measured(TRUTH, seed)])
        assert 0.8e-3 < res.sigma < 1.2e-3, res.sigma  # the residuals are the 1 mrad noise
        assert not res.warnings, res.warnings          # no false alarm: nothing flagged, residuals white
        for e in res.estimates:
            assert e.identifiable, (seed, e)
            z[e.key].append((e.value - TRUE[e.key]) / e.se)
            inside[e.key] += abs(e.value - TRUE[e.key]) <= 2 * e.se
    assert all(n >= 18 for n in inside.values()), (inside, z)
    # the standard errors are neither much too large: the spread of the z scores is about 1
    assert all(0.5 < np.std(v) < 1.5 for v in z.values()), {k: np.std(v) for k, v in z.items()}


def test_a_contact_parameter_without_a_collision_is_flagged_and_the_rest_still_recovered():
    """Small swings that never reach the neighbour: contact stiffness has no effect at all on the data."""
    calm = copy.deepcopy(TRUTH)
    calm["berries"][0]["angle"] = -0.05
    start = guess(calm)
    res = fit(start, Path.cwd(), parameters(["berries[*].hinge_damping", "berries[0].hinge_stiffness",
                                             "contact.stiffness"], start), [measured(calm, 3)])
    by = {e.key: e for e in res.estimates}
    assert not by["contact.stiffness"].identifiable and by["contact.stiffness"].se == math.inf
    assert "no sensitivity" in by["contact.stiffness"].note and "collision" in by["contact.stiffness"].note
    assert any(w.startswith("contact.stiffness is not identifiable") for w in res.warnings)
    for key in ("berries[*].hinge_damping", "berries[0].hinge_stiffness"):
        assert by[key].identifiable and abs(by[key].value - TRUE[key]) <= 3 * by[key].se, by[key]
    # "the scene's value kept": in the fitted scene as the scene gave it, not exp(log 2000) = 1999.9999999999998
    assert res.fitted_doc["contact"]["stiffness"] == start["contact"]["stiffness"] == 2000.0


def test_a_twig_key_the_data_say_nothing_about_keeps_each_twigs_own_value():
    """berries[*].hinge_damping of 1e-5 and 4e-5 on a cluster at rest: no sensitivity, "the scene's value kept",
    and the fitted scene held their geometric mean, 2e-5, for both."""
    rest = copy.deepcopy(TRUTH)
    rest["berries"][0]["angle"] = 0.0
    rest["berries"][0]["hinge_damping"], rest["berries"][1]["hinge_damping"] = 1e-5, 4e-5
    cols = camera_data(scene_from_dict(copy.deepcopy(rest), Path.cwd()), rate=100.0, noise=0.0, seed=3)
    still = Measured(Path("still.csv"), cols["time_s"], ("left", "right"),
                     np.column_stack([cols["angle_left_rad"], cols["angle_right_rad"]]), None)
    res = fit(rest, Path.cwd(), parameters(["berries[*].hinge_damping", "contact.stiffness"], rest), [still])
    by = {e.key: e for e in res.estimates}
    assert "no sensitivity" in by["berries[*].hinge_damping"].note
    assert [b["hinge_damping"] for b in res.fitted_doc["berries"]] == [1e-5, 4e-5]


def test_a_grazing_impact_leaves_the_contact_law_flagged_by_its_standard_errors():
    """One grazing impact (about 0.04 N) in the record: the contact law moves the data, but so little that its
    standard errors are huge; the hinge, which the whole swing shows, is still pinned."""
    graze = copy.deepcopy(TRUTH)
    graze["berries"][0]["angle"] = -0.185
    graze["solver"]["t_end"] = 0.6
    res = fit(graze, Path.cwd(), parameters(["contact.stiffness", "contact.restitution",
                                             "berries[0].hinge_stiffness"], graze), [measured(graze, 1, ["left"])])
    by = {e.key: e for e in res.estimates}
    for key in ("contact.stiffness", "contact.restitution"):
        assert not by[key].identifiable and "standard error" in by[key].note and np.isfinite(by[key].se), by[key]
        assert by[key].se_u > 0.5
    assert by["berries[0].hinge_stiffness"].identifiable and by["berries[0].hinge_stiffness"].se_u < 0.01


def test_a_model_that_cannot_fit_the_data_is_flagged_by_its_structured_residuals():
    """Only the damping fitted while the hinge stiffness is 30 % off: the residuals follow the swing, not the noise."""
    wrong = copy.deepcopy(TRUTH)
    for b in wrong["berries"]:
        b["hinge_stiffness"] *= 1.3
    res = fit(wrong, Path.cwd(), parameters(["berries[*].hinge_damping"], wrong), [measured(TRUTH, 5)])
    structured = [w for w in res.warnings if "structured" in w]
    assert {w.split("angle ")[1].split(" ")[0] for w in structured} == {"left", "right"}, res.warnings
    assert res.sigma > 5e-3


def test_segments_and_untracked_berries_recover_the_same_parameters():
    """Three segments, only the left berry tracked (the right one is carried across the segments): the estimates
    agree with the truth within 2.5 standard errors."""
    start = guess(TRUTH)
    params = parameters(list(TRUE), start)
    res = fit(start, Path.cwd(), params, [measured(TRUTH, 7, ["left"])], segments=3)
    assert 0.8e-3 < res.sigma < 1.2e-3
    for e in res.estimates:
        assert e.identifiable and abs(e.value - TRUE[e.key]) <= 2.5 * e.se, e


def test_a_measured_gripper_motion_drives_the_rig():
    """Berries at rest carried 0.2 m by a gripper whose acceleration is logged per frame (the camera's columns
    base_ax_m_s2, base_az_m_s2): the rig scene has no excitation of its own, the measured motion drives it, and
    the parameters come back within 2 standard errors."""
    carried = copy.deepcopy(TRUTH)
    carried["berries"][0]["angle"] = 0.0
    carried["excitation"] = {"kind": "pick-and-place", "start": 0.1,
                             "moves": [{"displacement": [0.2, 0.0], "duration": 0.4}]}
    carried["solver"]["t_end"] = 1.5
    cols = camera_data(scene_from_dict(copy.deepcopy(carried), Path.cwd()), seed=3, gripper=True)
    data = Measured(Path("g.csv"), cols["time_s"], ("left", "right"),
                    np.column_stack([cols["angle_left_rad"], cols["angle_right_rad"]]),
                    np.column_stack([cols["base_ax_m_s2"], cols["base_az_m_s2"]]))
    rig = guess({**carried, "excitation": {"kind": "none"}})
    res = fit(rig, Path.cwd(), parameters(list(TRUE), rig), [data])
    assert 0.8e-3 < res.sigma < 1.2e-3 and not res.warnings, res.warnings
    for e in res.estimates:
        assert e.identifiable and abs(e.value - TRUE[e.key]) <= 2 * e.se, e


def test_irregular_frame_times_are_interpolated_as_the_solver_integrates():
    """Frames at jittered times (no common grid): the samples between frames interpolated with angles and rates
    agree with stepping the solver to each frame's time exactly."""
    from grapefmu.fit.shooting import Shooting
    from grapefmu.solver.solver import Solver

    sc = scene_from_dict(copy.deepcopy(TRUTH), Path.cwd())
    rng = np.random.default_rng(5)
    t = np.cumsum(rng.uniform(0.008, 0.012, 100))
    problem = Shooting(TRUTH, Path.cwd(), [], [Measured(Path("j.csv"), t, ("left",), np.zeros((100, 1)), None)])
    x = sc.initial_state.copy()
    x[0] = -0.4
    q, _ = problem.shoot(sc, t, x)
    import dataclasses
    solver = Solver(dataclasses.replace(sc, angles=tuple(x[:2]), angular_velocities=tuple(x[2:])), rtol=1e-10,
                    atol=1e-12, t_start=float(t[0]))
    exact = [solver.angles]
    for tk in t[1:]:
        solver.advance(tk - solver.t)
        exact.append(solver.angles)
    assert np.abs(q - np.array(exact)).max() < 5e-5  # far below the 1 mrad of a camera


def test_a_trial_start_state_outside_the_models_ranges_is_a_failed_trial():
    """The optimiser's trial start state is a scene built in code: one the model refuses (an angle past π) is a failed
    trial, which least_squares retreats from (residuals of π), as from a solver failure, not a crash of the fit."""
    from grapefmu.errors import SolverError
    from grapefmu.fit.shooting import Shooting

    sc = scene_from_dict(copy.deepcopy(TRUTH), Path.cwd())
    t = np.arange(20) * 0.01
    problem = Shooting(TRUTH, Path.cwd(), [], [Measured(Path("j.csv"), t, ("left",), np.zeros((20, 1)), None)])
    x = sc.initial_state.copy()
    x[0] = 4.0
    with pytest.raises(SolverError, match=r"trial start state is refused: angles\[0\]"):
        problem.shoot(sc, t, x)


# --- bad measured CSVs: named by column and row -------------------------------------------------------------

MODEL = scene_from_dict(copy.deepcopy(TRUTH), Path.cwd()).model


def csv_file(tmp_path: Path, rows: list[list], header: str = "time_s,angle_left_rad,angle_right_rad") -> Path:
    p = tmp_path / "m.csv"
    p.write_text(header + "\n" + "\n".join(",".join(str(c) for c in r) for r in rows) + "\n")
    return p


def frames(n: int = 20) -> list[list]:
    return [[round(0.01 * k, 6), 0.1 * math.sin(k / 3), 0.05 * math.cos(k / 3)] for k in range(n)]


@pytest.mark.parametrize("change, words", [
    (lambda r: r[7].__setitem__(0, 0.05), ["time_s", "row 8 (line 9)", "not after the previous row", "sort"]),
    (lambda r: r[4].__setitem__(0, 0.03), ["time_s", "row 5 (line 6)", "not after"]),                # repeated time
    (lambda r: r[11].__setitem__(1, 28.6), ["angle_left_rad", "row 12 (line 13)", "beyond ±π", "degrees"]),
    (lambda r: r[3].__setitem__(0, "nan"), ["time_s", "row 4 (line 5)", "not finite"]),
    (lambda r: r[6].__setitem__(2, "abc"), ["angle_right_rad", "row 7 (line 8)", "'abc' is not a number"]),
    (lambda r: r[0].__setitem__(0, -1.0), ["time_s", "row 1 (line 2)", "starts at or after 0 s"]),
    (lambda r: r[19].__setitem__(0, 1e8), ["time_s", "row 20 (line 21)", "at most 100000 s"]),  # was out of memory
])
def test_bad_rows_are_errors_naming_column_and_row(tmp_path, change, words):
    rows = frames()
    change(rows)
    with pytest.raises(DataError) as e:
        read_measured(csv_file(tmp_path, rows), MODEL)
    text = str(e.value)
    assert "m.csv" in text and "\n" not in text
    for w in words:
        assert w in text, (w, text)


def test_a_measured_gripper_acceleration_beyond_the_faces_bound_is_refused(tmp_path):
    """5e6 m/s² was fitted (exit 0, a residual of 24.5 rad); every face refuses beyond ±1000 m/s²."""
    rows = [r + [0.0, 0.0] for r in frames()]
    rows[5][3] = 5e6
    with pytest.raises(DataError, match=r"base_ax_m_s2 row 6 \(line 7\): 5e\+06 m/s²; at most ±1000 m/s²"):
        read_measured(csv_file(tmp_path, rows, "time_s,angle_left_rad,angle_right_rad,base_ax_m_s2,base_az_m_s2"),
                      MODEL)


@pytest.mark.parametrize("header, words", [
    ("t,angle_left_rad,angle_right_rad", ["no time_s column"]),
    ("time_s,angle_left_deg,angle_right_rad", ["angle_left_deg", "radians", "angle_left_rad"]),
    ("time_s,angle_middle_rad,angle_right_rad", ["angle_middle_rad", "no angle 'middle'", "angle_left_rad"]),
    ("time_s,x,y", ["no angle column", "angle_left_rad, angle_right_rad"]),
    # the last copy won without a word, and the measured one was thrown away (found by an audit)
    ("time_s,angle_left_rad,angle_left_rad", ["column angle_left_rad appears 2 times", "(columns 2, 3)"]),
])
def test_bad_headers_name_the_column(tmp_path, header, words):
    with pytest.raises(DataError) as e:
        read_measured(csv_file(tmp_path, frames(), header), MODEL)
    for w in words:
        assert w in str(e.value), (w, str(e.value))


def test_gaps_and_missing_angles_are_warnings_naming_column_and_row(tmp_path):
    rows = frames(40)
    del rows[20:25]                      # five frames dropped: a gap before row 21
    rows[9][2] = "nan"                   # the tracker lost the right berry twice
    rows[30][2] = ""
    m = read_measured(csv_file(tmp_path, rows), MODEL)
    gap = next(w for w in m.warnings if "gap" in w)
    assert "time_s" in gap and "row 21 (line 22)" in gap and "5 frame(s) missing" in gap
    lost = next(w for w in m.warnings if "missing (empty or NaN)" in w)
    assert "angle_right_rad" in lost and "row 10 (line 11)" in lost and "row 31 (line 32)" in lost
    assert np.isnan(m.angles[[9, 30], 1]).all() and m.samples == 2 * 35 - 2


def test_missing_samples_are_left_out_of_the_fit():
    """NaN angles (a lost track) do not bias the fit: the estimates with a third of the frames lost agree."""
    data = measured(TRUTH, 11)
    lost = data.angles.copy()
    lost[::3, 0] = np.nan
    start = copy.deepcopy(TRUTH)  # the parameters not fitted at their true values, the two fitted ones off
    for b in start["berries"]:
        b["hinge_damping"] = 2e-5
    start["contact"]["restitution"] = 0.5
    params = parameters(["berries[*].hinge_damping", "contact.restitution"], start)
    res = fit(start, Path.cwd(), params, [Measured(data.path, data.t, data.dofs, lost, None)])
    assert res.residuals == np.isfinite(lost).sum()
    for e in res.estimates:
        assert abs(e.value - TRUE[e.key]) <= 3 * e.se, e


# --- the command end to end ----------------------------------------------------------------------------------

def cli(*args: str, cwd: Path) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", *args], cwd=cwd, capture_output=True, text=True, timeout=120,
                          env={**os.environ, "PYTHONWARNINGS": "ignore"})


def test_camera_then_fit_writes_a_fitted_scene_a_report_and_residual_plots(tmp_path):
    truth = ROOT / "docs" / "examples" / "fit_and_risk" / "swing_test_truth.toml"
    rig = ROOT / "docs" / "examples" / "fit_and_risk" / "swing_test.toml"
    r = cli("grapefmu.fit.camera", str(truth), "-o", "cam.csv", "--seed", "2", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    r = cli("grapefmu", "fit", str(rig), "cam.csv", "--param", "berries[*].hinge_damping", "--param",
            "contact.restitution", "-o", "fitted.toml", "--report", "fit.json", "--plot", "fit.png", cwd=tmp_path)
    assert r.returncode == 0 and "Traceback" not in r.stderr, r.stderr
    assert "berries[*].hinge_damping" in r.stdout and "std. error" in r.stdout and "correlations" in r.stdout
    report = json.loads((tmp_path / "fit.json").read_text())
    from grapefmu.scenefile import load_scene
    fitted = load_scene(tmp_path / "fitted.toml")
    est = {p["key"]: p for p in report["parameters"]}
    assert fitted.model.berries[1].hinge_damping == pytest.approx(est["berries[*].hinge_damping"]["estimate"])
    assert fitted.model.pairs[0].law.restitution == pytest.approx(est["contact.restitution"]["estimate"])
    # the truth file's values, recovered (the rig's starting values are docs/parameters.md's defaults)
    assert abs(est["contact.restitution"]["estimate"] - 0.42) <= 3 * est["contact.restitution"]["standard_error"]
    assert (tmp_path / "fit.png").stat().st_size > 10_000
    assert "± " in (tmp_path / "fitted.toml").read_text().splitlines()[2]
    # the angles written in degrees by mistake: one line naming the file, column and row
    head, *lines = (tmp_path / "cam.csv").read_text().splitlines()
    rows = [[float(c) for c in ln.split(",")] for ln in lines]
    (tmp_path / "deg.csv").write_text("\n".join([head, *(f"{t},{math.degrees(a)},{math.degrees(b)}"
                                                          for t, a, b in rows)]) + "\n")
    bad = cli("grapefmu", "fit", str(rig), "deg.csv", "--param", "contact.restitution", "-o", "f2.toml",
              cwd=tmp_path)
    assert bad.returncode == 2 and len(bad.stderr.strip().splitlines()) == 1, bad.stderr
    assert bad.stderr.startswith("grapefmu fit: deg.csv: angle_left_rad row 1 (line 2)"), bad.stderr
    assert "degrees" in bad.stderr
    assert not (tmp_path / "f2.toml").exists()

"""Pose tables (issue 13): the gripper's recorded poses as the rachis motion. The rachis follows an analytic
motion sampled at 100 Hz to the spline's error; the same table drives simulate, the FMU and the ROS node in
lockstep (fed the table's acceleration, held over each step) to the same trajectory, also while it turns; bad
tables are refused naming the row and column."""
from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from grapefmu import GrapefmuError, simulate
from grapefmu.model.excitation import read_pose_table
from grapefmu.physics.excitation import ACCEL_COMPONENTS, accel

from .conftest import dual, scene
from .test_ros_node import QOS, Controller, drive, ros, sim_node  # noqa: F401 - ros: the module's rclpy fixture

ROOT = Path(__file__).resolve().parents[1]
T, DX, DZ = 0.5, 0.06, -0.03  # s, m: one rest-to-rest move


def minimum_jerk(t):
    """x and z of a minimum-jerk move from rest to rest (an independent analytic motion), m."""
    s = np.clip(np.asarray(t) / T, 0.0, 1.0)
    shape = 10 * s**3 - 15 * s**4 + 6 * s**5
    return DX * shape, DZ * shape


def write_table(path: Path, t, x, z, orientation=("roll", "pitch", "yaw"), rows=None) -> Path:
    values = rows if rows is not None else [
        [ti, xi, 0.05, zi, *((0.0, 0.0, 0.3) if len(orientation) == 3 else (0.0, 0.0, math.sin(0.15), math.cos(0.15)))]
        for ti, xi, zi in zip(t, x, z)]
    path.write_text(",".join(["time", "x", "y", "z", *orientation]) + "\n"
                    + "".join(",".join(repr(float(v)) if not isinstance(v, str) else v for v in r) + "\n"
                              for r in values))
    return path


def table_scene(path: Path, t_end: float = 0.8) -> dict:
    return dual(angles=(0.0, 0.3), excitation={"kind": "pose-table", "file": str(path)},
                solver={"t_end": t_end, "rtol": 1e-10, "atol": 1e-13})


@pytest.mark.parametrize("orientation", [("roll", "pitch", "yaw"), ("qx", "qy", "qz", "qw")])
def test_the_rachis_follows_a_sampled_motion_to_the_splines_error(tmp_path, orientation):
    t = np.arange(0.0, T + 1e-9, 0.01)  # a camera or a robot log at 100 Hz
    path = write_table(tmp_path / "poses.csv", t, *minimum_jerk(t), orientation=orientation)
    run = simulate(scene(table_scene(path)))
    x, z = minimum_jerk(run.t)
    assert np.abs(run.base_displacement[:, 0] - x).max() < 2e-6  # m: the cubic spline's O(h⁴) error
    assert np.abs(run.base_displacement[:, 2] - z).max() < 2e-6
    assert np.abs(run.base_displacement[-1] - [DX, 0.0, DZ]).max() < 1e-9  # at rest where the table ends
    assert run.collision_count > 0


def test_one_table_gives_one_trajectory_through_simulate_the_fmu_and_the_ros_node(ros, tmp_path):
    """simulate follows the table's spline; the FMU and the node in lockstep get its acceleration held over
    each 5 ms step. The two held runs agree to round-off, and with the spline to what the hold allows."""
    from grapefmu.scenefile.toml_out import dumps

    t = np.arange(0.0, T + 1e-9, 0.01)
    path = write_table(tmp_path / "poses.csv", t, *minimum_jerk(t))
    ex = read_pose_table(path.read_text(), str(path), "excitation.file")
    dt, stop = 5e-3, 0.6
    grid = np.round(np.arange(0.0, stop - 1e-9, dt), 9)
    held = accel(ex, grid)  # the table's acceleration, held over each step
    np.savetxt(tmp_path / "held.csv", np.column_stack([grid, held]), delimiter=",",
               header=",".join(["time", *ACCEL_COMPONENTS]), comments="")
    plain = {k: v for k, v in table_scene(path, stop).items() if k != "excitation"}
    (tmp_path / "plain.toml").write_text(dumps(plain))
    subprocess.run([sys.executable, "-m", "grapefmu", "build-fmu", str(tmp_path / "plain.toml"), "-o",
                    str(tmp_path / "plain.fmu")], check=True, capture_output=True, cwd=ROOT)
    out = subprocess.run([sys.executable, "-m", "tests.fmu_driver", "named", str(tmp_path / "plain.fmu"),
                          str(tmp_path / "held.csv"), str(stop), str(dt), "angle_left,angle_right"],
                         check=True, capture_output=True, text=True, cwd=ROOT).stdout
    fmu = np.array(json.loads(out.split("JSON:", 1)[1])["rows"])[:, 1:]

    with sim_node(tmp_path, record=False, extra=["-p", f"scene:={tmp_path / 'plain.toml'}"]) as (proc, _):
        ctl = Controller("pose_table_driver")
        ctl.connect()
        node = []
        for k, tk in enumerate([*grid, stop]):
            ctl.send(tk, held[k] if k < len(grid) else np.zeros(6))  # advance to tk, then hold the next value
            ctl.wait_for(lambda tk=tk: ctl.state_at(tk) is not None)
            if k:
                node.append(list(ctl.state_at(tk).position))
        ctl.close()
    node = np.array(node)

    held_doc = {**plain, "excitation": {"kind": "csv", "file": str(tmp_path / "held.csv"), "hold": True, "after": "zero"}}
    core = simulate(scene(held_doc), output_interval=dt)
    np.testing.assert_allclose(node, fmu, atol=1e-9)  # the same held input, the same solver
    np.testing.assert_allclose(fmu, core.angles[1:], atol=1e-6)


def test_a_held_table_converges_to_the_table_as_the_step_shrinks(tmp_path):
    """What a master or a controller that holds the table's acceleration over each step gets: first order in
    the step (berries apart, so no impact amplifies the difference)."""
    t = np.arange(0.0, T + 1e-9, 0.01)
    path = write_table(tmp_path / "poses.csv", t, *minimum_jerk(t))
    doc = {**table_scene(path, 0.6), "berries": dual(d0=0.2)["berries"]}
    exact = simulate(scene(doc), output_interval=1e-3)
    ex = read_pose_table(path.read_text(), str(path), "excitation.file")
    errors = []
    for dt in (4e-3, 2e-3, 1e-3):
        grid = np.round(np.arange(0.0, 0.6 - 1e-9, dt), 9)
        np.savetxt(tmp_path / "held.csv", np.column_stack([grid, accel(ex, grid)]), delimiter=",")
        held = simulate(scene({**doc, "excitation": {"kind": "csv", "file": str(tmp_path / "held.csv"), "hold": True,
                                                     "after": "zero", "orientation": [0.0, 0.0, 0.3]}}),
                        output_interval=1e-3)  # the table's (constant) orientation
        errors.append(np.abs(held.angles - exact.angles).max())
    assert errors[0] < 2e-2  # rad: the hold lags the table by half a step
    assert errors[1] / errors[0] < 0.6 and errors[2] / errors[1] < 0.6, errors  # halving the step halves it


@pytest.mark.parametrize("change, where", [
    (lambda r: r.__setitem__(3, [r[2][0], *r[3][1:]]), "row 4 column time"),      # a repeated time
    (lambda r: r.__setitem__(5, [r[3][0] - 1e-3, *r[5][1:]]), "row 6 column time"),  # unsorted
    (lambda r: r[2].__setitem__(3, "nan"), "row 3 column z"),
    (lambda r: r[4].__setitem__(7, 0.9), "row 5 column qw"),                       # not a unit quaternion
    (lambda r: r[10].__setitem__(1, 5.0), "columns x, y, z"),                      # a jump: positions in mm?
    (lambda r: r[10].__setitem__(slice(6, 8), [math.sin(1.0), math.cos(1.0)]), "columns qx, qy, qz, qw"),  # a turn jump
])
def test_bad_pose_tables_are_refused_naming_row_and_column(tmp_path, change, where):
    t = np.arange(0.0, T + 1e-9, 0.01)
    x, z = minimum_jerk(t)
    rows = [[ti, xi, 0.05, zi, 0.0, 0.0, math.sin(0.15), math.cos(0.15)] for ti, xi, zi in zip(t, x, z)]
    change(rows)
    path = write_table(tmp_path / "bad.csv", t, x, z, ("qx", "qy", "qz", "qw"), rows=rows)
    with pytest.raises(GrapefmuError) as err:
        scene(table_scene(path))
    assert where in str(err.value) and "bad.csv" in str(err.value)


def test_an_fmu_is_not_built_from_a_pose_table_scene(tmp_path):
    """The FMU is driven by its inputs and would not carry the table's file: refused before anything is written."""
    from grapefmu.scenefile.toml_out import dumps

    t = np.arange(0.0, T + 1e-9, 0.01)
    path = write_table(tmp_path / "poses.csv", t, *minimum_jerk(t))
    (tmp_path / "table.toml").write_text(dumps(table_scene(path)))
    r = subprocess.run([sys.executable, "-m", "grapefmu", "build-fmu", str(tmp_path / "table.toml"), "-o",
                        str(tmp_path / "x.fmu")], capture_output=True, text=True, cwd=ROOT)
    assert r.returncode != 0 and "pose-table" in r.stderr and "base_ax" in r.stderr
    assert not (tmp_path / "x.fmu").exists()


def turning_table(path: Path, hz: float, rpy, move=(DX, 0.02, DZ), start=(0.0, 0.0, 0.0)) -> Path:
    """A minimum-jerk move that turns by the fixed-axis angles rpy (rad) on the way from the angles `start`,
    sampled at hz."""
    t = np.arange(0.0, T + 1e-9, 1.0 / hz)
    u = minimum_jerk(t)[0][:, None] / DX
    np.savetxt(path, np.column_stack([t, u * np.array(move), np.array(start) + u * np.array(rpy)]), delimiter=",",
               header="time,x,y,z,roll,pitch,yaw", comments="")
    return path


def spherical_table_scene(path: Path) -> dict:
    return {"name": "turning", "berries": [
        {"name": "a", "kind": "spherical", "mass": 0.011, "radius": 0.0135, "twig_length": 0.03,
         "hinge": [-0.015, 0.0, 0.0], "hinge_stiffness": 1e-3, "hinge_damping": 2e-5, "azimuth": 0.5},
        {"name": "b", "kind": "spherical", "mass": 0.012, "radius": 0.014, "twig_length": 0.04,
         "hinge": [0.015, 0.0, 0.0], "hinge_stiffness": 1e-3, "hinge_damping": 2e-5, "angle": [0.2, 0.1]}],
        "contact": {"law": "hertz", "effective_modulus": 1e6},
        "excitation": {"kind": "pose-table", "file": str(path)},
        "solver": {"t_end": 0.7, "rtol": 1e-10, "atol": 1e-13}}


@pytest.mark.parametrize("rpy, order", [((0.0, 0.5, 0.0), 16.0), ((0.3, 0.5, 0.4), 4.0)])
def test_the_rachis_turns_with_a_sampled_motion_to_the_schemes_error(tmp_path, rpy, order):
    """Orientation against the analytic turn: O(h⁴) about a fixed axis (the spline), O(h²) about a moving one (α
    tabulated between rows); the energy ledger closes while the rachis turns and the berries collide."""
    from scipy.spatial.transform import Rotation

    err = {}
    for hz in (100, 50):
        run = simulate(scene(spherical_table_scene(turning_table(tmp_path / f"p{hz}.csv", hz, rpy))))
        u = minimum_jerk(run.t)[0][:, None] / DX
        err[hz] = (Rotation.from_euler("xyz", u * np.array(rpy)).inv()
                   * Rotation.from_quat(run.base_orientation)).magnitude().max()
        assert np.abs(run.base_displacement - u * np.array([DX, 0.02, DZ])).max() < 2e-6
        assert run.ledger_error() < 1e-8
    assert err[100] < 2e-6  # rad
    assert 0.7 * order < err[50] / err[100] < 1.3 * order, err


def test_a_table_that_turns_more_than_once_about_a_fixed_axis_is_followed(tmp_path):
    """A table may turn any number of times about a fixed axis: its rotation vectors were unwrapped only through ±π,
    so a turn of more than 2π from its first row jumped, and was refused as one ("a jump the interpolation cannot
    follow"). Against the analytic turn (1.5 turns in yaw), at 100 Hz, to the scheme's error scaled to the angle
    (the test above: 2e-6 rad for 0.5 rad). About a moving axis, the rotation vector is singular at whole turns: a
    table that passes near one is still refused as a jump, naming the row."""
    from scipy.spatial.transform import Rotation

    rpy = (0.0, 0.0, 3 * math.pi)
    run = simulate(scene(spherical_table_scene(turning_table(tmp_path / "p.csv", 100, rpy))))
    u = minimum_jerk(run.t)[0][:, None] / DX
    err = (Rotation.from_euler("xyz", u * np.array(rpy)).inv() * Rotation.from_quat(run.base_orientation)).magnitude()
    assert err.max() < 2e-6 * 3 * math.pi / 0.5, err.max()
    assert err[-1] < 1e-6 and np.abs(run.base_angular_velocity[-1]).max() < 1e-6  # at rest, turned as the table ends
    assert run.ledger_error() < 1e-8
    with pytest.raises(GrapefmuError, match=r"row \d+ columns roll, pitch, yaw: .* a jump the interpolation"):
        scene(spherical_table_scene(turning_table(tmp_path / "q.csv", 100, (0.1, 0.1, -2.2 * math.pi))))


def test_a_planar_scene_refuses_a_table_that_rolls(tmp_path):
    path = turning_table(tmp_path / "roll.csv", 100, (0.2, 0.0, 0.0))
    with pytest.raises(GrapefmuError) as err:
        scene(table_scene(path))
    assert "excitation.file" in str(err.value) and "y axis" in str(err.value)


def test_a_turning_table_gives_one_trajectory_through_simulate_and_the_fmu(tmp_path):
    """A spherical cluster on a gripper that moves and turns about all three axes from a tilted start: simulate
    follows the table; the FMU, started at the table's first orientation by its parameters (rachis_roll, _pitch,
    _yaw) and fed the table's derivatives at each step's start ((a, α) held, ω from simulate's run of the table),
    follows it to what the hold allows: the difference halves when the step halves (2 ms → 1 ms) and nothing
    remains beside that first-order term (fmu_driver.assert_hold_error)."""
    from grapefmu.scenefile.toml_out import dumps

    from .fmu_driver import assert_hold_error, fed_from, named_outputs

    start, stop = (0.2, -0.3, 0.6), 0.6
    doc = spherical_table_scene(turning_table(tmp_path / "poses.csv", 100, (0.3, 0.5, 0.4), start=start))
    for b, x in zip(doc["berries"], (-0.1, 0.1)):
        b["hinge"] = [x, 0.0, 0.0]  # apart: no impact amplifies the hold's difference
    run = simulate(scene(doc), stop, output_interval=1e-3)
    assert np.abs(run.base_angular_velocity).max() > 1.0  # rad/s: it turns
    plain = {k: v for k, v in doc.items() if k != "excitation"}  # the FMU carries no table
    (tmp_path / "plain.toml").write_text(dumps(plain))
    subprocess.run([sys.executable, "-m", "grapefmu", "build-fmu", str(tmp_path / "plain.toml"), "-o",
                    str(tmp_path / "plain.fmu")], check=True, capture_output=True, cwd=ROOT)
    names = [f"angle_{b}_{c}" for b in "ab" for c in ("swing", "tilt")]
    params = dict(zip(("rachis_roll", "rachis_pitch", "rachis_yaw"), start))
    differences = {}
    for dt in (2e-3, 1e-3):
        got = named_outputs(tmp_path / "plain.fmu", fed_from(run.scene.excitation, run, dt, stop), stop, dt, names,
                            tmp_path, params)
        differences[dt] = got[:, 1:] - run.angles[np.rint(got[:, 0] / 1e-3).astype(int)]
    assert_hold_error(differences)
    assert np.abs(run.angles - run.angles[0]).max() > 0.05  # rad: the berries swung


def test_a_turning_table_gives_one_trajectory_through_simulate_and_the_ros_node(ros, tmp_path):
    """The 6-DoF node in lockstep: a table that carries the cluster and turns it about a moving axis (roll, pitch
    and yaw together) drives simulate (its splines) and the node. Every 5 ms the node gets the table's (a, α) held
    (rachis/accel) and the rachis' angular velocity at that instant (rachis/twist, set at the step's start, as an
    FMU's base_omega inputs). The node equals a Solver.advance loop on the same held inputs bit for bit (impacts
    included), turns its TF frame with the table, and differs from simulate by the hold's error alone: the
    loop's error halves when the step does (first order), so the tolerance is that error, measured."""
    from tf2_msgs.msg import TFMessage

    from grapefmu import Solver
    from grapefmu.recording.stamps import stamp_seconds, to_ns
    from grapefmu.scenefile.toml_out import dumps
    from scipy.spatial.transform import Rotation

    path = turning_table(tmp_path / "turn.csv", 100, (0.3, 0.5, 0.4))
    doc = spherical_table_scene(path)
    ex = read_pose_table(path.read_text(), str(path), "excitation.file")
    stop, fine = 0.6, 2.5e-3
    exact = simulate(scene(doc), stop, output_interval=fine)
    assert exact.collision_count > 0 and np.ptp(exact.base_angular_velocity, axis=0).min() > 0.5  # turns every way
    plain = {k: v for k, v in doc.items() if k != "excitation"}  # starts where the table does: at rest, unturned
    (tmp_path / "plain.toml").write_text(dumps(plain))

    def held_inputs(dt):
        """(t, (a, α) of the table at t, ω at t) for every step start: what a sampled controller sends."""
        grid = np.round(np.arange(0.0, stop - 1e-9, dt), 9)
        omega = exact.base_angular_velocity[np.rint(grid / fine).astype(int)]
        return [(t, tuple(map(float, a)), tuple(map(float, w))) for t, a, w in zip(grid, accel(ex, grid), omega)]

    def held_loop(rows):
        """The same held inputs straight into Solver.advance, each step ending where the next row starts."""
        solver, angles = Solver(scene(plain), driven=True), []  # as the node builds it
        for (_, a, w), t1 in zip(rows, [r[0] for r in rows[1:]] + [stop]):
            solver.advance(stamp_seconds(0, to_ns(t1)) - solver.t, a, w)  # the interval as the node computes it
            angles.append(solver.angles)
        return np.array(angles)

    def error(angles, dt):
        return np.abs(angles - exact.angles[np.rint(np.arange(1, len(angles) + 1) * dt / fine).astype(int)]).max()

    rows = held_inputs(5e-3)
    turns = {}
    with sim_node(tmp_path, record=False, extra=["-p", f"scene:={tmp_path / 'plain.toml'}"]) as (proc, _):
        ctl = Controller("turning_table_driver")
        ctl.node.create_subscription(TFMessage, "/tf", lambda m: turns.update(
            {to_ns(stamp_seconds(tr.header.stamp.sec, tr.header.stamp.nanosec)): tr.transform.rotation
             for tr in m.transforms if tr.child_frame_id == "grape_cluster/rachis"}), QOS)
        ctl.connect()
        drive(ctl, [*rows, (stop, (0.0,) * 6)])  # each row: advance to its time, then hold its (a, α), set its ω
        ctl.spin(0.3)
        node = np.array([ctl.state_at(t).position for t in [r[0] for r in rows[1:]] + [stop]])
        ctl.close()

    np.testing.assert_array_equal(node, held_loop(rows))  # the same held inputs, the same solver: bit for bit
    coarse, half = error(node, 5e-3), error(held_loop(held_inputs(fine)), fine)
    assert 0.4 < half / coarse < 0.6, (coarse, half)  # the hold's error, first order in the step
    assert coarse < 1e-2  # rad: the node follows the table's trajectory to that error
    # its rachis frame turns with the table: ω set every step leaves an O(dt²) error per step
    assert len(turns) > 30
    for ns, q in turns.items():
        k = int(round(ns * 1e-9 / fine))
        offset = Rotation.from_quat([q.x, q.y, q.z, q.w]).inv() * Rotation.from_quat(exact.base_orientation[k])
        assert offset.magnitude() < 2e-4, (ns, offset.magnitude())  # rad (7e-5 at 5 ms, a quarter at 2.5 ms)

"""Obstacles fixed in the world (docs/model.md §7): berries landing on a crate floor while the rachis moves,
hitting a wall, against scipy's reference with its own event location; the ledger with a moving base and
obstacle impacts; per-surface bruise thresholds; the broad phase over a floor; bad obstacle tables."""
from __future__ import annotations

import math
import re

import numpy as np
import pytest

from grapefmu import GrapefmuError, Solver, simulate
from grapefmu.cluster import ClusterSpec, cluster_scene

from .conftest import dual, scene
from .test_ros_node import QOS, Controller, along_x, drive, ros, sim_node  # noqa: F401 - ros: the rclpy fixture

FLOOR = {"name": "floor", "point": [0.0, 0.0, -0.05], "normal": [0.0, 0.0, 1.0], "law": "hunt-crossley",
         "stiffness": 2e4, "restitution": 0.3, "bruise_force": 0.25}
WALL = {"name": "wall", "point": [0.04, 0.0, 0.0], "normal": [-1.0, 0.0, 0.0], "law": "kelvin-voigt",
        "stiffness": 3000.0, "restitution": 0.4}
CRATE_WALL = {"name": "crate_wall", "kind": "box", "centre": [0.06, 0.0, -0.06], "size": [0.01, 0.2, 0.04],
              "yaw": 0.1, "law": "kelvin-voigt", "stiffness": 5000.0, "restitution": 0.5}
FINGER = {"name": "finger", "kind": "capsule", "attached": "gripper", "ends": [[-0.036, -0.02, -0.02],
                                                                            [-0.036, 0.02, -0.02]],
          "radius": 0.005, "law": "hunt-crossley", "stiffness": 5e4, "restitution": 0.4}
CASES = {
    # carried 5 cm sideways and lowered 12 mm onto a foam floor: both berries land, swing and touch each other
    "set-down on a floor": dual(angles=(-0.3, 0.3), obstacles=[FLOOR], excitation={"kind": "pick-and-place", "moves": [
        {"displacement": [0.05, -0.012], "duration": 0.4}]}, solver={"t_end": 1.0}),
    # shaken sideways next to a hard wall
    "shaken against a wall": dual(angles=(0.0, 0.2), obstacles=[WALL], excitation={
        "kind": "sine", "amplitude": [6.0, 0.0], "frequency": 3.0}, solver={"t_end": 1.5}),
    # lifted 2 mm and carried 10 cm over a crate wall (a box, turned 0.1 rad): the berries clip its edge
    "carried over a box wall": dual(angles=(0.0, 0.0), obstacles=[CRATE_WALL], excitation={
        "kind": "pick-and-place", "moves": [{"displacement": [0.0, 0.002], "duration": 0.1},
                                            {"displacement": [0.1, 0.0], "duration": 0.5}]}, solver={"t_end": 1.0}),
    # a finger pad on the gripper (a capsule that moves with the rachis) next to the left berry, shaken
    "finger pad on the gripper": dual(angles=(0.0, 0.0), obstacles=[FINGER], excitation={
        "kind": "sine", "amplitude": [8.0, 0.0], "frequency": 4.0}, solver={"t_end": 1.0}),
}


@pytest.mark.parametrize("name", list(CASES))
def test_matches_scipy_reference_with_a_moving_rachis(name):
    sc = scene(CASES[name])
    ours = simulate(sc, rtol=1e-12, atol=1e-14)
    ref = simulate(sc, method="reference", rtol=1e-12, atol=1e-14)
    hit = {sc.model.pair_name(int(p)) for p in ours.impacts.pair}
    assert any(sc.model.touches_obstacle(int(p)) for p in ours.impacts.pair), hit
    assert ours.collision_count == ref.collision_count
    assert np.abs(ours.angles - ref.angles).max() < 1e-8
    np.testing.assert_allclose(ours.impacts.onset, ref.impacts.onset, atol=1e-10)
    np.testing.assert_allclose(ours.impacts.peak_force, ref.impacts.peak_force, rtol=1e-7)
    np.testing.assert_array_equal(ours.impacts.bruising, ref.impacts.bruising)


@pytest.mark.parametrize("name", list(CASES))
def test_ledger_closes_with_a_moving_base_and_obstacle_impacts(name):
    run = simulate(scene(CASES[name]), rtol=1e-11, atol=1e-13)
    assert run.ledger_error() < 1e-8
    assert abs(run.energy["base_work"][-1]) > 1e-5  # the base did work: the obstacle's share is in the ledger


def test_a_wall_returns_the_restitution_it_was_given():
    """A pendulum swinging into a wall head on: the impact's separation over approach speed is the wall's
    restitution (Hunt–Crossley's χ is chosen for it, with the berry's mass against a fixed body)."""
    doc = {"berries": [{"name": "b", "mass": 0.01, "radius": 0.012, "twig_length": 0.05, "hinge_x": 0.0,
                        "angle": -0.6}],
           "obstacles": [{"name": "wall", "point": [0.012, 0.0, 0.0], "normal": [-1.0, 0.0, 0.0],
                          "law": "hunt-crossley", "stiffness": 1e6, "restitution": 0.6}],
           "solver": {"t_end": 0.4, "rtol": 1e-10, "atol": 1e-13}}
    run = simulate(scene(doc))
    first = run.impacts.records()[0]
    assert first["separation_speed"] / first["approach_speed"] == pytest.approx(0.6, abs=0.01)


def test_each_surface_bruises_at_its_own_thresholds():
    sc = scene(CASES["set-down on a floor"])
    run = simulate(sc)
    force, energy = run.bruise_thresholds[run.impacts.pair.astype(int)].T
    floor = np.array([sc.model.touches_obstacle(int(p)) for p in run.impacts.pair])
    assert np.all(force[floor] == 0.25) and np.all(force[~floor] == sc.thresholds.bruise_force)
    expected = (run.impacts.peak_force >= force) | (run.impacts.dissipated >= energy)
    np.testing.assert_array_equal(run.impacts.bruising, expected)
    # the floor's low threshold makes its impacts bruise where the scene's would not
    assert np.any(floor & run.impacts.bruising & (run.impacts.peak_force < sc.thresholds.bruise_force))
    by = run.summary()["impacts_by_surface"]  # what the summary (and the CLI) report per surface
    assert list(by) == ["berry–berry", "floor"]
    assert by["floor"]["count"] == floor.sum() and by["berry–berry"]["count"] == (~floor).sum()
    assert by["floor"]["bruising"] == (floor & run.impacts.bruising).sum() > 0
    assert by["floor"]["peak_force_n"] == run.impacts.peak_force[floor].max()


def test_a_cluster_over_a_floor_watches_only_near_pairs():
    doc = cluster_scene(ClusterSpec(berries=30, seed=3))
    start = Solver(scene(doc)).snapshot().observation.position[0, :, 2] - [b["radius"] for b in doc["berries"]]
    doc["obstacles"] = [{"name": "floor", "point": [0.0, 0.0, float(start.min()) - 0.004], "normal": [0.0, 0.0, 1.0],
                         "law": "hunt-crossley", "stiffness": 2e4, "restitution": 0.3}]
    doc["excitation"] = {"kind": "pick-and-place", "moves": [{"displacement": [0.1, -0.01], "duration": 0.5}]}
    doc["solver"] = {**doc["solver"], "t_end": 0.8, "rtol": 1e-8, "atol": 1e-11}
    sc = scene(doc)
    a = Solver(sc).run()
    b = Solver(sc, skin=math.inf).run()  # the whole candidate list on every step
    assert sum(sc.model.touches_obstacle(p) for p in range(len(sc.model.pairs))) == 30
    assert any(sc.model.touches_obstacle(int(p)) for p in a.impacts.pair)
    assert a.stats["near_pairs_mean"] < 0.3 * a.stats["candidate_pairs"]
    assert a.collision_count == b.collision_count
    assert np.abs(a.angles - b.angles).max() < 1e-6


@pytest.mark.parametrize("change, key", [
    ({"normal": [0.0, 0.0, 0.0]}, "obstacles[0].normal"),
    ({"name": "left"}, "obstacles[0].name"),
    ({"kind": "cone"}, "obstacles[0].kind"),
    ({"kind": "box"}, "obstacles[0]"),  # a box has a centre and a size, not a point and a normal
    ({"colour": "red"}, "obstacles[0]"),
    ({"point": [0.0, 0.0, -0.035]}, "obstacles[0].point"),  # the hanging berries would start inside it
    ({"bruise_force": -1.0}, "obstacles[0].bruise_force"),
    ({"restitution": 1.5}, "obstacles[0].restitution"),
])
def test_bad_obstacles_are_refused_naming_the_key(change, key):
    with pytest.raises(GrapefmuError) as err:
        scene(dual(angles=(0.0, 0.0), obstacles=[{**FLOOR, **change}]))
    assert key in str(err.value)


def test_the_fmu_reports_obstacle_totals_that_match_the_core(tmp_path):
    """The set-down scene as an FMU: per-pair and per-obstacle outputs, driven by a held signal, agree with
    grapefmu simulate on the same held signal."""
    import json
    import subprocess
    import sys
    from pathlib import Path

    from grapefmu.model.excitation import pick_and_place
    from grapefmu.physics.excitation import ACCEL_COMPONENTS, accel
    from grapefmu.scenefile.toml_out import dumps

    root = Path(__file__).resolve().parents[1]
    doc = CASES["set-down on a floor"]
    (tmp_path / "setdown.toml").write_text(dumps(doc))
    t = np.round(np.arange(0, 1.0 + 1e-9, 1e-2), 10)
    ex = pick_and_place([((0.05, -0.012), 0.4)])
    np.savetxt(tmp_path / "signal.csv", np.column_stack([t, accel(ex, t)]), delimiter=",",
               header=",".join(["time", *ACCEL_COMPONENTS]), comments="")
    subprocess.run([sys.executable, "-m", "grapefmu", "build-fmu", str(tmp_path / "setdown.toml"), "-o",
                    str(tmp_path / "setdown.fmu")], check=True, capture_output=True, cwd=root)
    names = ["angle_left", "angle_right", "contact_force_left_floor", "contact_force_right_floor",
             "obstacle_force_floor"]
    out = subprocess.run([sys.executable, "-m", "tests.fmu_driver", "named", str(tmp_path / "setdown.fmu"),
                          str(tmp_path / "signal.csv"), "1.0", "0.01", ",".join(names)],
                         check=True, capture_output=True, text=True, cwd=root).stdout
    rows = np.array(json.loads(out.split("JSON:", 1)[1])["rows"])
    ref_doc = {**doc, "excitation": {"kind": "csv", "file": str(tmp_path / "signal.csv"), "hold": True}}
    ref = simulate(scene(ref_doc), 1.0, output_interval=1e-2)
    floor = [ref.scene.model.pair_name(p) for p in range(len(ref.scene.model.pairs))].index("left_floor")
    np.testing.assert_allclose(rows[:, 1:3], ref.angles[1:], atol=1e-6)
    np.testing.assert_allclose(rows[:, 3], ref.contact_force[1:, floor], atol=1e-4)
    np.testing.assert_allclose(rows[:, 5], rows[:, 3] + rows[:, 4], atol=1e-12)
    assert rows[:, 5].max() > 0.1  # the berries did land


def test_recordings_name_and_draw_the_obstacles(tmp_path):
    """Both independent readers decode every message of a recording with obstacles; contacts and collision
    events name the obstacle as body_b; the markers carry one shape per obstacle."""
    from rosbags.highlevel import AnyReader

    from grapefmu.recording.mcap_writer import write_mcap
    from grapefmu.recording.typestore import TYPESTORE

    from .recordings import decode_everything

    doc = {**CASES["finger pad on the gripper"], "obstacles": [FINGER, CRATE_WALL, FLOOR]}
    run = simulate(scene(doc), 0.6)
    write_mcap(run, tmp_path / "r.mcap")
    counts = decode_everything(tmp_path / "r.mcap")
    assert counts["contacts"] > 0 and counts["collision_events"] == run.collision_count
    bodies, shapes = set(), None
    with AnyReader([tmp_path / "r.mcap"], default_typestore=TYPESTORE) as reader:
        for conn, _, raw in reader.messages():
            m = reader.deserialize(raw, conn.msgtype)
            if conn.topic.endswith("collision_events"):
                bodies.add(m.body_b)
            if conn.topic.endswith("markers") and shapes is None:
                shapes = sorted(x.type for x in m.markers if x.ns == "obstacles")
    assert "finger" in bodies
    assert shapes == [1, 1, 3]  # the floor's square, the box, the capsule's cylinder


def test_the_ros_node_names_and_draws_obstacles(ros, tmp_path):
    """The node in lockstep on the finger-pad scene: contacts and collision events name the pad, the markers
    draw it where the gripper has carried it, and the node's angles equal the core's on the same inputs."""
    from grapefmu_msgs.msg import Contacts
    from visualization_msgs.msg import MarkerArray

    from grapefmu import load_scene
    from grapefmu.scenefile.toml_out import dumps

    doc = {k: v for k, v in CASES["finger pad on the gripper"].items() if k != "excitation"}
    (tmp_path / "pad.toml").write_text(dumps(doc))
    rows = [(k * 0.005, along_x(8.0 * np.sin(2 * np.pi * 4 * k * 0.005))) for k in range(121)]
    with sim_node(tmp_path, record=False, extra=["-p", f"scene:={tmp_path / 'pad.toml'}",
                                                 "-p", "marker_rate_hz:=50.0"]) as (proc, _):
        ctl = Controller("obstacle_listener")
        contacts, markers = [], []
        ctl.node.create_subscription(Contacts, "contacts", contacts.append, QOS)
        ctl.node.create_subscription(MarkerArray, "markers", markers.append, QOS)
        ctl.connect()
        drive(ctl, rows)
        ctl.spin(0.5)
        ctl.close()
    sc = load_scene(tmp_path / "pad.toml")
    solver = Solver(sc, driven=True)  # as the node builds it
    for (_, a), (t1, _) in zip(rows, rows[1:]):
        solver.advance(t1 - solver.t, a)
    np.testing.assert_allclose(list(ctl.state_at(rows[-1][0]).position), solver.angles, atol=1e-9)
    assert {c.body_b for m in contacts for c in m.contacts} >= {"finger"}
    pads = [x for m in markers for x in m.markers if x.ns == "obstacles"]
    assert pads and {x.type for x in pads} == {3}
    assert np.ptp([x.pose.position.x for x in pads]) > 1e-3  # it moves with the gripper


def test_a_rachis_that_drags_berries_into_the_floor_is_warned_of():
    """Lowered 80 mm onto a floor 50 mm below the hinges, the berries (hanging 43.5 mm down to their bottoms) are dragged
    through its soft foam: a contact law means nothing that deep, and the run says so in its warnings, naming the
    berry, the depth and when (results/trust.py: beyond 0.2 of the radius, the deepest a start may hold). The depth
    it names is the floor less the berry's bottom from the run's world positions, another path than the contact gap.
    Of the scenes above, the one whose rachis drifts through its wall is warned, and only it."""
    run = simulate(scene(dual(angles=(0.0, 0.0), obstacles=[FLOOR], excitation={"kind": "pick-and-place", "moves": [
        {"displacement": [0.0, -0.08], "duration": 0.4}]}, solver={"t_end": 0.6})))
    [words] = [w for w in run.summary()["warnings"] if "no contact law holds" in w]
    found = re.search(r"berry '(\w+)' was ([0-9.e+-]+) mm inside obstacle 'floor' at t = ([0-9.e+-]+) s, beyond "
                      r"([0-9.e+-]+) mm \(0.2 of the berry radius\)", words)
    assert found, words
    name, depth, t, bound = found[1], float(found[2]) * 1e-3, float(found[3]), float(found[4]) * 1e-3
    i = run.scene.model.names.index(name)
    k = int(np.argmin(np.abs(run.t - t)))
    radius = run.scene.model.berries[i].radius
    assert bound == pytest.approx(0.2 * radius, rel=1e-3)
    assert depth == pytest.approx(-0.05 - (run.positions[k, i, 2] - radius), rel=1e-3)
    assert depth > 0.02  # dragged about 30 mm past the floor
    warned = {name for name, case in CASES.items()
              if [w for w in simulate(scene(case)).summary()["warnings"] if "no contact law holds" in w]}
    # a sine acceleration of 6 m/s² at 3 Hz from rest drifts at 6/(2π 3) = 0.32 m/s on average: 0.48 m in its 1.5 s,
    # through the wall 40 mm away (the case still serves as a hard contact for scipy's reference to agree with)
    assert warned == {"shaken against a wall"}


KV_WALL = ({"law": "kelvin-voigt", "stiffness": 3000.0, "restitution": 0.5}, lambda d: 3000.0 * d)


@pytest.mark.parametrize("law, force, pitch, attached", [
    (*KV_WALL, 0.0, "world"),
    ({"law": "hunt-crossley", "effective_modulus": 2e5, "restitution": 0.4},
     lambda d: 4.0 / 3.0 * 2e5 * math.sqrt(0.012) * d ** 1.5, 0.0, "world"),  # K = 4/3 E* √R*, R* = r on a plane
    (*KV_WALL, 0.2, "world"),    # the rachis starts pitched: the wall stays where the world frame has it
    (*KV_WALL, 0.2, "gripper"),  # ... or turns with the rachis
])
def test_a_berry_leaning_on_a_wall_rests_where_its_torques_balance(law, force, pitch, attached):
    """One berry (hinge at the origin, l = 50 mm, r = 12 mm) started touching a wall 5 mm to its right (x, in the
    world frame or the rachis'; the normal given at twice unit length), on a rachis pitched by φ (REP-103: x turns
    toward −z, so the twig's world angle is s − φ). Hanging straight it would be 7 mm inside, which the file
    accepts (it used to refuse it: "starts 7 mm inside obstacle 'wall' in the hanging rest state", a check for
    mistyped hinges between berries), and the berry comes to rest where gravity, the hinge and the wall's law
    balance about the hinge, solved here with brentq: m g l sin(s − φ) + k_h s + F(δ) l cos w = 0 with
    δ = r + l sin w − 5 mm, w = s − φ for a wall fixed in the world and s for one on the gripper."""
    from scipy.optimize import brentq

    m, g, l, r, kh = 0.01, 9.81, 0.05, 0.012, 2e-3
    touching = math.asin((0.005 - r) / l)
    doc = {"berries": [{"name": "b", "mass": m, "radius": r, "twig_length": l, "hinge_x": 0.0, "hinge_stiffness": kh,
                        "hinge_damping": 1e-3, "angle": touching + (pitch if attached == "world" else 0.0)}],
           "obstacles": [{"name": "wall", "point": [0.005, 0.0, 0.0], "normal": [-2.0, 0.0, 0.0], "attached": attached,
                          **law}],
           "excitation": {"kind": "none", "orientation": [0.0, pitch, 0.0]},
           "solver": {"t_end": 3.0, "rtol": 1e-10, "atol": 1e-13}}
    run = simulate(scene(doc))

    def wall(s):
        return s - pitch if attached == "world" else s

    s = brentq(lambda s: m * g * l * math.sin(s - pitch) + kh * s + force(max(r + l * math.sin(wall(s)) - 0.005, 0.0))
               * l * math.cos(wall(s)), -0.3, 0.3, xtol=1e-15)
    delta = r + l * math.sin(wall(s)) - 0.005
    assert delta > 1e-6
    assert run.angles[-1, 0] == pytest.approx(s, rel=1e-9)  # measured within 1e-14
    assert run.penetration[-1, 0] == pytest.approx(delta, rel=1e-9)  # 3.8 µm to 76 µm
    assert run.contact_force[-1, 0] == pytest.approx(force(delta), rel=1e-9)


def test_a_start_is_judged_in_the_start_orientation():
    """An obstacle fixed in the world meets the berries where the rachis starts, in its start orientation: a
    spherical berry (l = 50 mm, r = 12 mm) on a rachis rolled 90° about x starts at y = +50 mm, z = 0. A floor
    55 mm down is clear of it (the file used to judge the start unturned and refuse it, while Solver ran it), and
    the berry swings down onto it; a wall at y = 45 mm is 17 mm inside it, refused naming the wall's point."""
    def doc(obstacle):
        return {"berries": [{"name": "b", "kind": "spherical", "mass": 0.01, "radius": 0.012, "twig_length": 0.05,
                             "hinge_x": 0.0, "angle": [0.0, 0.0]}],
                "obstacles": [{"name": "o", "law": "kelvin-voigt", "stiffness": 3000.0, **obstacle}],
                "excitation": {"kind": "none", "orientation": [math.pi / 2, 0.0, 0.0]}, "solver": {"t_end": 0.3}}
    run = simulate(scene(doc({"point": [0.0, 0.0, -0.055], "normal": [0.0, 0.0, 1.0]})))
    assert run.collision_count >= 1
    with pytest.raises(GrapefmuError, match="17 mm inside obstacle 'o' in the initial state") as err:
        scene(doc({"point": [0.0, 0.045, 0.0], "normal": [0.0, -1.0, 0.0]}))
    assert err.value.key == "obstacles[0].point"

"""What a run writes, read back by independent readers (numpy, pyarrow, rosbags, mcap-ros2-support)."""
from __future__ import annotations

import json
import subprocess
import sys
import tomllib
from pathlib import Path

import numpy as np
import pytest

from grapefmu import simulate
from grapefmu.solver.islands import Islands
from grapefmu.solver.solver import Solver
from grapefmu.recording.messages import absolute, relative
from grapefmu.write import write_run

from .conftest import dual, scene
from .recordings import decode_everything

@pytest.fixture(scope="module")
def run():
    return simulate(scene(dual(solver={"t_end": 0.5})))


def test_csv_has_the_named_columns_and_values(run, tmp_path):
    path = tmp_path / "run.csv"
    write_run(run, path)
    data = np.genfromtxt(path, delimiter=",", names=True)
    for col in ("time_s", "angle_left_rad", "angle_right_rad", "angular_velocity_left_rad_s", "pedicel_tension_right_n",
                "contact_force_left_right_n", "penetration_left_right_m", "energy_kinetic_j", "in_contact_left_right",
                "collision_count"):  # each named with its unit (a count or a flag has none)
        assert col in data.dtype.names
    np.testing.assert_allclose(data["angle_right_rad"], run.angles[:, 1], rtol=1e-11, atol=1e-14)
    np.testing.assert_allclose(data["contact_force_left_right_n"], run.contact_force[:, 0], rtol=1e-11, atol=1e-14)
    assert data["contact_force_left_right_n"].max() > 0


def test_parquet_roundtrip_keeps_the_scene(run, tmp_path):
    import pyarrow.parquet as pq
    path = tmp_path / "run.parquet"
    write_run(run, path)
    table = pq.read_table(path)
    np.testing.assert_array_equal(table.column("angle_left_rad").to_numpy(), run.angles[:, 0])
    assert tomllib.loads(table.schema.metadata[b"grapefmu.scene"].decode()) is not None


def test_mcap_reads_back_in_rosbags_and_mcap_ros2(run, tmp_path):
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory
    from rosbags.highlevel import AnyReader

    path = tmp_path / "run.mcap"
    write_run(run, path)
    with AnyReader([path]) as r:
        counts = {relative(c.topic): c.msgcount for c in r.connections}
        assert counts["joint_states"] == len(run.t)
        # one message per impact, as many as the independent scipy reference finds
        assert counts["collision_events"] == len(run.impacts) == simulate(run.scene, method="reference").collision_count
        js = [c for c in r.connections if c.topic == absolute("joint_states")]
        positions = np.array([r.deserialize(raw, c.msgtype).position for c, _, raw in r.messages(connections=js)])
        np.testing.assert_array_equal(positions, run.angles)
        ev = [c for c in r.connections if c.topic == absolute("collision_events")]
        peaks = [r.deserialize(raw, c.msgtype).peak_force for c, _, raw in r.messages(connections=ev)]
        np.testing.assert_allclose(sorted(peaks), sorted(run.impacts.peak_force))
    with open(path, "rb") as fh:
        reader = make_reader(fh, decoder_factories=[DecoderFactory()])
        meta = {m.name: m.metadata for m in reader.iter_metadata()}
        assert tomllib.loads(meta["grapefmu"]["scene_toml"])["berries"][0]["name"] == "left"
        efforts = [m.effort for _, _, _, m in reader.iter_decoded_messages(topics=[absolute("joint_states")])]
        assert len(efforts) == len(run.t) and all(len(e) == 2 for e in efforts)
    counts = decode_everything(path)
    assert counts["joint_states"] == counts["pedicel_tension"] == counts["summary"] == len(run.t)


def test_a_recording_says_why_its_results_cannot_be_trusted(run, tmp_path):
    """The grapefmu metadata record holds the run's warnings as a JSON list: a run whose fixed step is too long for
    its contact says so in the file itself, where Foxglove and rosbags show it; a sound run's list is empty."""
    from mcap.reader import make_reader

    coarse = simulate(scene(dual(solver={"t_end": 0.5, "method": "paper", "fixed_step": 2e-3})))
    for r, name in ((run, "fine.mcap"), (coarse, "coarse.mcap")):
        write_run(r, tmp_path / name)
        with open(tmp_path / name, "rb") as fh:
            meta = {m.name: m.metadata for m in make_reader(fh).iter_metadata()}
        assert json.loads(meta["grapefmu"]["warnings"]) == r.summary()["warnings"]
    assert coarse.summary()["warnings"][0].startswith("fixed step 0.002 s is too long")
    assert run.summary()["warnings"] == []


def test_a_turning_run_draws_its_markers_and_frames_where_its_berries_are(tmp_path):
    """A run whose rachis turns: every sample's markers and TF (world → rachis → berry) put each berry at its own
    world position x = b + R p (the markers once took every sample's orientation from the first)."""
    from rosbags.highlevel import AnyReader
    from scipy.spatial.transform import Rotation

    from grapefmu.recording.typestore import TYPESTORE
    from grapefmu.results import catalogue

    doc = dual(left={"kind": "spherical", "angle": [-0.6, 0.2]}, right={"kind": "spherical", "angle": [0.6, -0.1]},
               excitation={"kind": "sine", "amplitude": [2.0, 1.0, -1.5], "angular_amplitude": [3.0, -2.0, 4.0],
                           "frequency": 3.0, "orientation": [0.1, -0.2, 0.3], "angular_velocity": [0.5, -0.4, 0.8]})
    run = simulate(scene(doc), 0.2)
    write_run(run, tmp_path / "turn.mcap")
    snap = run.snapshot()
    world = {int(round(t * 1e9)): x for t, x in zip(run.t, catalogue.world(snap, snap.observation.position))}
    checked = 0
    with AnyReader([tmp_path / "turn.mcap"], default_typestore=TYPESTORE) as reader:
        for c, ns, raw in reader.messages():
            m = reader.deserialize(raw, c.msgtype)
            if c.topic == "/tf":
                tr = {x.child_frame_id: x.transform for x in m.transforms}
                b, q = tr["grape_cluster/rachis"].translation, tr["grape_cluster/rachis"].rotation
                for i, name in enumerate(run.scene.model.names):
                    p = tr[f"grape_cluster/{name}"].translation
                    x = Rotation.from_quat([q.x, q.y, q.z, q.w]).apply([p.x, p.y, p.z]) + [b.x, b.y, b.z]
                    np.testing.assert_allclose(x, world[ns][i], atol=1e-12)
            elif c.topic.endswith("/markers"):
                spheres = [x.pose.position for x in m.markers if x.ns == "berries"]
                np.testing.assert_allclose([[s.x, s.y, s.z] for s in spheres], world[ns], atol=1e-12)
                checked += 1
    assert checked > 5 and np.ptp(run.base_orientation, axis=0).max() > 0.05


def test_main_command_writes_plot_and_mcap(tmp_path):
    r = subprocess.run([sys.executable, "-m", "grapefmu", "simulate", "--plot", str(tmp_path / "d.png"),
                        "--out", str(tmp_path / "d.mcap")], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    assert "collisions" in r.stdout and "peak contact force" in r.stdout
    assert (tmp_path / "d.png").stat().st_size > 20_000
    assert (tmp_path / "d.mcap").stat().st_size > 10_000
    assert not list(Path(tmp_path).glob(".*.part"))


@pytest.mark.parametrize("name", ["open_loop", "gentle"])
def test_example_recordings_read_back_and_replay_exactly(name):
    from grapefmu.recording.replay import check
    path = Path(__file__).resolve().parents[1] / "recordings" / f"{name}.mcap"
    topics = decode_everything(path)
    assert topics["joint_states"] > 2000 and "collision_events" in topics and "rachis/accel_applied" in topics
    res = check(path)
    assert res.truncated is None and res.compared >= 2000 and res.max_deviation == 0.0


def test_a_run_off_its_output_grid_ends_with_a_sample_at_its_end():
    """t_end off the output grid, an impact after the last grid point: the run's last sample is its end, on every
    path (one step size, islands, the scipy reference). Before, the samples stopped at the grid point before it, and
    the summary read its end time and its energy there (t_end_s 0.08 s, the contacts' dissipation below the impact's
    own), while it counted the impact."""
    sc = scene(dual(solver={"t_end": 0.0895, "output_interval": 0.01}))
    solver = Solver(sc)
    r = solver.run()
    assert r.t[-1] == 0.0895 and len(r.t) == 10 and r.t[-2] == pytest.approx(0.08)
    np.testing.assert_allclose(r.y[-1], solver.y, rtol=1e-12, atol=1e-18)  # the dense output at the step's end
    assert len(r.impacts) == 1 and r.impacts.onset[0] > r.t[-2]
    s = r.summary()
    assert s["t_end_s"] == 0.0895 and s["collision_count"] == 1 == r.columns()["collision_count"][-1]
    assert s["bruising_impacts"] == int(r.impacts.bruising.sum())
    assert s["peak_contact_force_n"] == r.impacts.peak_force.max()
    assert r.energy["dissipated_contact"][-1] == pytest.approx(r.impacts.dissipated.sum(), rel=1e-6)
    for other in (Islands(sc).run(), simulate(sc, method="reference")):
        np.testing.assert_array_equal(other.t, r.t)
        np.testing.assert_allclose(other.angles[-1], r.angles[-1], atol=1e-6)


@pytest.mark.parametrize("t_end", [1e-300, 1e-13])
def test_a_run_shorter_than_a_rounding_of_its_output_interval_ends_with_a_sample_at_its_end(t_end):
    """A run shorter than 1e-9 of its output interval (grid_last's tolerance for an end just past a grid point) had
    only its start's sample: `grapefmu simulate --t-end 1e-300` said "simulated 0 s". Its last sample is now its end,
    on every path: one step size, islands, the scipy reference, and groups run apart (run_by_group); a run of no
    length keeps its one sample."""
    sc = scene(dual(solver={"output_interval": 0.01}))
    apart = scene(dual(d0=0.2))  # berries that cannot reach each other: two groups
    solver = Solver(sc)
    r = solver.run(t_end)
    assert list(r.t) == [0.0, t_end] and r.summary()["t_end_s"] == t_end
    np.testing.assert_allclose(r.y[-1], solver.y, rtol=1e-12, atol=0.0)  # the dense output at the step's end
    runs = (Islands(sc).run(t_end), simulate(sc, t_end, method="reference"), simulate(apart, t_end))
    assert runs[2].stats["groups"] == 2
    for other in runs:
        assert list(other.t) == [0.0, t_end]
    assert list(Solver(sc).run(0.0).t) == [0.0]


def test_the_foxglove_layout_is_current_and_names_only_recorded_topics(run, tmp_path):
    import json
    from grapefmu.recording import foxglove
    shipped = json.loads((Path(__file__).resolve().parents[1] / "recordings" / "grapefmu.foxglove.json").read_text())
    assert shipped == foxglove.layout(run.scene.model)  # regenerated with the command in foxglove.py
    path = tmp_path / "run.mcap"
    write_run(run, path)
    from rosbags.highlevel import AnyReader
    with AnyReader([path]) as r:
        recorded = {c.topic for c in r.connections}
    named = foxglove.topics(shipped)
    assert named and named <= recorded
    assert {"/tf", "/tf_static", absolute("robot_description"), absolute("markers"), "/clock"} <= recorded


def test_the_summary_message_is_the_catalogue():
    from grapefmu.recording.messages import summary_msg
    from grapefmu.recording.typestore import MSG_DIR
    assert (MSG_DIR / "Summary.msg").read_text(encoding="utf-8") == summary_msg()  # regenerate it from summary_msg()


def test_a_negative_pedicel_tension_is_explained_where_it_is_shown():
    """It is the twig in compression (a contact or the base pushing the berry toward its hinge): the channel's
    description and the figure's axis say so."""
    import inspect
    from grapefmu.results import catalogue, plot
    assert "compression" in catalogue.channel("pedicel_tension").description
    assert "compressed" in inspect.getsource(plot)


def test_contact_log_fills_each_pair_from_its_latest_change():
    """ContactLog.dense and .mode against the plain definition: from each change's sample on, its pair has its
    record, later changes (the same sample included) overriding earlier ones."""
    from grapefmu.physics.forces import CONTACT
    from grapefmu.results.contacts import CHANGE, ContactLog

    rng = np.random.default_rng(3)
    n, pairs = 400, 7
    changes = np.zeros(900, CHANGE)
    changes["sample"] = np.sort(rng.integers(0, n, len(changes)))
    changes["pair"] = rng.integers(0, pairs, len(changes))
    changes["mode"] = rng.integers(0, 3, len(changes))
    changes["v_onset"] = rng.random(len(changes))
    changes["smooth"] = rng.random(len(changes)) < 0.3
    start = np.zeros(pairs, CONTACT)
    start["mode"], start["v_onset"] = 1, 0.5
    expected = np.empty((n, pairs), CONTACT)
    expected[:] = start
    for row in changes:
        for f in CONTACT.names:
            expected[f][row["sample"]:, row["pair"]] = row[f]
    log = ContactLog(start, changes)
    assert np.array_equal(log.dense(n), expected)
    assert np.array_equal(log.mode(n), expected["mode"].astype(np.int8))
    assert np.array_equal(ContactLog.of(expected).dense(n), expected)


def test_contact_log_agrees_with_the_impact_book():
    """A run keeps each pair's contact record as changes (results/contacts.py); 230 impacts overflow the recorder's
    change log several times (its chunks are joined). A pair is in contact at exactly the samples inside one of its
    impacts, onset < t ≤ end (a sample at a step's end holds the step's mode), and the log densifies to the records
    it was made from."""
    from grapefmu.bench.scenes import bench_scenes, build
    from grapefmu.results.contacts import ContactLog

    run = simulate(build(bench_scenes()["shaken stiff pair"]), rtol=1e-6, atol=1e-8, output_interval=1e-3)
    assert len(run.impacts) > 200 and len(run.contact_log.changes) > 4 * 64
    inside = np.zeros(len(run.t), bool)
    for onset, end in zip(run.impacts.onset, run.impacts.end):
        inside |= (run.t > onset) & (run.t <= end)
    assert np.array_equal(run.mode[:, 0] != 0, inside)
    assert np.array_equal(run.contacts["mode"], run.mode)
    again = ContactLog.of(run.contacts)
    assert np.array_equal(again.dense(len(run.t)), run.contacts)


def test_write_run_refuses_a_directory_as_its_file_naming_it(tmp_path):
    """write_run(run, "x.csv") where x.csv is a directory raised IsADirectoryError on its temporary file (an audit);
    the CLI already refused it. Now write_run checks the path as the CLI does, and writes nothing."""
    from grapefmu.errors import GrapefmuError
    from grapefmu.write import write_run
    from .conftest import dual, scene
    (tmp_path / "x.csv").mkdir()
    with pytest.raises(GrapefmuError, match=r"output .*x\.csv: is a directory; expected a file name ending in"):
        write_run(simulate(scene(dual(solver={"t_end": 0.01}))), tmp_path / "x.csv")
    assert [p.name for p in tmp_path.iterdir()] == ["x.csv"] and not any((tmp_path / "x.csv").iterdir())

"""Issue 16, item 4: `grapefmu replay FILE --check` tells a truncated recording (a killed writer: checked up
to its last complete chunk, exit 0) from a corrupted one (a CRC, parse or decode failure: one line naming
the record, non-zero exit), and any deviation above the tolerance fails the check."""
from __future__ import annotations

import json
import math

import subprocess
import sys
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from mcap.reader import make_reader
from mcap.writer import CompressionType

from grapefmu.cli import main
from grapefmu.errors import GrapefmuError, RecordingError
from grapefmu.recording.messages import absolute
from grapefmu.recording.mcap_writer import write_mcap
from grapefmu.recording.replay import TOLERANCE, CorruptRecording, check
from grapefmu.recording.typestore import McapWriter, deserialize, serialize
from grapefmu.scenefile import default_scene_path, load_scene
from grapefmu.solver.api import simulate

FUZZ = settings(max_examples=300, deadline=None, derandomize=True, database=None,
                suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])


@pytest.fixture(scope="module")
def recordings(tmp_path_factory):
    """The default scene for 0.05 s: written by the command line (one zstd chunk), by the library's writer
    in small chunks, so that a cut leaves some complete chunks behind, and in small uncompressed chunks (as
    the ROS node records)."""
    d = tmp_path_factory.mktemp("rec")
    cli = d / "cli.mcap"
    assert main(["simulate", "--t-end", "0.05", "--out", str(cli)]) == 0
    small = d / "chunked.mcap"
    write_mcap(simulate(load_scene(default_scene_path()), 0.05), small, chunk_size=2048)
    plain = d / "plain.mcap"
    rewrite(small, plain, lambda *_: None, CompressionType.NONE)
    return {"cli": cli, "chunked": small, "plain": plain}


def messages(path: Path) -> list | None:
    """(metadata, [(topic, log time, CDR bytes)]) read by mcap's own reader without CRC checks, or None when
    it cannot read them: what a check that passes must have seen."""
    try:
        with open(path, "rb") as fh:
            reader = make_reader(fh)
            meta = [(m.name, dict(m.metadata)) for m in reader.iter_metadata()]
            msgs = [(c.topic, m.log_time, bytes(m.data)) for _, c, m in reader.iter_messages(log_time_order=False)]
        return [meta, msgs]
    except Exception:  # noqa: BLE001 - any failure: not readable
        return None


def replay(path: Path, capsys) -> tuple[int, str]:
    rc = main(["replay", str(path), "--check"])
    out = capsys.readouterr()
    return rc, out.out + out.err


def test_an_intact_recording_passes(recordings, capsys):
    for path in recordings.values():
        r = check(path)
        assert r.ok and r.truncated is None and r.max_deviation == 0.0 and r.compared == 51
        rc, out = replay(path, capsys)
        assert rc == 0 and "51 joint states compared" in out


@pytest.mark.parametrize("fraction", [0.3, 0.5, 0.7, 0.9, 0.97, 0.999])
def test_a_truncated_recording_is_checked_up_to_its_last_complete_chunk(recordings, tmp_path, capsys, fraction):
    data = recordings["chunked"].read_bytes()
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(data[: int(fraction * len(data))])
    r = check(cut)
    assert r.ok and r.truncated and "truncated" in r.truncated and 0 < r.compared <= 51
    rc, out = replay(cut, capsys)
    assert rc == 0 and "truncated" in out and "Traceback" not in out
    assert len([line for line in out.splitlines() if "truncated" in line]) == 1


def test_a_recording_cut_before_its_metadata_is_refused_in_one_line(recordings, tmp_path, capsys):
    cut = tmp_path / "cut.mcap"
    for n in (0, 5, 30, 300):
        cut.write_bytes(recordings["chunked"].read_bytes()[:n])
        with pytest.raises(RecordingError):
            check(cut)
        rc, out = replay(cut, capsys)
        assert rc != 0 and len(out.strip().splitlines()) == 1


def fuzz_one(original: Path, damaged: bytes, tmp_path: Path) -> None:
    """The property: a named error, or a check that passes only when the damaged file's messages and
    metadata are exactly the original's; never another exception, never a truncation claimed for a file
    of full length."""
    path = tmp_path / "damaged.mcap"
    path.write_bytes(damaged)
    try:
        r = check(path)
    except GrapefmuError as e:
        assert "\n" not in str(e)
        return
    assert r.truncated is None, r.truncated  # the file has its full length: nothing was cut off
    if r.ok:
        assert messages(path) == messages(original), "a damaged recording passed the check"


@pytest.mark.parametrize("which", ["cli", "chunked", "plain"])
def test_bit_flips_are_never_reported_as_success(recordings, tmp_path, which):
    data = recordings[which].read_bytes()

    @FUZZ
    @given(offset=st.integers(0, len(data) - 1), bit=st.integers(0, 7))
    def flip(offset, bit):
        b = bytearray(data)
        b[offset] ^= 1 << bit
        fuzz_one(recordings[which], bytes(b), tmp_path)

    flip()


def test_garbage_runs_are_never_reported_as_success(recordings, tmp_path):
    data = recordings["chunked"].read_bytes()

    @FUZZ
    @given(offset=st.integers(0, len(data) - 1), garbage=st.binary(min_size=1, max_size=24))
    def overwrite(offset, garbage):
        b = bytearray(data)
        b[offset: offset + len(garbage)] = garbage
        fuzz_one(recordings["chunked"], bytes(b[: len(data)]), tmp_path)

    overwrite()


def test_a_damaged_chunk_is_named_with_its_offset_and_time(recordings, tmp_path, capsys):
    data = bytearray(recordings["chunked"].read_bytes())
    with open(recordings["chunked"], "rb") as fh:
        chunk = make_reader(fh).get_summary().chunk_indexes[3]
    data[chunk.chunk_start_offset + chunk.chunk_length - 10] ^= 0x10  # inside the chunk's compressed data
    path = tmp_path / "flipped.mcap"
    path.write_bytes(bytes(data))
    with pytest.raises(CorruptRecording, match=f"chunk at byte {chunk.chunk_start_offset} .messages logged"):
        check(path)
    rc, out = replay(path, capsys)
    assert rc != 0 and len(out.strip().splitlines()) == 1 and f"chunk at byte {chunk.chunk_start_offset}" in out
    r = subprocess.run([sys.executable, "-m", "grapefmu", "replay", str(path), "--check"], capture_output=True,
                       text=True, timeout=120)
    assert r.returncode != 0 and "Traceback" not in r.stderr and "corrupted" in r.stderr


def rewrite(original: Path, out: Path, change, compression=CompressionType.ZSTD, meta_change=None,
            chunk_size: int = 2048) -> None:
    """Copy a recording message by message, in the file's order, through the typestore: `change(topic, log_time,
    message)` edits the decoded message in place, or returns the messages written in its place (none: it is dropped;
    the CRCs are those of the new bytes), and `meta_change(metadata)` each metadata record's map."""
    with open(original, "rb") as fh:
        reader = make_reader(fh)
        meta = {m.name: dict(m.metadata) for m in reader.iter_metadata()}
        msgs = [(s.name, c.topic, m.log_time, bytes(m.data)) for s, c, m in reader.iter_messages(log_time_order=False)]
    for data in meta.values() if meta_change else ():
        meta_change(data)
    with McapWriter(out, compression=compression, chunk_size=chunk_size) as w:
        for name, data in meta.items():
            w.add_metadata(name, data)
        for typename, topic, t, data in msgs:
            m = deserialize(data, typename)
            written = change(topic, t, m)
            for x in (m,) if written is None else written:
                w.write(topic, x, t)


@pytest.mark.parametrize("field, delta, passes", [("position", 1e-3, False), ("velocity", 0.82, False),
                                                  ("position", 1e-9, True)])
def test_a_deviation_above_the_tolerance_fails(recordings, tmp_path, capsys, field, delta, passes):
    def perturb(topic, t, m):
        if topic == absolute("joint_states") and t == 20_000_000:
            v = getattr(m, field).copy()
            v[1] += delta
            setattr(m, field, v)
    path = tmp_path / "perturbed.mcap"
    rewrite(recordings["chunked"], path, perturb)
    r = check(path)
    assert r.truncated is None and r.compared == 51
    assert r.max_deviation == pytest.approx(delta, rel=1e-3) and r.ok is passes and (delta < TOLERANCE) is passes
    rc, out = replay(path, capsys)
    if passes:
        assert rc == 0
    else:
        assert rc == 1 and "t = 0.020000 s" in out and "tolerance" in out


@pytest.mark.parametrize("key, value, unmatched", [("t_end", 0.02, 30), ("output_interval", 0.002, 25)])
def test_settings_that_do_not_describe_the_recorded_run_fail(recordings, tmp_path, capsys, key, value, unmatched):
    """A recording whose metadata gives a shorter run or a coarser grid than its joint states passed: only the states
    at the re-simulated samples were compared, the rest skipped without a word (found by an audit)."""
    def settings(meta):
        if "solver" in meta:
            meta["solver"] = json.dumps(json.loads(meta["solver"]) | {key: value})
    path = tmp_path / "settings.mcap"
    rewrite(recordings["chunked"], path, lambda *_: None, meta_change=settings)
    r = check(path)
    assert not r.ok and r.unmatched == unmatched and r.max_deviation == 0.0
    rc, out = replay(path, capsys)
    assert rc == 1 and f"{unmatched} recorded joint states" in out and "no sample in the re-simulation" in out


def test_a_reference_run_is_checked_and_a_method_grapefmu_does_not_run_is_refused(tmp_path, capsys):
    """The reference method's recordings named it "reference (DOP853)", which replay handed to simulate(): every
    check failed (exit 1, as a deviation). Recordings written so are still read; a method that is none of grapefmu's
    is refused naming the file (exit 2)."""
    path = tmp_path / "reference.mcap"
    write_mcap(simulate(load_scene(default_scene_path()), 0.05, method="reference"), path, chunk_size=2048)
    r = check(path)
    assert r.ok and r.compared == 51 and r.max_deviation == 0.0
    for method, rc_expected in (("reference (DOP853)", 0), ("bogus", 2)):
        named = tmp_path / f"{method}.mcap"
        rewrite(path, named, lambda *_: None,
                meta_change=lambda meta, method=method: meta.update(method=method) if "method" in meta else None)
        rc, out = replay(named, capsys)
        assert rc == rc_expected, out
    assert f"{named}: the recorded method 'bogus' is none of event, paper, reference" in out


def test_a_nan_in_a_recorded_angle_is_a_deviation(recordings, tmp_path):
    def poison(topic, t, m):
        if topic == absolute("joint_states") and t == 30_000_000:
            m.position = m.position.copy()
            m.position[0] = float("nan")
    path = tmp_path / "nan.mcap"
    rewrite(recordings["chunked"], path, poison)
    assert not check(path).ok


def test_a_recording_is_rerun_the_way_it_ran_in_islands_or_not(tmp_path, monkeypatch):
    """A recording keeps the berry count from which `solver.islands = "auto"` ran a scene in islands: replayed under
    another count (or one recorded before "auto", when every such run took one step size), it is re-simulated as
    it ran, to the bit, where the rule of the day would run it the other way (islands or one step size differ
    within the tolerance asked, not to the bit)."""
    from grapefmu.cluster import ClusterSpec, cluster_scene
    from grapefmu.model import model as model_module
    from grapefmu.scenefile import scene_from_dict
    solver = {"t_end": 0.2, "rtol": 1e-8, "atol": 1e-11}
    sc = scene_from_dict(cluster_scene(ClusterSpec(berries=12, seed=1, solver=solver)), Path.cwd())
    for ran_from, replay_from in ((1000, 12), (12, 1000)):
        monkeypatch.setattr(model_module, "ISLANDS_FROM", ran_from)
        monkeypatch.setattr("grapefmu.recording.mcap_writer.ISLANDS_FROM", ran_from)
        run = simulate(sc)
        assert ("islands_formed" in run.stats) == (ran_from == 12)
        path = tmp_path / f"from{ran_from}.mcap"
        write_mcap(run, path)
        monkeypatch.setattr(model_module, "ISLANDS_FROM", replay_from)
        monkeypatch.setattr("grapefmu.recording.replay.ISLANDS_FROM", replay_from)
        assert ("islands_formed" in simulate(sc).stats) == (replay_from == 12)  # today's rule: the other way
        result = check(path)
        assert result.compared == len(run.t) and result.max_deviation == 0.0


@pytest.mark.parametrize("ran, rtol", [("DOPRI5", 3e-6), ("DOP853", 1e-4)])
def test_a_recording_is_rerun_with_the_pair_it_was_stepped_with(tmp_path, monkeypatch, ran, rtol):
    """A recording names the Runge–Kutta pair its run stepped with (the run's stats' integrator): replayed where
    today's rule picks the other pair, it is re-simulated with its own (solver.integrator pinned), to the bit; with
    the other pair it would agree to the tolerance only. A recording that names none was made under the rule of its
    day, DOP853 below rtol 1e-7 alone, and is pinned to what that rule chose."""
    from grapefmu.bench.scenes import bench_scenes, build
    from grapefmu.solver import solver as solver_module
    sc = build(bench_scenes()["paper collision"])
    today = simulate(sc, 0.5, rtol=rtol, atol=rtol / 100)
    assert today.stats["integrator"] != ran
    with monkeypatch.context() as m:  # the rule of another day
        m.setattr(solver_module, "DOP853_BELOW_FEW", 1.0 if ran == "DOP853" else 0.0)
        run = simulate(sc, 0.5, rtol=rtol, atol=rtol / 100)
    assert run.stats["integrator"] == ran and float(abs(run.y - today.y).max()) > 0.0
    named = tmp_path / "named.mcap"
    write_mcap(run, named)
    result = check(named)
    assert result.compared == len(run.t) and result.max_deviation == 0.0
    if ran == "DOPRI5":  # what the rule before 2026-11-29 chose at this rtol: a recording of then names no pair
        del run.stats["integrator"]
        unnamed = tmp_path / "unnamed.mcap"
        write_mcap(run, unnamed)
        assert check(unnamed).max_deviation == 0.0


def test_a_recording_of_groups_stepped_by_different_pairs_runs_under_todays_rule(tmp_path, monkeypatch):
    """Independent groups of a scene may step with different pairs (solver.integrator_for counts a group's berries):
    the run's stats say "mixed", which no scene can pin, and its replay runs under the rule, to the bit."""
    from grapefmu.solver import solver as solver_module

    from .conftest import dual, scene
    doc = dual()
    doc["berries"].append({**doc["berries"][0], "name": "lone", "hinge_x": -0.5, "angle": 0.3})  # out of reach
    sc = scene(doc)
    monkeypatch.setattr(solver_module, "FEW_BERRIES", 2)  # the pair's group steps with DOPRI5, the lone berry DOP853
    run = simulate(sc, 0.3, rtol=1e-6, atol=1e-8)
    assert run.stats["groups"] == 2 and run.stats["integrator"] == "mixed"
    path = tmp_path / "mixed.mcap"
    write_mcap(run, path)
    result = check(path)
    assert result.compared == len(run.t) and result.max_deviation == 0.0


def test_a_scene_changed_in_code_is_recorded_as_it_ran(tmp_path):
    """A scene changed in code (`dataclasses.replace`: its initial state, a berry's hinge, its solver, thresholds and
    name) is recorded with a document that reads back as it, not the one it was read from: its replay re-simulates
    it to the bit, where the stale document's scene runs otherwise, and the Parquet file names it too. An unchanged
    scene, or the face's driven one, keeps the text it was read from, comments and all."""
    from dataclasses import replace

    import pyarrow.parquet as pq

    from grapefmu.results.writers import write_parquet
    from grapefmu.scenefile import parse_scene, scene_toml
    sc = load_scene(default_scene_path())
    assert scene_toml(sc) == scene_toml(sc.driven()) == sc.source and sc.source.lstrip().startswith("#")
    m = sc.model
    changed = replace(sc, angles=(-0.2, 0.1), name="changed", solver=replace(sc.solver, rtol=1e-7, atol=1e-9),
                      thresholds=replace(sc.thresholds, bruise_force=1.2),
                      model=replace(m, berries=(replace(m.berries[0], hinge_stiffness=0.004),) + m.berries[1:]))
    run = simulate(changed, 0.3)
    stale = simulate(parse_scene(sc.source), 0.3, rtol=1e-7, atol=1e-9)
    assert float(abs(stale.y[:, :2] - run.y[:, :2]).max()) > 100 * TOLERANCE
    path = tmp_path / "changed.mcap"
    write_mcap(run, path)
    result = check(path)
    assert result.compared == len(run.t) and result.max_deviation == 0.0
    write_parquet(run, tmp_path / "changed.parquet")
    text = pq.read_schema(tmp_path / "changed.parquet").metadata[b"grapefmu.scene"].decode()
    again = parse_scene(text)
    assert again.key == changed.key != sc.key and again.name == "changed" and again.solver.rtol == 1e-7


def test_a_change_its_document_cannot_carry_is_refused_before_a_file_is_written(tmp_path):
    """A berry's mass changed in code leaves its contact law as calibrated for the old mass (the file asks for a
    restitution, so reading it back calibrates anew): no document describes that scene, and recording it is refused
    naming `source`, before a file exists. So is a start the document would refuse, and a scene built in code
    without a document."""
    from dataclasses import replace

    from grapefmu.errors import SceneError
    from grapefmu.model.model import Scene
    from grapefmu.scenefile import scene_toml
    sc = load_scene(default_scene_path())
    m = sc.model
    heavier = replace(sc, model=replace(m, berries=(replace(m.berries[0], mass=0.02),) + m.berries[1:]))
    run = simulate(heavier, 0.05)
    with pytest.raises(SceneError, match="contacts") as e:
        write_mcap(run, tmp_path / "heavier.mcap")
    assert e.value.key == "source" and list(tmp_path.iterdir()) == []
    with pytest.raises(SceneError, match="would refuse .*overlap") as e:  # a start the parser takes for a typo
        scene_toml(replace(sc, angles=(0.3, -0.1)))
    assert e.value.key == "source"
    with pytest.raises(SceneError, match="without a scene document") as e:
        scene_toml(Scene(m, sc.angles, sc.angular_velocities))
    assert e.value.key == "source"


@pytest.mark.parametrize("path", sorted(str(p.relative_to(default_scene_path().parent))
                                        for p in default_scene_path().parent.rglob("*.toml")))
def test_every_shipped_scene_reads_back_from_its_rewritten_document(path):
    """The writer's berries, initial state, solver and thresholds on every packaged scene (planar and spherical
    berries, hinges on and off the rod, obstacles, the pick-and-place and still rachis): a scene renamed in code,
    with one berry's damping and a threshold changed, is described by the document written for it."""
    from dataclasses import replace

    from grapefmu.scenefile import parse_scene, scene_toml
    sc = load_scene(default_scene_path().parent / path)
    m = sc.model
    changed = replace(sc, name="renamed", thresholds=replace(sc.thresholds, fatigue_fraction=0.4),
                      model=replace(m, berries=(replace(m.berries[0], hinge_damping=3e-5),) + m.berries[1:]))
    text = scene_toml(changed)
    assert text != sc.source and parse_scene(text).key == changed.key != sc.key


POSES = "time,x,y,z,roll,pitch,yaw\n" + "".join(
    f"{t:.2f},{0.05 * (10 * (t / 0.5) ** 3 - 15 * (t / 0.5) ** 4 + 6 * (t / 0.5) ** 5)!r},0.0,0.0,0.0,0.0,0.3\n"
    for t in [k * 0.01 for k in range(51)])
TABLES = {"csv": ("time,ax,az\n0,0.0,0.0\n0.1,2.0,1.0\n0.2,2.0,1.0\n", {"after": "zero"}), "pose-table": (POSES, {})}


@pytest.mark.parametrize("kind", TABLES)
def test_a_recording_carries_the_csv_its_scene_names(tmp_path, monkeypatch, kind):
    """A scene whose excitation is a CSV file named relative to the scene file is recorded with the table inline
    (`text`): its replay re-simulates it to the bit from another directory with the file gone. The table given
    inline in a scene file reads as the same scene as the file, and a scene giving both is refused."""
    from grapefmu.errors import SceneError
    from grapefmu.scenefile import parse_scene, scene_from_dict
    from grapefmu.scenefile.toml_out import dumps

    from .conftest import dual
    text, options = TABLES[kind]
    (tmp_path / "scene").mkdir()
    (tmp_path / "scene" / "motion.csv").write_text(text)
    doc = dual(angles=(0.0, 0.3), excitation={"kind": kind, "file": "motion.csv", **options}, name="moved")
    (tmp_path / "scene" / "moved.toml").write_text(dumps(doc))
    sc = load_scene(tmp_path / "scene" / "moved.toml")
    run = simulate(sc, 0.3)
    assert float(abs(run.base_displacement).max()) > 1e-3  # the table moves the rachis
    (tmp_path / "out").mkdir()
    path = tmp_path / "out" / "moved.mcap"
    write_mcap(run, path)
    (tmp_path / "scene" / "motion.csv").unlink()
    monkeypatch.chdir(tmp_path / "out")
    result = check(path)
    assert result.compared == len(run.t) and result.max_deviation == 0.0
    inline = {**doc, "excitation": {"kind": kind, "text": text, **options}}
    assert scene_from_dict(inline, tmp_path).key == sc.key
    with pytest.raises(SceneError, match="exactly one") as e:
        parse_scene(dumps({**doc, "excitation": {**inline["excitation"], "file": "motion.csv"}}))
    assert e.value.key == "excitation.file"


def _real_time_copy(path, t_max: int, leave_out, wall: int = 1_796_000_000 * 10**9, back=(math.inf, 0)) -> None:
    """The shipped lockstep recording up to `t_max` ns, logged `wall` ns later (a real-time node's stamps: the wall
    clock's, here 2026-11-30), without the sim_time messages `leave_out` picks out of their indices; after simulated
    time back[0] (ns), logged back[1] ns earlier again."""
    with open(Path(__file__).parents[1] / "recordings" / "gentle.mcap", "rb") as fh:
        reader = make_reader(fh)
        meta = {m.name: dict(m.metadata) for m in reader.iter_metadata()}
        msgs = [(s.name, c.topic, m.log_time, bytes(m.data)) for s, c, m in reader.iter_messages()
                if m.log_time <= t_max]
    lost = leave_out([k for k, (_, topic, _, _) in enumerate(msgs) if topic == absolute("sim_time")])
    with McapWriter(path, chunk_size=2048) as w:
        for name, data in meta.items():
            w.add_metadata(name, data)
        for k, (typename, topic, t, data) in enumerate(msgs):
            if k not in lost:
                w.write(topic, deserialize(data, typename), wall + t - (back[1] if t > back[0] else 0))


def test_a_real_time_recording_cut_between_an_intervals_two_messages_is_checked_up_to_the_interval_before(tmp_path):
    """A node in real time stamps its messages with the wall clock and says where each interval ends in `sim_time`,
    logged right after the interval's rachis/accel_applied. A file cut between the two has lost where its last
    interval ends: it is left out. Before, the check took that interval's wall-clock stamp (1.8e9 s) for its end and
    asked the solver for 1.8e9 s, which it refused (tests/test_ros_node.py's killed node, now and then). Here: the
    shipped lockstep recording's first 0.2 s, logged at wall-clock times, its last sim_time left out, cut before its
    data section ends."""
    path = tmp_path / "realtime.mcap"
    _real_time_copy(path, 200_000_000, lambda at: at[-1:])
    data = path.read_bytes()
    summary_start = int.from_bytes(data[-28:-20], "little")  # the footer's first field, before its CRC and magic
    path.write_bytes(data[: summary_start - 13])  # without the data-end record (opcode, length, CRC): cut
    r = check(path)
    assert r.truncated and r.ok and r.max_deviation == 0.0 and r.compared == 199


def test_an_interval_without_its_sim_time_in_a_whole_recording_is_refused_by_its_stamp(tmp_path):
    """Only a cut can lose a sim_time; in a whole file a missing one is damage, and the interval's stamp, the wall
    clock's in real time, is no end to re-simulate to: the check names the interval instead of asking the solver
    for 1.8e9 s. A recording with no sim_time at all (a lockstep node's from before it logged them, stamped with
    simulated time) still ends each interval at its stamp."""
    path = tmp_path / "realtime.mcap"
    _real_time_copy(path, 200_000_000, lambda at: at[len(at) // 2:len(at) // 2 + 1])
    with pytest.raises(RecordingError, match=r"accel_applied is logged at 1796000000\.\d+ s has no sim_time"):
        check(path)
    old = tmp_path / "before_sim_time.mcap"
    _real_time_copy(old, 200_000_000, lambda at: at, wall=0)
    r = check(old)
    assert r.ok and r.max_deviation == 0.0 and r.compared == 200


def test_intervals_that_share_a_stamp_end_at_their_own_sim_times(tmp_path):
    """A real-time node running ahead of its clock (real_time_factor > 1) restarts its stamps from the clock when it
    resumes: they go back, and a stamp can end two intervals at two simulated times. Each interval's sim_time is
    the one logged after its own rachis/accel_applied, as its other messages are. Before, one table keyed by stamp
    kept the later: the intervals it shared were re-simulated to the later ends. Here: the shipped recording's first
    0.8 s (its berries swing from 0.55 s on), its last 0.2 s logged at the 0.2 s before's stamps."""
    path = tmp_path / "resumed.mcap"
    _real_time_copy(path, 800_000_000, lambda at: [], back=(600_000_000, 200_000_000))
    r = check(path)
    assert r.ok and r.max_deviation == 0.0 and r.compared == 800


def test_an_empty_file_and_a_damaged_end_magic_are_said_as_they_are(recordings, tmp_path):
    """An empty file was 'read up to the last complete record, which ends at byte 8' (of 0), and a file whose last
    bytes, its end magic, were damaged was said to be damaged 'not at the end of the file' (found by an audit)."""
    empty = tmp_path / "empty.mcap"
    empty.write_bytes(b"")
    with pytest.raises(GrapefmuError, match="ends abruptly at byte 0, .*; no record in it"):
        check(empty)
    data = bytearray(recordings["cli"].read_bytes())
    data[-3] ^= 0x10
    damaged = tmp_path / "magic.mcap"
    damaged.write_bytes(bytes(data))
    with pytest.raises(CorruptRecording, match=r"corrupted \(its end magic is damaged\)"):
        check(damaged)


@pytest.mark.parametrize("bad_first", [True, False])
def test_a_second_joint_state_at_a_stamp_is_compared_too(recordings, tmp_path, capsys, bad_first):
    """Recorded states were keyed by their stamp, so of two at one stamp the first was dropped unread: a state 0.5 rad
    off written before the true one passed (51 compared, deviation 0; found by rewriting a recording with a copy)."""
    def twice(topic, t, m):
        if topic == absolute("joint_states") and t == 20_000_000:
            bad = moved(m, 0.5)
            return (bad, m) if bad_first else (m, bad)
    path = tmp_path / "twice.mcap"
    rewrite(recordings["chunked"], path, twice)
    r = check(path)
    assert not r.ok and r.unmatched == 1 and r.max_deviation == pytest.approx(0.5 if bad_first else 0.0)
    rc, out = replay(path, capsys)
    assert rc == 1 and "t = 0.020000 s" in out


def test_joint_states_naming_other_joints_are_refused(recordings, tmp_path, capsys):
    """The joint names were not read: a recording whose joint_states named its two angles the other way round (a
    viewer shows each at the other twig) passed with deviation 0 (found by rewriting a recording with rosbags' reader
    and the typestore)."""
    def swap(topic, t, m):
        if topic == absolute("joint_states"):
            m.name = list(reversed(m.name))
    path = tmp_path / "swapped.mcap"
    rewrite(recordings["chunked"], path, swap)
    with pytest.raises(RecordingError, match="names the joints .* the recorded scene's are"):
        check(path)
    rc, out = replay(path, capsys)
    assert rc == 2 and len(out.strip().splitlines()) == 1 and "joint_states logged at 0.000000 s" in out


@pytest.mark.parametrize("drop, missing", [(lambda t: t % 2_000_000, 25), (lambda t: t > 0, 50)])
def test_a_whole_recording_without_some_joint_states_fails(recordings, tmp_path, capsys, drop, missing):
    """A whole (not truncated) recording is one joint state per re-simulated sample. One left with every other state,
    or with the first alone, passed (26 or 1 compared, deviation 0; found by rewriting a recording without them)."""
    path = tmp_path / "sparse.mcap"
    rewrite(recordings["chunked"], path,
            lambda topic, t, m: () if topic == absolute("joint_states") and drop(t) else None)
    r = check(path)
    assert not r.ok and r.missing == missing and r.first_missing == 0.001 and r.max_deviation == 0.0
    rc, out = replay(path, capsys)
    assert rc == 1 and f"{missing} re-simulated samples (the first at t = 0.001000 s) have no recorded" in out


def test_an_input_source_replay_does_not_know_is_refused_naming_it(recordings, tmp_path, capsys):
    """Any input_source but "scene" was taken for a node recording: a simulate recording whose metadata said
    "scenee" failed with "no recorded joint state matches a re-simulated time", naming neither field nor value."""
    path = tmp_path / "source.mcap"
    rewrite(recordings["chunked"], path, lambda *_: None,
            meta_change=lambda meta: meta.update(input_source="scenee") if "input_source" in meta else None)
    rc, out = replay(path, capsys)
    assert rc == 2 and out.strip().endswith(f"{path}: the recorded input_source 'scenee' is neither 'scene' "
                                            f"(grapefmu simulate) nor 'applied' (the ROS node)")


def test_a_corrupted_recording_is_not_republished(recordings, tmp_path, capsys, monkeypatch):
    """`replay --publish` streamed the file without CRCs: a recording with a bit flipped in a chunk went out without
    that chunk's messages (300 of 316), exit 0 and no warning. It is now read as --check reads it first."""
    import grapefmu.cli as cli
    published = []
    monkeypatch.setattr(cli, "face", lambda *_: lambda path, rate: published.append(path) or 0)
    data = bytearray(recordings["chunked"].read_bytes())
    with open(recordings["chunked"], "rb") as fh:
        chunk = make_reader(fh).get_summary().chunk_indexes[3]
    data[chunk.chunk_start_offset + chunk.chunk_length - 10] ^= 0x10
    path = tmp_path / "flipped.mcap"
    path.write_bytes(bytes(data))
    assert main(["replay", str(path), "--publish"]) == 2 and not published
    assert f"chunk at byte {chunk.chunk_start_offset}" in capsys.readouterr().err
    assert main(["replay", str(recordings["chunked"]), "--publish"]) == 0 and published == [str(recordings["chunked"])]


def _node_copy(path: Path, change) -> None:
    """recordings/open_loop.mcap (the lockstep node's: two states at t = 0, the start's and the answer to the first
    input, then accel_applied, sim_time and joint_states per 1 ms interval) rewritten (`rewrite`'s change)."""
    rewrite(Path(__file__).parents[1] / "recordings" / "open_loop.mcap", path, change, chunk_size=1 << 16)


def moved(m, by: float):
    """A copy of joint state m with every angle moved by `by` rad."""
    bad = deserialize(serialize(m), m.__msgtype__)
    bad.position = bad.position + by
    return bad


def test_an_unchanged_copy_of_a_node_recording_passes(tmp_path):
    path = tmp_path / "copy.mcap"
    _node_copy(path, lambda *_: None)
    r = check(path)
    assert r.ok and r.compared == 2000 and r.max_deviation == 0.0 and r.unmatched == r.missing == 0


@pytest.mark.parametrize("stamp", [0, 1_000_000_000])
def test_a_second_state_at_a_node_recordings_stamp_is_compared_too(tmp_path, capsys, stamp):
    """The node publishes a state again at its stamp (its start's, the answer to a lockstep input at the current
    time), so replay compared the first state after each interval's accel_applied and skipped the others: a copy
    0.5 rad off written after the true one passed (2000 compared, deviation 0; found by an audit rewriting
    recordings/open_loop.mcap). Every state is compared with the re-simulation's at its place in the file, those at
    the start with the initial state."""
    def twice(topic, t, m):
        if topic == absolute("joint_states") and t == stamp:
            return m, moved(m, 0.5)
    path = tmp_path / "twice.mcap"
    _node_copy(path, twice)
    r = check(path)
    assert not r.ok and r.compared == 2000 and r.max_angle_deviation == pytest.approx(0.5)
    assert r.worst_time == stamp / 1e9
    rc, out = replay(path, capsys)
    assert rc == 1 and f"at t = {stamp / 1e9:.6f} s" in out


def test_a_node_recordings_state_at_another_stamp_than_its_interval_fails(tmp_path, capsys):
    """A state whose interval's accel_applied (and sim_time) was lost follows the interval before, at another stamp,
    and was skipped there: the next interval, re-simulated over both with its input, stayed within the tolerance
    (ok, 1999 compared, deviation 2e-15; found by an audit dropping one rachis/accel_applied of
    recordings/open_loop.mcap). A state at another stamp than its interval's is no sample's."""
    lost = (absolute("rachis/accel_applied"), absolute("sim_time"))
    path = tmp_path / "lost.mcap"
    _node_copy(path, lambda topic, t, m: () if topic in lost and t == 1_000_000_000 else None)
    r = check(path)
    assert not r.ok and r.unmatched == 1 and r.first_unmatched == 1.0 and r.compared == 1999
    rc, out = replay(path, capsys)
    assert rc == 1 and "1 recorded joint states (the first at t = 1.000000 s)" in out


@pytest.mark.parametrize("kept, missing", [(lambda t: t % 10_000_000 == 0, 1800), (lambda t: t != 1_000_000_000, 1)])
def test_a_whole_node_recording_without_some_joint_states_fails(tmp_path, capsys, kept, missing):
    """The node publishes a state after every interval; an interval without one was passed over: a copy of
    recordings/open_loop.mcap with one state in ten passed (ok, 200 compared; found by an audit). In a whole file
    an interval without its state is missing (a cut file lacks those after its last state alone)."""
    path = tmp_path / "sparse.mcap"
    _node_copy(path, lambda topic, t, m: () if topic == absolute("joint_states") and not kept(t) else None)
    r = check(path)
    assert not r.ok and r.missing == missing and r.compared == 2000 - missing and r.max_deviation == 0.0
    rc, out = replay(path, capsys)
    assert rc == 1 and f"{missing} re-simulated samples (the first at t = " in out


@pytest.mark.parametrize("lost", [("rachis/accel_applied",), ("rachis/accel_applied", "joint_states")])
def test_a_node_recordings_sim_time_without_its_interval_is_refused(tmp_path, capsys, lost):
    """A sim_time that follows no accel_applied at its stamp was passed over: with an interval's accel_applied and
    state lost, the next interval was re-simulated over both with its own input, within the tolerance (ok, 1999
    compared; found by dropping them from recordings/open_loop.mcap). Only a start's sim_time (0) ends no interval."""
    lost = {absolute(topic) for topic in lost}
    path = tmp_path / "lost.mcap"
    _node_copy(path, lambda topic, t, m: () if topic in lost and t == 1_000_000_000 else None)
    with pytest.raises(RecordingError, match=r"sim_time logged at 1\.000000 s does not follow a rachis/accel_applied"):
        check(path)
    rc, out = replay(path, capsys)
    assert rc == 2 and len(out.strip().splitlines()) == 1

"""Read a grapefmu MCAP recording back and re-simulate it (`grapefmu replay run.mcap --check`).

A recording from `grapefmu simulate` is re-simulated from the scene and solver settings in its metadata;
one from the ROS node is re-simulated from `rachis/accel_applied`, the exact intervals and held
accelerations (linear and angular) the node integrated, with the angular velocity it set at an interval's start
from `rachis/twist_applied`. Either way the recorded joint states are compared with the new run,
and a deviation above TOLERANCE fails the check.

Reading tells two kinds of damage apart (`read_recording`):
- truncated: the writer was killed, so the file ends inside a record and has no summary, footer or end
  magic. Everything up to the last complete chunk is read (and CRC-checked) and the check goes on with it.
- corrupted: a chunk whose CRC (mcap's `validate_crcs`) or decompression fails, a data section or summary
  section whose CRC fails, a record the mcap reader cannot parse anywhere but at a torn end, a message that
  does not decode, counts that disagree with the Statistics record. Reading stops with CorruptRecording,
  one line naming the record (byte offset, topic, log time)."""
from __future__ import annotations

import bisect
import io
import json
import math
import mmap
import os
import struct
import zlib
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from ..errors import GrapefmuError, RecordingError
from ..model.model import INTEGRATORS, ISLANDS_FROM
from ..scenefile import parse_scene
from .messages import NAMESPACE, joint_names, relative
from .stamps import seconds, stamp_seconds, to_ns


@dataclass
class Recording:
    path: Path
    metadata: dict[str, str]
    topics: dict[str, list] = field(default_factory=dict)  # topic -> [(log_time_ns, decoded message)]
    #: topic -> where each of its messages is among all those read (their order in the file, across topics)
    positions: dict[str, list[int]] = field(default_factory=dict)
    truncated: str | None = None
    count: int = 0

    @property
    def last_time(self) -> float:
        return max((m[-1][0] for m in self.topics.values() if m), default=0) / 1e9


def iter_messages(fh, on_metadata=None):
    """(schema, channel, message record) for every message, streamed record by record, so a file with a
    torn end yields every complete chunk before the reader raises at the tear."""
    from mcap.records import Channel, Message, Metadata, Schema
    from mcap.stream_reader import StreamReader

    schemas, channels = {}, {}
    for r in StreamReader(fh).records:
        if isinstance(r, Schema):
            schemas[r.id] = r
        elif isinstance(r, Channel):
            channels[r.id] = r
        elif isinstance(r, Metadata) and on_metadata:
            on_metadata(r)
        elif isinstance(r, Message):
            ch = channels[r.channel_id]
            yield schemas[ch.schema_id], ch, r


class CorruptRecording(RecordingError):
    """A recording whose bytes are damaged (not merely cut short): a CRC mismatch, an unparsable record, a
    message that does not decode. The message names the record."""


#: The MCAP magic that opens and closes a complete file.
MAGIC = b"\x89MCAP0\r\n"


def _t(ns: int) -> str:
    return f"{seconds(ns):.6f} s"


def read_recording(path: str | Path, topics: set[str] | None = None) -> Recording:
    """Every message (of the given topics), decoded through the typestore that wrote it. Every message of
    every topic is decoded, so an undecodable one is found wherever it is. A truncated file is read up to
    its last complete chunk (`Recording.truncated` says so); a corrupted one raises CorruptRecording."""
    path = Path(path)
    if not path.exists():
        raise RecordingError(f"{path}: no such recording")
    if path.is_dir():
        raise RecordingError(f"{path}: is a directory, not an MCAP recording")
    rec = Recording(path, {})
    try:
        with open(path, "rb") as fh:
            size = os.fstat(fh.fileno()).st_size
            # mapped, so that a length field damaged into gigabytes reads what the file has instead of
            # allocating what the field claims (mmap's read stops at the end)
            mapped = mmap.mmap(fh.fileno(), 0, access=mmap.ACCESS_READ) if size else io.BytesIO()
            with mapped as m:
                _scan(path, m, size, rec, topics)
    except OSError as e:
        raise RecordingError(f"{path}: cannot read: {e.strerror or e}") from None
    if "scene_toml" not in rec.metadata:
        if rec.truncated:
            raise RecordingError(f"{rec.truncated}; the grapefmu metadata record (scene and solver settings) is not "
                                 f"in what remains, nothing to check")
        raise RecordingError(f"{path}: no grapefmu metadata record (scene and solver settings); "
                             f"not a grapefmu recording")
    return rec


def _scan(path: Path, fh, size: int, rec: Recording, topics: set[str] | None) -> None:
    """Stream the file record by record through mcap's StreamReader with CRC validation (chunks are broken
    up here, so a failing chunk is known by its offset), classify a failure as truncation or corruption,
    and check the summary CRC (which mcap's readers do not) and the Statistics of a complete file.

    A record cut short by the end of the file makes mcap raise EndOfFile, a short struct read or a string
    cut inside a UTF-8 sequence. One of these when every byte has been read and the file lacks its end magic
    is a truncation; any failure elsewhere, or in a file that has its end magic, is corruption."""
    from mcap.exceptions import EndOfFile
    from mcap.records import Channel, Chunk, DataEnd, Footer, Message, Metadata, Schema, Statistics
    from mcap.stream_reader import CRCValidationError, StreamReader, breakup_chunk

    from .typestore import deserialize

    if size >= 2 * len(MAGIC):
        fh.seek(size - len(MAGIC))
        complete = fh.read(len(MAGIC)) == MAGIC
        fh.seek(0)
    else:
        complete = False
    schemas, channels = {}, {}
    counts = {"chunks": 0, "messages": 0, "last": 0}
    stats = footer = None
    at = len(MAGIC)  # byte offset of the record being read (after the last one the reader handed over)

    def message(r: Message, where: str) -> None:
        ch = channels.get(r.channel_id)
        if ch is None or ch.schema_id not in schemas:
            raise CorruptRecording(f"{path}: {where}: a message logged at {_t(r.log_time)} names channel "
                                   f"{r.channel_id}, which the file never defines (corrupted)")
        try:
            typename = schemas[ch.schema_id].name
            decoded = deserialize(r.data, typename)
        except Exception as e:  # noqa: BLE001 - rosbags raises several types on bad CDR
            raise CorruptRecording(f"{path}: {where}: the message on topic {ch.topic!r} logged at {_t(r.log_time)} "
                                   f"does not decode as {typename} ({type(e).__name__}: {e})") from None
        counts["messages"] += 1
        counts["last"] = max(counts["last"], r.log_time)
        name = relative(ch.topic, rec.metadata.get("namespace", NAMESPACE))  # recorded under the node's namespace
        if topics is None or name in topics:
            rec.topics.setdefault(name, []).append((r.log_time, decoded))
            rec.positions.setdefault(name, []).append(rec.count)
            rec.count += 1

    def inner(r, where: str) -> None:
        if isinstance(r, Schema):
            schemas[r.id] = r
        elif isinstance(r, Channel):
            channels[r.id] = r
        elif isinstance(r, Message):
            message(r, where)

    reader = StreamReader(fh, emit_chunks=True, validate_crcs=True)
    try:
        for r in reader.records:
            start, at = at, fh.tell()
            if isinstance(r, Chunk):
                where = (f"chunk at byte {start} (messages logged {_t(r.message_start_time)} to "
                         f"{_t(r.message_end_time)})")
                try:
                    records = breakup_chunk(r, validate_crc=True)
                except CRCValidationError as e:
                    raise CorruptRecording(f"{path}: {where}: CRC mismatch (stored {e.expected:#010x}, "
                                           f"computed {e.actual:#010x}); the file is corrupted") from None
                except Exception as e:  # noqa: BLE001 - zstd, struct and mcap errors on garbage
                    raise CorruptRecording(f"{path}: {where}: cannot be unpacked ({type(e).__name__}: {e}); "
                                           f"the file is corrupted") from None
                counts["chunks"] += 1
                for x in records:
                    inner(x, where)
            elif isinstance(r, Metadata):
                if r.name == "grapefmu":
                    rec.metadata.update(r.metadata)
            elif isinstance(r, Statistics):
                stats = r
            elif isinstance(r, Footer):
                footer = (r, start)
            elif not isinstance(r, DataEnd):
                inner(r, f"record at byte {start}")
    except CorruptRecording:
        raise
    except CRCValidationError as e:  # the DataEnd record's data section CRC
        raise CorruptRecording(f"{path}: the data section (up to the DataEnd record at byte {at}) fails its CRC "
                               f"(stored {e.expected:#010x}, computed {e.actual:#010x}); corrupted") from None
    except Exception as e:  # noqa: BLE001 - mcap raises many types on a torn end or garbage: classified here
        if not complete and fh.tell() >= size and isinstance(e, (EndOfFile, struct.error, UnicodeDecodeError)):
            got = (f"read up to the last complete record, which ends at byte {at}: {counts['messages']} messages, "
                   f"logged up to {_t(counts['last'])}") if at < size else "no record in it"
            rec.truncated = (f"{path} ends abruptly at byte {size}, without summary and footer (truncated: the writer "
                             f"did not finish it, probably killed); {got}")
            return
        why = ("the file has its end magic, so it is not merely cut short" if complete else
               "its end magic is damaged" if at + 8 >= size else
               "it is not at the end of the file, where a killed writer would leave a torn record")
        raise CorruptRecording(f"{path}: the record at byte {at} cannot be read ({type(e).__name__}: {e}); "
                               f"corrupted ({why})") from None
    if fh.tell() != size:
        raise CorruptRecording(f"{path}: {size - fh.tell()} bytes follow the end magic at byte {fh.tell()}; corrupted")
    f, f_at = footer
    if f.summary_crc:
        start = f.summary_start or f_at
        if not 0 < start <= f_at:
            raise CorruptRecording(f"{path}: the footer at byte {f_at} puts the summary at byte {f.summary_start}, "
                                   f"outside the file; corrupted")
        fh.seek(start)
        crc = zlib.crc32(fh.read(f_at + 25 - start))  # summary section + footer up to its CRC field
        if crc != f.summary_crc:
            raise CorruptRecording(f"{path}: the summary section (bytes {start} to {f_at + 25}) fails its CRC "
                                   f"(stored {f.summary_crc:#010x}, computed {crc:#010x}); corrupted")
    if stats is not None and (stats.message_count, stats.chunk_count) != (counts["messages"], counts["chunks"]):
        raise CorruptRecording(f"{path}: {counts['messages']} messages in {counts['chunks']} chunks read, the "
                               f"Statistics record says {stats.message_count} in {stats.chunk_count}; corrupted")


#: The largest deviation (rad and rad/s) a re-simulation may show from the recorded joint states. A replay
#: on the same build is bit for bit (deviation 0); 1e-6 leaves room for another CPU's or library's last-bit
#: rounding growing over a run, and is far below anything physical (a berry's angle is read to ~1e-3 rad).
TOLERANCE = 1e-6


@dataclass
class CheckResult:
    #: re-simulated samples (simulate's output times, the node's intervals) whose recorded joint state was compared;
    #: a node's other states (its starts', repeats at a stamp) are compared too, not counted
    compared: int
    max_angle_deviation: float
    max_rate_deviation: float
    source: str
    truncated: str | None
    worst_time: float = math.nan   # s, the recorded time of the largest deviation
    tolerance: float = TOLERANCE
    #: recorded joint states the re-simulation has no sample at (settings that do not describe the recorded run, a
    #: second state at one stamp; in a node's, a state at another stamp than the interval it follows), and the time of
    #: the first
    unmatched: int = 0
    first_unmatched: float = math.nan
    #: re-simulated samples (a node's intervals) the recording has no joint state at (up to its last one if it is
    #: truncated), and the time of the first
    missing: int = 0
    first_missing: float = math.nan

    @property
    def max_deviation(self) -> float:
        return max(self.max_angle_deviation, self.max_rate_deviation)

    @property
    def ok(self) -> bool:
        """Every recorded joint state compared, one for every re-simulated sample, and within the tolerance (NaN
        counts as a deviation)."""
        return self.max_deviation <= self.tolerance and not self.unmatched and not self.missing


def _deviation(a: np.ndarray, b: np.ndarray) -> float:
    """Largest |a − b|; NaN or infinite anywhere is an infinite deviation."""
    d = np.abs(np.asarray(a, dtype=float) - np.asarray(b, dtype=float))
    return float(d.max(initial=0.0)) if np.isfinite(d).all() else math.inf


def _islands_from(cfg: dict) -> float:
    """The berries from which the recorded run went in islands under `solver.islands = "auto"` (recordings made
    before that setting: never)."""
    v = cfg.get("islands_from")
    return float(v) if isinstance(v, (int, float)) and not isinstance(v, bool) else math.inf


#: until recordings named the pair they were stepped with (2026-11-29), every event run stepped with DOP853 below
#: this rtol and with DOPRI5 from it on (solver.integrator_for's rule of that day)
DOP853_BELOW_UNNAMED = 1e-7


def _pinned(scene, cfg: dict, method: str | None):
    """The scene with the pair its recording was stepped with pinned (solver.integrator), where the scene leaves it to
    the rule: the one the recording names, or, for a recording that names none, the one the rule of its day chose
    (DOP853_BELOW_UNNAMED). Re-simulated with another pair, a run agrees to its tolerance, not to the bit. A
    recording of groups stepped by different pairs ("mixed") runs under today's rule."""
    s = scene.solver
    if s.integrator != "auto" or s.method != "event" or method not in (None, "event") or s.fixed_step > 0.0:
        return scene  # the scene's own pin, or a method or fixed step no pair is pinned for (SolverSettings.refusal)
    named = cfg.get("integrator")
    if named is None:
        named = "DOP853" if cfg.get("rtol", s.rtol) < DOP853_BELOW_UNNAMED else "DOPRI5"
    if named not in INTEGRATORS or named == "auto":
        return scene
    return replace(scene, solver=replace(s, integrator=named))


#: the methods a recording may name (recordings before 2026-11-30 named the reference "reference (DOP853)")
METHODS = ("event", "paper", "reference")


def _settings(path: Path, rec: Recording):
    """The scene, solver settings and method (None: the scene's) a recording was made with, or a RecordingError saying
    why not."""
    method = rec.metadata.get("method")
    if method is not None and method.startswith("reference ("):
        method = "reference"
    if method is not None and method not in METHODS:
        raise RecordingError(f"{path}: the recorded method {method!r} is none of {', '.join(METHODS)}")
    try:
        scene = parse_scene(rec.metadata["scene_toml"], name=rec.metadata.get("scene_name", "scene"))
        cfg = json.loads(rec.metadata.get("solver", "{}"))
        if not isinstance(cfg, dict):
            raise ValueError("the solver settings are not a table")
        for key in ("t_end", "rtol", "atol", "output_interval"):
            v = cfg.get(key)
            if v is not None and not (isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)
                                      and v > 0):
                raise ValueError(f"solver setting {key} = {v!r} is not a positive number")
    except GrapefmuError as e:
        raise RecordingError(f"{path}: the recorded scene is not valid: {e}") from None
    except ValueError as e:  # json.JSONDecodeError included
        raise RecordingError(f"{path}: the recorded solver settings are not valid: {e}") from None
    return scene, cfg, method


def _by_interval(rec: Recording, topic: str, applied: list, at: list[int]) -> tuple[dict[int, object], int | None]:
    """What the node wrote about interval k (its `rachis/accel_applied` is applied[k], at position at[k] in the
    file) on `topic`: the first such message after that accel_applied, before the next one, at the same stamp
    (stamps alone repeat after a lockstep reset, and go back when a real-time node resumes ahead of its clock). For
    twist_applied, the angular velocity set at the interval's start; for sim_time, where it ended. Also the stamp
    of a message that follows no interval (or None)."""
    out, stray = {}, None
    for pos, (ns, m) in zip(rec.positions.get(topic, []), rec.topics.get(topic, [])):
        k = bisect.bisect_left(at, pos) - 1
        if k >= 0 and applied[k][0] == ns:
            if k not in out:
                out[k] = m.twist.angular if topic == "rachis/twist_applied" else m
        elif stray is None:
            stray = ns
    return out, stray


class _Tally:
    """What a check has compared so far: the largest deviations and where the worst was, the re-simulated samples
    compared (`n`), and the recorded states no sample matched and the samples no recorded state did."""

    def __init__(self) -> None:
        self.n = 0
        self.dq = self.dw = 0.0
        self.worst, self.worst_t = -1.0, math.nan
        self.unmatched, self.first_unmatched = 0, math.nan
        self.missing, self.first_missing = 0, math.nan

    def compare(self, ns: int, q, w, angles, rates) -> None:
        """The recorded state (q, w) logged at ns against the re-simulated (angles, rates)."""
        a, b = _deviation(angles, q), _deviation(rates, w)
        self.dq, self.dw = max(self.dq, a), max(self.dw, b)
        if max(a, b) > self.worst:
            self.worst, self.worst_t = max(a, b), seconds(ns)

    def no_sample(self, t: float) -> None:
        """A recorded state at t (s) that no re-simulated sample matches."""
        self.first_unmatched = t if not self.unmatched else self.first_unmatched
        self.unmatched += 1

    def no_state(self, t: float) -> None:
        """A re-simulated sample at t (s) that the recording has no state for."""
        self.first_missing = t if not self.missing else self.first_missing
        self.missing += 1

    def result(self, source: str, truncated: str | None, tolerance: float) -> CheckResult:
        return CheckResult(self.n, self.dq, self.dw, source, truncated, self.worst_t, tolerance, self.unmatched,
                           self.first_unmatched, self.missing, self.first_missing)


def _joint_states(path: Path, rec: Recording, model) -> list[tuple[int, np.ndarray, np.ndarray]]:
    """Every recorded joint state as (logged at = its header's stamp in ns, angles, rates), in the file's order;
    a RecordingError for one that is not the recorded scene's."""
    n_dof, joints = model.n_dof, joint_names(model)
    states = []
    for ns, m in rec.topics.get("joint_states", []):
        q, w = np.array(m.position, dtype=float), np.array(m.velocity, dtype=float)
        if q.shape != (n_dof,) or w.shape != (n_dof,):
            raise RecordingError(f"{path}: joint_states logged at {_t(ns)} has {q.size} positions and {w.size} "
                                 f"velocities, the recorded scene has {n_dof} angles")
        if list(m.name) != joints:  # a viewer places each value at the joint its name says
            raise RecordingError(f"{path}: joint_states logged at {_t(ns)} names the joints {list(m.name)}, the "
                                 f"recorded scene's are {joints}")
        states.append((ns, q, w))
    if not states:
        raise RecordingError(f"{path}: no joint_states to compare")
    return states


def check(path: str | Path, tolerance: float = TOLERANCE) -> CheckResult:
    """Re-simulate a recording and compare its joint states. A truncated file is checked up to its last
    complete chunk; a corrupted one raises CorruptRecording; `CheckResult.ok` says whether every deviation
    is within `tolerance`."""
    path = Path(path)
    rec = read_recording(path, {"joint_states", "rachis/accel_applied", "rachis/twist_applied", "sim_time"})
    scene, solver_cfg, method = _settings(path, rec)
    states = _joint_states(path, rec, scene.model)
    source = rec.metadata.get("input_source", "scene")
    if source not in ("scene", "applied"):  # simulate's and the node's (recorder.metadata)
        raise RecordingError(f"{path}: the recorded input_source {source!r} is neither 'scene' (grapefmu simulate) "
                             f"nor 'applied' (the ROS node)")
    scene = _pinned(scene, solver_cfg, method)
    tally = _Tally()
    if source == "scene":
        _check_run(rec, scene, solver_cfg, method, states, tally)
    else:
        _check_node(path, rec, scene, states, tally)
    if tally.n == 0:
        raise RecordingError(f"{path}: no recorded joint state matches a re-simulated time")
    return tally.result(source, rec.truncated, tolerance)


def _check_run(rec: Recording, scene, solver_cfg: dict, method: str | None, states: list, tally: _Tally) -> None:
    """A recording of `grapefmu simulate`: the scene run again with its settings, each output sample against the
    recorded state at its time."""
    from ..solver.api import simulate
    if scene.solver.islands == "auto" and _islands_from(solver_cfg) != ISLANDS_FROM:
        # run under another "auto" rule (none before it existed: one step size), as that rule chose
        islands = scene.model.n_berries >= _islands_from(solver_cfg)
        scene = replace(scene, solver=replace(scene.solver, islands=islands))
    run = simulate(scene, solver_cfg.get("t_end"), method=method, rtol=solver_cfg.get("rtol"),
                   atol=solver_cfg.get("atol"), output_interval=solver_cfg.get("output_interval"), cross_check=False)
    recorded: dict[int, list] = {}  # every state at a stamp, in the file's order: a second one is no sample's
    for ns, q, w in states:
        recorded.setdefault(ns, []).append((q, w))
    last = max(recorded) if rec.truncated else math.inf  # a truncated file lacks the samples after its last
    for k, t in enumerate(run.t):
        if at_key := recorded.get(to_ns(t)):
            tally.compare(to_ns(t), *at_key.pop(0), run.angles[k], run.angular_velocities[k])
            tally.n += 1
        elif to_ns(t) <= last:  # states left out of a whole file, or a longer t_end or a finer grid than the run's
            tally.no_state(float(t))
    for ns in sorted(ns for ns, v in recorded.items() for _ in v):  # a shorter t_end or a coarser grid than the run's
        tally.no_sample(seconds(ns))


def _check_node(path: Path, rec: Recording, scene, states: list, tally: _Tally) -> None:
    """A recording of the ROS node: its solver driven again through the recorded intervals (rachis/accel_applied,
    ending at their sim_time, the angular velocity set by twist_applied), each state the node published against
    its solver's at that place in the file."""
    from ..solver.solver import Solver
    # the node's solver is driven by its inputs (metadata "turning"). Recordings before it could say so had no turns:
    # their solver carried the rachis' translation alone, as Solver(scene) does for a scene that moves it; one that
    # holds it still needs a driven solver to take the recorded accelerations
    driven = rec.metadata.get("turning") == "true" or not scene.excitation.moves
    solver = Solver(scene, driven=driven)
    initial = solver.angles.copy(), solver.angular_velocities.copy()
    applied, at = rec.topics.get("rachis/accel_applied", []), rec.positions.get("rachis/accel_applied", [])
    starts, start_stamps = _starts(rec)
    ends = _ends(path, rec, applied, at)
    omega, stray = _by_interval(rec, "rachis/twist_applied", applied, at)
    if stray is not None:
        raise RecordingError(f"{path}: rachis/twist_applied logged at {_t(stray)} does not follow the "
                             f"rachis/accel_applied of its interval")
    segments = _segments(rec, states, at, starts)

    def compare_segment(key, stamp: int | None, angles, rates) -> int:
        """Compare the states recorded at `key` and `stamp` (None: the first one's) with (angles, rates); how many
        were. One at another stamp is no sample's (the accel_applied of its own interval lost, say)."""
        found = 0
        for ns, q, w in segments.pop(key, []):
            stamp = ns if stamp is None else stamp
            if ns == stamp:
                tally.compare(ns, q, w, angles, rates)
                found += 1
            else:
                tally.no_sample(seconds(ns))
        return found

    clocked = "sim_time" in rec.topics  # recordings before the node logged sim_time end an interval at its stamp
    if clocked and rec.truncated and applied and len(applied) - 1 not in ends:
        # cut between the last interval's accel_applied and its sim_time: where it ends is lost (in real time its
        # stamp is the wall clock's, not an end), so it is not re-simulated
        applied = applied[:-1]
    for k, (ns, m) in enumerate(applied):
        if clocked and k not in ends:
            raise RecordingError(f"{path}: the interval whose rachis/accel_applied is logged at {_t(ns)} has no "
                                 f"sim_time at its stamp, so where it ends is not known")
        t_end = seconds(ends[k] if clocked else ns)
        restarted = bisect.bisect_left(starts, at[k]) > bisect.bisect_left(starts, at[k - 1]) if k else False
        if restarted or t_end < solver.t:  # the node was reset (older recordings: its time went back)
            solver = Solver(scene, driven=driven)
        a, w = m.accel.linear, m.accel.angular
        set_omega = omega.get(k)
        solver.advance(t_end - solver.t, (a.x, a.y, a.z, w.x, w.y, w.z),
                       None if set_omega is None else (set_omega.x, set_omega.y, set_omega.z))
        if compare_segment(("interval", k), ns, solver.angles, solver.angular_velocities):
            tally.n += 1
        elif not rec.truncated or at[k] < rec.positions["joint_states"][-1]:  # a cut one lacks those after its last
            tally.no_state(seconds(ns))
    for kind, j in [key for key in segments if key[0] == "start"]:  # compared, not counted: no re-simulated sample
        compare_segment((kind, j), start_stamps[j] if j >= 0 else None, *initial)


def _starts(rec: Recording) -> tuple[list[int], list[int]]:
    """The node's (re)starts, a sim_time of 0 (which no interval ends at; recordings before it had none): their
    positions in the file and their stamps. A start's stamp may be an interval's (a reset before the clock moved),
    so it is left out of the intervals' ends (_ends)."""
    starts = [(pos, ns) for pos, (ns, m) in zip(rec.positions.get("sim_time", []), rec.topics.get("sim_time", []))
              if m.clock.sec == 0 and m.clock.nanosec == 0]
    return [pos for pos, _ in starts], [ns for _, ns in starts]


def _ends(path: Path, rec: Recording, applied: list, at: list[int]) -> dict[int, int]:
    """Where each applied interval ends in simulated time (ns): its `sim_time`, logged at the same stamp (its header
    is the ROS clock). Matched by position, as the interval's other messages: a stamp may end two intervals at two
    simulated times. A sim_time that ends none (its accel_applied lost) is refused: its interval would be
    re-simulated into the next one's."""
    ends = {}
    for pos, (ns, m) in zip(rec.positions.get("sim_time", []), rec.topics.get("sim_time", [])):
        if m.clock.sec == 0 and m.clock.nanosec == 0:
            continue  # a (re)start (_starts)
        k = bisect.bisect_left(at, pos) - 1
        if k < 0 or applied[k][0] != ns or k in ends:
            raise RecordingError(f"{path}: sim_time logged at {_t(ns)} does not follow a rachis/accel_applied at "
                                 f"its stamp (or follows one that has its sim_time)")
        ends[k] = to_ns(stamp_seconds(m.clock.sec, m.clock.nanosec))
    return ends


def _segments(rec: Recording, states: list, at: list[int], starts: list[int]) -> dict[tuple[str, int], list]:
    """The recorded states by where they sit in the file. Every state the node published is its solver's at that
    place: the one an interval reached, at its stamp after its accel_applied (again for a lockstep input at the
    current time); after a (re)start, or before the first interval, the initial state at the start's stamp. Keyed
    ("interval", k), or ("start", j) (j = -1: the first start, in recordings without its sim_time 0)."""
    segments: dict[tuple[str, int], list] = {}
    for pos, state in zip(rec.positions["joint_states"], states):
        k, j = bisect.bisect_left(at, pos) - 1, bisect.bisect_left(starts, pos) - 1
        segments.setdefault(("interval", k) if k >= 0 and (j < 0 or at[k] > starts[j]) else ("start", j),
                            []).append(state)
    return segments

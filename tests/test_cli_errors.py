"""No user error ends in a traceback (issue 16, items 3 and 6).

Every error a user can cause on any `grapefmu` command is one line on stderr,
`grapefmu <command>: <input>: <what is allowed>`, with exit code 2 (bad input) or 1 (failure); outputs that
cannot be written are refused before the run; values that together would exhaust memory are refused up front
with the estimate; an interrupted writer leaves no temporary file and the next writer removes a killed one's.
The fuzz (hypothesis, derandomized, bounded example counts) mutates the default scene as a document and as
bytes, and the command line.
"""
from __future__ import annotations

import copy
import math
import os
import signal
import subprocess
import sys
import time
import tomllib
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from grapefmu.errors import GrapefmuError, SceneError
from grapefmu.scenefile import default_scene_path, load_scene, parse_scene, scene_from_dict

DEFAULT = str(default_scene_path())
DEFAULT_TEXT = default_scene_path().read_text(encoding="utf-8")
DEFAULT_DOC = tomllib.loads(DEFAULT_TEXT)
FUZZ = settings(derandomize=True, deadline=None, database=None, print_blob=False,
                suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture,
                                       HealthCheck.data_too_large, HealthCheck.filter_too_much])
CLEAN_EXITS = {0, 1, 2}


def cli(*args: str, cwd: Path, timeout: float = 60) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "grapefmu", *args], cwd=cwd, capture_output=True, text=True,
                          timeout=timeout, env={**os.environ, "PYTHONWARNINGS": "ignore"})


def assert_one_line_error(r: subprocess.CompletedProcess, command: str, *words: str, code: int = 2) -> str:
    """The run failed with `code`, no traceback, and said why in one line naming the input."""
    assert "Traceback" not in r.stderr, r.stderr[-3000:]
    assert r.returncode == code, (r.returncode, r.stderr[-2000:])
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1, r.stderr
    assert lines[0].startswith(f"grapefmu {command}: "), lines[0]
    for w in words:
        assert w in lines[0], (w, lines[0])
    return lines[0]


def scene_file(tmp: Path, name: str, text: str | bytes) -> Path:
    p = tmp / name
    if isinstance(text, bytes):
        p.write_bytes(text)
    else:
        p.write_text(text, encoding="utf-8")
    return p


def with_solver(**values) -> str:
    doc = copy.deepcopy(DEFAULT_DOC)
    doc["solver"].update(values)
    from grapefmu.scenefile import dumps
    return dumps(doc)


# --- every defect found ------------------------------------------------------------------------------------

def test_integer_beyond_float_range_names_the_key(tmp_path):
    p = scene_file(tmp_path, "big.toml", DEFAULT_TEXT.replace("gravity = 9.81", "gravity = 1" + "0" * 400))
    assert_one_line_error(cli("simulate", str(p), "--t-end", "0.01", cwd=tmp_path), "simulate", "gravity", "[0, 100]")
    with pytest.raises(SceneError) as ei:  # and beyond Python's int-to-string limit, inside the TOML parser
        parse_scene(DEFAULT_TEXT.replace("gravity = 9.81", "gravity = 1" + "0" * 5000))
    assert "\n" not in str(ei.value)


def test_non_utf8_scene_names_the_file(tmp_path):
    p = scene_file(tmp_path, "latin1.toml", DEFAULT_TEXT.replace("Kyoho-like", "Kyōho").encode("latin-1", "replace")
                   + b"\n# caf\xe9\n")
    assert_one_line_error(cli("simulate", str(p), cwd=tmp_path), "simulate", "latin1.toml", "UTF-8")


@pytest.mark.parametrize("nest", ["a = " + "[" * 3000 + "]" * 3000, "a = " + "{b=" * 3000 + "1" + "}" * 3000])
def test_deeply_nested_toml_names_the_file(tmp_path, nest):
    p = scene_file(tmp_path, "deep.toml", nest + "\n")
    assert_one_line_error(cli("simulate", str(p), cwd=tmp_path), "simulate", "deep.toml", "nested too deeply")


@pytest.mark.parametrize("out, words", [
    ("{tmp}", ["--out", "unknown file type"]),                         # a directory
    ("{tmp}/adir.csv", ["--out", "is a directory"]),
    ("{tmp}/afile/x.csv", ["--out", "afile is a file, not a directory"]),
    ("/proc/grapefmu-no-such/x.csv", ["--out", "cannot write"]),       # unwritable even for root
    ("", ["--out ''", ".csv, .parquet or .mcap"]),                     # used to write nothing, silently
    ("{tmp}/x.xyz", ["--out", "unknown file type .xyz", ".csv, .parquet or .mcap"]),
    ("{tmp}/" + "n" * 250 + ".csv", ["--out", "file name too long"]),
])
def test_bad_out_is_refused_before_the_run(tmp_path, out, words):
    (tmp_path / "adir.csv").mkdir()
    (tmp_path / "afile").write_text("")
    start = time.monotonic()
    # a run of 1000 s takes minutes: a refusal within seconds shows the check comes before the run
    r = cli("simulate", "--t-end", "1000", "--out", out.format(tmp=tmp_path), cwd=tmp_path)
    assert time.monotonic() - start < 20
    assert_one_line_error(r, "simulate", *words)
    assert not list(tmp_path.glob(".*grapefmu-part"))


@pytest.mark.skipif(os.geteuid() == 0, reason="root writes through directory permissions")
def test_unwritable_directory_is_refused_before_the_run(tmp_path):
    ro = tmp_path / "ro"
    ro.mkdir()
    ro.chmod(0o555)
    try:
        assert_one_line_error(cli("simulate", "--t-end", "1000", "--out", str(ro / "x.csv"), cwd=tmp_path),
                              "simulate", "cannot write in directory")
    finally:
        ro.chmod(0o755)


@pytest.mark.parametrize("plot, words", [("x.xyz", ["--plot", ".png, .pdf or .svg"]), ("", ["--plot ''"]),
                                         (".", ["--plot"])])
def test_bad_plot_is_refused_before_the_run(tmp_path, plot, words):
    assert_one_line_error(cli("simulate", "--t-end", "1000", "--plot", plot, cwd=tmp_path), "simulate", *words)


@pytest.mark.parametrize("args, command, words", [
    (["replay", "missing.mcap", "--publish"], "replay", ["missing.mcap", "no such recording"]),
    (["replay", "missing.mcap", "--check"], "replay", ["missing.mcap"]),
    (["replay", "missing.mcap", "--publish", "--rate", "-1"], "replay", ["--rate", "-1"]),
    (["replay", "missing.mcap", "--publish", "--rate", "nan"], "replay", ["--rate", "nan"]),
    (["replay", "missing.mcap", "--publish", "--rate", "inf"], "replay", ["--rate", "inf"]),
    (["replay", "missing.mcap", "--publish", "--rate", "fast"], "replay", ["--rate", "invalid float"]),
    (["simulate", "--t-end", "-1"], "simulate", ["--t-end", "(0, 100000]"]),
    (["simulate", "--t-end", "1e400"], "simulate", ["--t-end"]),
    (["simulate", "--rtol", "nan"], "simulate", ["--rtol"]),
    (["simulate", "--method", "euler"], "simulate", ["--method", "invalid choice"]),
    (["simulate", "missing.toml"], "simulate", ["missing.toml", "No such file"]),
    (["simulate", "."], "simulate", ["cannot read scene file"]),
    (["cluster", "-o", "c.csv"], "cluster", ["--output c.csv", ".toml"]),
    (["cluster", "-o", "afile/c.toml"], "cluster", ["afile is a file"]),
    (["cluster", "--seed", "-1", "-o", "c.toml"], "cluster", ["seed"]),
    (["cluster", "--berries", "100000", "-o", "c.toml"], "cluster", ["berries", "[1, 1000]"]),
    (["cluster", "--row", "--pitch", "nan", "-o", "c.toml"], "cluster", ["pitch"]),
    (["cluster", "--seed", "-1", "-o", "c.toml"], "cluster", ["--seed: expected an integer in [0, 2**63)"]),
    (["cluster", "--row", "--precompression", "5", "-o", "c.toml"], "cluster",  # was ignored without a word
     ["--precompression: for a cluster, not with --row"]),
    (["cluster", "--pitch", "-1", "-o", "c.toml"], "cluster", ["--pitch: only with --row"]),
    (["cluster", "--hinge-stiffness", "1e-5", "0", "-o", "c.toml"], "cluster",  # named berries[0].rest_angles[1]
     ["--hinge-stiffness", "cannot hold its twig", "needs at least"]),
    (["sweep", "missing.toml"], "sweep", ["missing.toml"]),
    (["sweep", "latin1.toml"], "sweep", ["latin1.toml", "UTF-8"]),
    (["sweep", "spec.toml", "-o", "afile"], "sweep", ["--output afile", ".parquet"]),
    (["sweep", "spec.toml", "--workers", "0"], "sweep", ["--workers"]),
    (["build-fmu", "-o", "x.zip"], "build-fmu", ["--output x.zip", ".fmu"]),
    (["build-fmu", "-o", "afile/x.fmu"], "build-fmu", ["afile is a file"]),
    (["paper", "--out", "afile"], "paper", ["--out afile", "not a directory"]),
    (["bench", "--out", "report.txt"], "bench", ["--out report.txt", ".md"]),
    (["bench", "--plots", "afile"], "bench", ["--plots afile"]),
    (["fit", "missing.toml", "m.csv", "--param", "contact.stiffness", "-o", "f.toml"], "fit", ["missing.toml"]),
    (["fit", DEFAULT, "missing.csv", "--param", "contact.stiffness", "-o", "f.toml"], "fit",
     ["missing.csv", "cannot read"]),
    (["fit", DEFAULT, "m.csv", "--param", "gravity", "-o", "f.toml"], "fit", ["--param", "'gravity'", "allowed"]),
    (["fit", DEFAULT, "m.csv", "--param", "contact.stiffness", "-o", "f.csv"], "fit", ["--output f.csv", ".toml"]),
    (["fit", DEFAULT, "m.csv", "--param", "contact.stiffness", "--param", "contact.stiffness", "-o", "f.toml"], "fit",
     ["set the same value"]),
    (["risk", DEFAULT], "risk", ["--fit", "--range"]),
    (["risk", DEFAULT, "--range", "contact.stiffness=5"], "risk", ["--range", "KEY=LOW:HIGH"]),
    (["risk", DEFAULT, "--range", "contact.restitution=0.2:1.5"], "risk", ["--range", "0 < LOW < HIGH < 1"]),
    (["risk", DEFAULT, "--range", "contact.stiffness=1:2", "--max-bruise", "0.01", "--samples", "10"], "risk",
     ["--max-bruise", "samples are needed"]),
    (["risk", DEFAULT, "--fit", "missing.json"], "risk", ["--fit missing.json", "cannot read"]),
    (["risk", DEFAULT, "--range", "contact.stiffness=1:2", "--scales", "2:1"], "risk", ["--scales 2:1"]),
    (["risk", DEFAULT, "--range", "berries[*].hinge_damping=1e-5:5e-5", "--range", "berries[0].hinge_damping=1e-5:2e-5"],
     "risk", ["--range", "set the same value"]),  # both were drawn, the last silently winning
    (["risk", "still.toml", "--range", "contact.stiffness=1000:2000", "--max-bruise", "0.5", "--samples", "10"], "risk",
     ["--max-bruise", "pick-and-place"]),  # refused before any run (it was after every plan's runs)
    (["simulate", "--no-such-flag"], "simulate", ["unrecognized arguments"]),
    (["no-such-command"], "", ["invalid choice"]),
])
def test_every_command_refuses_in_one_line(tmp_path, args, command, words):
    (tmp_path / "afile").write_text("")
    (tmp_path / "latin1.toml").write_bytes(b"scene = \"caf\xe9.toml\"\n")
    (tmp_path / "m.csv").write_text("time_s,angle_left_rad\n" + "".join(f"{k / 100},0.0\n" for k in range(20)))
    (tmp_path / "spec.toml").write_text(f'scene = "{default_scene_path()}"\n[[parameters]]\nkey = "gravity"\n'
                                        'values = [9.81]\n')
    still = copy.deepcopy(DEFAULT_DOC)
    still["excitation"] = {"kind": "none"}  # a plan with no moves to scale
    from grapefmu.scenefile import dumps
    (tmp_path / "still.toml").write_text(dumps(still))
    r = cli(*args, cwd=tmp_path)
    if command:
        assert_one_line_error(r, command, *words)
    else:
        assert r.returncode == 2 and "Traceback" not in r.stderr and len(r.stderr.strip().splitlines()) == 1
        assert r.stderr.startswith("grapefmu: ") and all(w in r.stderr for w in words)


# --- values in range that together would exhaust memory ----------------------------------------------------

def test_samples_beyond_memory_are_refused_with_the_estimate(tmp_path):
    p = scene_file(tmp_path, "huge.toml", with_solver(t_end=1e5, output_interval=1e-6))
    start = time.monotonic()
    line = assert_one_line_error(cli("simulate", str(p), cwd=tmp_path), "simulate",
                                 "solver.t_end", "solver.output_interval", "GiB", "at most")
    assert time.monotonic() - start < 20
    assert "1e+11 samples" in line
    # the same refusal when the command line asks for it, naming the flag
    assert_one_line_error(cli("simulate", "--t-end", "1e5", cwd=tmp_path), "simulate", "--t-end", "GiB")


def test_zeno_ring_beyond_memory_is_refused(monkeypatch):
    from grapefmu.scenefile import budget

    cluster = Path(default_scene_path()).with_name("cluster60.toml")
    doc = tomllib.loads(cluster.read_text(encoding="utf-8"))
    doc.setdefault("solver", {})["zeno_max_events"] = 10**6  # the allowed maximum: 768 pairs × 10⁶ × 8 B = 6.1 GB
    monkeypatch.setattr(budget, "memory_limit", lambda: 4 * 2**30)
    with pytest.raises(SceneError) as ei:
        scene_from_dict(doc, cluster.parent)
    assert ei.value.key == "solver.zeno_max_events"
    assert "768 contact pairs" in str(ei.value) and "GiB" in str(ei.value)
    doc["solver"]["zeno_max_events"] = 64
    scene_from_dict(doc, cluster.parent)  # the default fits


# --- interruption and temporary files ----------------------------------------------------------------------

def _parts(d: Path) -> list[Path]:
    return sorted(d.glob(".*.grapefmu-part"))


def _catches(pid: int, sig: int) -> bool:
    """Whether process pid has a handler for sig (Linux: the SigCgt mask in /proc/<pid>/status)."""
    try:
        line = next(x for x in Path(f"/proc/{pid}/status").read_text().splitlines() if x.startswith("SigCgt:"))
    except (OSError, StopIteration):
        return False
    return bool(int(line.split()[1], 16) >> (sig - 1) & 1)


def _start_and_signal(tmp_path: Path, sig: int, args: list[str], wait_for_part: float) -> subprocess.CompletedProcess:
    out = tmp_path / "run.csv"
    proc = subprocess.Popen([sys.executable, "-m", "grapefmu", "simulate", *args, "--out", str(out)], cwd=tmp_path,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    # first the command's own handlers (under load, its imports took longer than the wait below, and the signal
    # killed the interpreter before main ran: a test of Python's start-up, not of the command)
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline and proc.poll() is None and not _catches(proc.pid, signal.SIGTERM):
        time.sleep(0.02)
    deadline = time.monotonic() + wait_for_part
    while time.monotonic() < deadline and not _parts(tmp_path) and proc.poll() is None:
        time.sleep(0.05)
    assert proc.poll() is None, proc.communicate()
    proc.send_signal(sig)
    t0 = time.monotonic()
    stdout, stderr = proc.communicate(timeout=5)
    assert time.monotonic() - t0 < 5
    return subprocess.CompletedProcess(proc.args, proc.returncode, stdout, stderr)


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT])
def test_interrupted_run_writes_nothing(tmp_path, sig):
    r = _start_and_signal(tmp_path, sig, ["--t-end", "1000"], wait_for_part=3.0)
    line = assert_one_line_error(r, "simulate", "interrupted; nothing written to", "run.csv", code=128 + sig)
    assert line.endswith("run.csv")
    assert not (tmp_path / "run.csv").exists() and not _parts(tmp_path)


@pytest.mark.parametrize("when", ["inside mkstemp", "after mkstemp"])
def test_an_interrupted_check_of_the_output_leaves_no_temporary_file(tmp_path, monkeypatch, when):
    """check_target proves a directory writable with a temporary file; a signal while it existed left it behind (seen
    once in CI: the interrupted-run test signalled the moment that probe appeared). The interrupt is raised here
    where the signal landed: inside mkstemp once the file exists, or just after it returned."""
    import tempfile

    from grapefmu.results import writers
    real = tempfile.mkstemp

    def made_then_interrupted(*a, **k):
        fd, name = real(*a, **k)
        if when == "inside mkstemp":
            os.close(fd)
            raise KeyboardInterrupt
        monkeypatch.setattr(writers.os, "close", interrupted_close)
        return fd, name

    def interrupted_close(fd):
        monkeypatch.undo()
        os.close(fd)
        raise KeyboardInterrupt

    monkeypatch.setattr(writers.tempfile, "mkstemp", made_then_interrupted)
    with pytest.raises(KeyboardInterrupt):
        writers.check_target(tmp_path / "run.csv", (".csv",), "--out")
    monkeypatch.undo()
    assert list(tmp_path.iterdir()) == []


SIGNAL_IN_A_CALLBACK = r"""
import ctypes, os, signal, sys, time
from grapefmu import cli

def in_a_callback(a):
    @ctypes.CFUNCTYPE(None)
    def callback():  # as llvmlite's object cache, called from C while numba compiles
        os.kill(os.getpid(), signal.SIGTERM)
        for _ in range(10000):  # the handler runs here, inside the callback
            pass
    callback()
    t = time.time()
    while time.time() - t < 20:  # the command's work goes on: the signal must still end it
        pass
    return 0

cli.cmd_simulate = in_a_callback
sys.exit(cli.main(["simulate", "--out", sys.argv[1]]))
"""


def test_a_signal_that_lands_in_a_callback_from_c_still_interrupts(tmp_path):
    """SIGTERM while numba compiled (llvmlite calls back into Python from C) raised Interrupted inside the callback,
    where ctypes printed its traceback and dropped it (seen once in CI): the command must still end at once, with the
    one-line message and 128 + the signal."""
    r = subprocess.run([sys.executable, "-c", SIGNAL_IN_A_CALLBACK, str(tmp_path / "run.csv")], cwd=tmp_path,
                       capture_output=True, text=True, timeout=60)
    assert_one_line_error(r, "simulate", "interrupted; nothing written to", "run.csv", code=143)


def test_interrupted_writer_removes_its_temporary_file(tmp_path):
    # half a million samples: the run takes about a second, the CSV several, so the signal comes mid-write
    p = scene_file(tmp_path, "many.toml", with_solver(t_end=0.5, output_interval=1e-6))
    r = _start_and_signal(tmp_path, signal.SIGTERM, [str(p)], wait_for_part=30.0)
    assert_one_line_error(r, "simulate", "interrupted; nothing written to", code=143)
    assert not (tmp_path / "run.csv").exists() and not _parts(tmp_path)


def test_next_writer_removes_stale_temporary_files(tmp_path):
    from grapefmu.results.writers import _host_tag

    dead = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True, text=True)
    dead_pid = int(dead.stdout)
    host = _host_tag()
    stale = tmp_path / f".run.csv.{host}-{dead_pid}.abcd1234.grapefmu-part"
    live = tmp_path / f".run.csv.{host}-{os.getpid()}.efgh5678.grapefmu-part"     # a writer still running
    other_host = tmp_path / f".run.csv.000000-{dead_pid}.ijkl9012.grapefmu-part"  # another machine's writer
    other_target = tmp_path / f".other.csv.{host}-{dead_pid}.mnop3456.grapefmu-part"
    for f in (stale, live, other_host, other_target):
        f.write_bytes(b"x" * 1000)
    r = cli("simulate", "--t-end", "0.01", "--out", str(tmp_path / "run.csv"), cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    assert (tmp_path / "run.csv").exists()
    assert not stale.exists()
    assert live.exists() and other_host.exists() and other_target.exists()


def test_atomic_path_names_its_temporary_file_with_the_pid(tmp_path):
    from grapefmu.results.writers import atomic_path

    with pytest.raises(KeyboardInterrupt):
        with atomic_path(tmp_path / "x.csv") as tmp:
            assert tmp.name.startswith(".x.csv.") and f"-{os.getpid()}." in tmp.name
            assert tmp.name.endswith(".grapefmu-part")
            tmp.write_text("half")
            raise KeyboardInterrupt
    assert not list(tmp_path.iterdir())


# --- fuzz: scene documents, scene bytes, command lines -----------------------------------------------------

def _paths(node, prefix=()):
    """Every (path, value) in a scene document, tables and lists included."""
    yield prefix, node
    if isinstance(node, dict):
        for k, v in node.items():
            yield from _paths(v, (*prefix, k))
    elif isinstance(node, list):
        for i, v in enumerate(node):
            yield from _paths(v, (*prefix, i))


PATHS = [p for p, _ in _paths(DEFAULT_DOC) if p]
NASTY_SCALARS = st.one_of(
    st.integers(min_value=-(10**400), max_value=10**400),
    st.sampled_from([10**20, -(10**20), 2**63, 10**308 * 10, 0, -1, 1]),
    st.floats(allow_nan=True, allow_infinity=True),
    st.sampled_from([math.nan, math.inf, -math.inf, -0.0, 5e-324, 1e308]),
    st.sampled_from(["nan", "inf", "", "1e3", "kelvin-voigt", "event", "a\nb", "é" * 40, "x" * 5000]),
    st.text(max_size=20),
    st.booleans(),
)
NASTY = st.recursive(NASTY_SCALARS, lambda inner: st.one_of(st.lists(inner, max_size=4),
                                                            st.dictionaries(st.text(max_size=8), inner, max_size=3)),
                     max_leaves=8)


def _deep(depth: int, leaf, kind: str):
    for _ in range(depth):
        leaf = [leaf] if kind == "list" else {"a": leaf}
    return leaf


@st.composite
def mutated_docs(draw):
    doc = copy.deepcopy(DEFAULT_DOC)
    for _ in range(draw(st.integers(1, 3))):
        path = draw(st.sampled_from(PATHS))
        parent = doc
        try:
            for k in path[:-1]:
                parent = parent[k]
            action = draw(st.sampled_from(["set", "set", "set", "delete", "deep"]))
            if action == "delete":
                del parent[path[-1]]
            elif action == "deep":
                parent[path[-1]] = _deep(draw(st.integers(50, 2000)), draw(NASTY_SCALARS),
                                         draw(st.sampled_from(["list", "dict"])))
            else:
                parent[path[-1]] = draw(NASTY)
        except (KeyError, IndexError, TypeError):
            pass  # an earlier mutation removed or replaced this path
    if draw(st.integers(0, 9)) == 7:  # now and then a key of its own (most are refused as unknown at once)
        doc[draw(st.sampled_from(["colour", "solver", "berries", "x" * 300, "a\nb"]))] = draw(NASTY)
    return doc


def assert_named_error_or_scene(fn, *args):
    try:
        fn(*args)
    except GrapefmuError as e:
        text = str(e)
        assert text and "\n" not in text and len(text) < 2000, text[:3000]
        if isinstance(e, SceneError):
            assert e.key and len(e.key) < 500
    # anything else (OverflowError, RecursionError, TypeError, ...) propagates and fails the test


@settings(FUZZ, max_examples=300)
@given(mutated_docs())
def test_fuzz_scene_documents(doc):
    assert_named_error_or_scene(scene_from_dict, doc, default_scene_path().parent)


TOKENS = [b"1" + b"0" * 400, b"1" + b"0" * 5000, b"nan", b"inf", b"-inf", b"-1", b"0", b"\"nan\"", b"true",
          b"[" * 2000 + b"]" * 2000, b"{a=" * 1000 + b"1" + b"}" * 1000, b"\xff\xfe", b"\xe9", b"\x00", b"\"\xc3\x28\"",
          b"1e400", b"0x7fffffffffffffffff", b"[1, 2, 3]", b"{}", b"\"\"", b"-0.0", b"1979-05-27T07:32:00Z"]


def _token(draw) -> bytes:
    """Mostly a token that TOML reads (so the scene checks see it), now and then raw bytes."""
    return draw(st.binary(min_size=1, max_size=12)) if draw(st.integers(0, 4)) == 3 else draw(st.sampled_from(TOKENS))


@st.composite
def mutated_bytes(draw):
    data = bytearray(DEFAULT_TEXT.encode())
    for _ in range(draw(st.integers(1, 3))):
        how = draw(st.sampled_from(["value", "value", "value", "insert", "truncate", "flip"]))
        if how == "value":  # replace what follows an "=" on a random line
            lines = data.split(b"\n")
            eq = [i for i, ln in enumerate(lines) if b"=" in ln and not ln.lstrip().startswith(b"#")]
            if eq:
                i = draw(st.sampled_from(eq))
                key = lines[i].split(b"=", 1)[0]
                lines[i] = key + b"= " + _token(draw)
                data = bytearray(b"\n".join(lines))
        elif how == "insert":
            at = draw(st.integers(0, len(data)))
            data[at:at] = _token(draw)
        elif how == "truncate":
            del data[draw(st.integers(0, len(data))):]
        elif data:
            at = draw(st.integers(0, len(data) - 1))
            data[at] ^= 1 << draw(st.integers(0, 7))
    return bytes(data)


@pytest.fixture(scope="module")
def fuzz_dir(tmp_path_factory):
    return tmp_path_factory.mktemp("fuzz")


@settings(FUZZ, max_examples=250)
@given(mutated_bytes())
def test_fuzz_scene_files(fuzz_dir, data):
    p = fuzz_dir / "scene.toml"
    p.write_bytes(data)
    assert_named_error_or_scene(load_scene, p)


FLOATS_TEXT = st.one_of(st.sampled_from(["nan", "inf", "-inf", "-1", "0", "1e400", "1e-400", "x", "", "1e5", "0.001"]),
                        st.floats(allow_nan=True, allow_infinity=True).map(repr))


@st.composite
def command_lines(draw):
    """Command lines that are wrong somewhere, or right and quick (a valid run is at most 0.02 s simulated)."""
    where = draw(st.sampled_from(["", "afile/", "adir/", "new/dir/", "/proc/none/"]))
    suffix = draw(st.sampled_from([".csv", ".parquet", ".mcap", ".png", ".svg", ".toml", ".xyz", "", ".CSV", "/"]))
    target = f"{where}{draw(st.sampled_from(['out', 'plot', 'x']))}{suffix}"
    cmd = draw(st.sampled_from(["simulate", "simulate", "simulate", "replay", "cluster", "sweep", "build-fmu",
                                "paper", "bench", "outputs"]))
    if cmd == "simulate":
        args = ["simulate"]
        scene = draw(st.sampled_from([None, "bad.toml", "latin1.toml", "missing.toml", "afile", "adir"]))
        args += [scene] if scene else []
        t_end = draw(st.one_of(FLOATS_TEXT, st.sampled_from(["0.01", "0.02"])))
        try:
            if 0.02 < float(t_end) <= 1e5:  # a valid t_end must stay short
                t_end = "0.01"
        except ValueError:
            pass
        args += ["--t-end", t_end]
        for flag in ("--rtol", "--atol", "--method"):
            if draw(st.booleans()):
                args += [flag, draw(st.one_of(FLOATS_TEXT, st.sampled_from(["event", "paper", "euler"])))]
        return args + [draw(st.sampled_from(["--out", "--plot"])), target]
    if cmd == "replay":  # --publish only of what is not a recording (a real one would be published over ROS)
        publish = draw(st.booleans())
        recording = draw(st.sampled_from(["missing.mcap", "adir"] if publish else
                                         ["missing.mcap", "afile", "adir", "latin1.toml"]))
        return ["replay", recording, "--publish" if publish else "--check", "--rate", draw(FLOATS_TEXT)]
    if cmd == "cluster":
        args = ["cluster", "-o", f"{where}c{draw(st.sampled_from(['.toml', '.toml', suffix]))}"]
        args += ["--berries", draw(st.sampled_from(["-1", "0", "2", "3", "100000", "x", "1e3"]))]
        args += ["--seed", draw(st.sampled_from(["-5", "0", "7", str(2**70), "x"]))]
        if draw(st.booleans()):
            return args + ["--row", "--pitch", draw(FLOATS_TEXT)]
        return args + ["--diameter", draw(FLOATS_TEXT), draw(FLOATS_TEXT)]
    if cmd == "sweep":
        return ["sweep", draw(st.sampled_from(["missing.toml", "latin1.toml", "bad.toml", "adir"])), "-o", target]
    if cmd == "build-fmu":  # never a writable .fmu: building one is slow
        return ["build-fmu", draw(st.sampled_from(["bad.toml", "missing.toml"])), "-o", target]
    if cmd == "paper":  # only targets that cannot be a directory to write in: a full reproduction is slow
        return ["paper", "--out", draw(st.sampled_from(["afile", "afile/x", "/proc/none", ""]))]
    if cmd == "bench":
        return ["bench", "--quick", "--out", draw(st.sampled_from(["afile/r.md", "r.txt", "", "adir"])),
                "--plots", draw(st.sampled_from(["afile", "plots"]))]
    return ["outputs", *draw(st.sampled_from([[], ["--bogus"], ["x"]]))]


@pytest.fixture(scope="module")
def cli_dir(tmp_path_factory):
    d = tmp_path_factory.mktemp("cli")
    (d / "afile").write_text("")
    (d / "adir").mkdir()
    (d / "latin1.toml").write_bytes(DEFAULT_TEXT.encode() + b"# caf\xe9\n")
    (d / "bad.toml").write_text(DEFAULT_TEXT.replace("mass = 0.011", "mass = -1"))
    return d


@settings(FUZZ, max_examples=24)
@given(command_lines())
def test_fuzz_command_lines(cli_dir, args):
    r = cli(*args, cwd=cli_dir, timeout=120)
    assert "Traceback" not in r.stderr, (args, r.stderr[-3000:])
    assert r.returncode in CLEAN_EXITS, (args, r.returncode, r.stderr[-2000:])
    if r.returncode:
        lines = r.stderr.strip().splitlines()
        assert len(lines) == 1 and lines[0].startswith("grapefmu"), (args, r.stderr)
    assert not list(cli_dir.rglob("*.grapefmu-part")), args


def test_an_interruption_a_library_turned_into_another_error_still_ends_as_one(monkeypatch, tmp_path, capsys):
    """SIGINT raises Interrupted wherever Python is; inside numba's boxing of a compiled object it came out as a
    TypeError (a risk run interrupted in CI exited 1 instead of 130). Once a signal was received, whatever the
    command raises ends it as that interruption: 128 + signal, and the journal's note."""
    from grapefmu import cli

    def interrupted_inside_a_library(a):
        cli._received.append(signal.SIGINT)  # what _on_signal records before it raises
        raise TypeError("StructRefProxy._numba_box_() missing 2 required positional arguments: 'ty' and 'mi'")

    import grapefmu.sweep as sweep_pkg
    monkeypatch.setattr(sweep_pkg, "run_sweep", lambda *a, **k: interrupted_inside_a_library(None))
    (tmp_path / "scene.toml").write_text((Path(__file__).resolve().parents[1] / "scenes" / "default.toml").read_text())
    spec = tmp_path / "s.toml"
    spec.write_text('scene = "scene.toml"\nmode = "grid"\n[[parameters]]\nkey = "contact.stiffness"\n'
                    'values = [1000.0, 2000.0]\n')
    monkeypatch.chdir(tmp_path)
    code = cli.main(["sweep", str(spec)])
    err = capsys.readouterr().err
    assert code == 130, err
    assert "interrupted" in err and "run the same command again" in err
    cli._received.clear()


def test_a_reference_run_shows_progress_and_a_summary_without_blanks(tmp_path, capsys):
    """`simulate --method reference` showed no progress on a 33 s run (simulate did not hand its callback to the
    reference), and its summary printed '- steps' and 'nan near pairs per step' for counts only the event solver
    keeps (an audit)."""
    from grapefmu.cli import main
    from grapefmu.solver.api import simulate
    assert main(["cluster", "--row", "--berries", "3", "-o", str(tmp_path / "row.toml")]) == 0
    capsys.readouterr()
    seen = []
    simulate(load_scene(tmp_path / "row.toml"), 0.05, method="reference", progress=lambda t, te: seen.append((t, te)))
    assert seen[0] == (0.0, 0.05) and seen[-1] == (0.05, 0.05) and seen == sorted(seen)
    assert main(["simulate", str(tmp_path / "row.toml"), "--method", "reference", "--t-end", "0.05"]) == 0
    out = capsys.readouterr().out  # (the bar itself shows after a second of running: Progress)
    assert " - " not in out and "nan" not in out and "scene row: 3 berries, 3 contact pairs" in out
    kept = next(line for line in out.splitlines() if line.strip().startswith("kept"))
    assert "degrees of freedom" not in kept and "at most" in kept


def test_one_file_given_twice_as_out_is_written_once(tmp_path, capsys, monkeypatch):
    """--out a.csv --out ./a.csv wrote the same file twice (an audit)."""
    from grapefmu.cli import main
    monkeypatch.chdir(tmp_path)
    assert main(["simulate", "--t-end", "0.01", "--out", "a.csv", "--out", "./a.csv", "--out", "b.csv"]) == 0
    assert [line for line in capsys.readouterr().out.splitlines() if line.startswith("wrote")] == \
        ["wrote a.csv", "wrote b.csv"]

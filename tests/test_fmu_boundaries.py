"""The FMU at the edges of what a host may do, found by an audit (each case failed on the code before it): the built
FMUs driven in a process of their own (tests/fmu_boundaries.py)."""
from __future__ import annotations

import json
import math
import re
import subprocess
import sys
from pathlib import Path

import pytest

from .conftest import build_fmu

pytest.importorskip("fmpy")
ROOT = Path(__file__).resolve().parents[1]
ERROR = 3


#: a third berry out of the default scene's reach (its pairs left out of the build) unless its hinge moves 5.5 cm
FAR_BERRY = """
[[berries]]
name = "far"
mass = 0.011
radius = 0.0135
twig_length = 0.03
hinge_x = -0.2
hinge_stiffness = 1.0e-3
hinge_damping = 2.0e-5
"""


@pytest.fixture(scope="module")
def results(tmp_path_factory):
    d = tmp_path_factory.mktemp("fmu")
    far = d / "far.toml"
    far.write_text((ROOT / "src/grapefmu/scenes/default.toml").read_text() + FAR_BERRY)
    fmus = [build_fmu(d / "d2.fmu", 2), build_fmu(d / "d3.fmu", 3),
            build_fmu(d / "bare2.fmu", 2, "scenes/paper/test1.toml"), build_fmu(d / "far2.fmu", 2, str(far))]
    r = subprocess.run([sys.executable, "-m", "tests.fmu_boundaries", *map(str, fmus)], cwd=ROOT,
                       capture_output=True, text=True, timeout=900)
    assert "JSON:" in r.stdout, r.stderr[-3000:]
    return json.loads(r.stdout.split("JSON:", 1)[1])


def test_the_same_fmu_extracted_twice_in_one_process_still_refuses(results):
    """pythonfmu imports the slave module once per process, so two extractions share its classes; the refusal went to
    the binary of the last instance made, and the earlier instance's refused calls returned OK."""
    for fmi in ("fmi2", "fmi3"):
        assert results[fmi]["twice: a zero step"] == ERROR, fmi
    assert results["fmi2"]["twice: a NaN input"] == ERROR
    assert results["fmi2"]["twice: b zero step"] == ERROR


def test_start_times_and_communication_points_the_fmu_cannot_run_from_are_refused(results):
    """A NaN or 1e300 s start time was taken (every step then OK, nothing moving); so were doStep at NaN and −∞."""
    r = results["fmi2"]
    assert r["start NaN"] == r["start huge"] == ERROR
    assert r["doStep at NaN"] == r["doStep at -inf"] == ERROR
    assert results["fmi3"]["start NaN"] == ERROR


def test_fmi3_starts_at_the_hosts_start_time(results):
    """pythonfmu3 hands FMI 3's startTime to nobody: the FMU started at 0 and refused every step of a host at 5 s."""
    r = results["fmi3"]
    assert r["start 5: time"] == 5.0 and r["start 5: step"] == 0 and r["start 5: time after"] == 5.001


def test_an_fmu_state_brings_its_parameters_or_is_refused(results):
    """A state whose stored parameters were altered (mass, restitution) is refused, the instance unchanged; one whose
    integer was stored as 2.7 too. Another instance's real state, taken at another yaw, is restored with that yaw: the
    restored instance then steps exactly as the one that made it (it used to keep its own yaw and check the inputs
    against its own plane)."""
    r = results["fmi2"]
    for label in ("mass", "restitution", "law 2.7"):
        status, *values = r[f"crafted {label}"]
        assert status == ERROR, label
        assert values == r["fresh"], label  # the instance as made: nothing of the refused state
    assert r["yaw state restored"] == 0 and r["yaw reads"] == 0.5
    assert r["yaw steps"] == [0, 0] and r["yaw same angle"]
    assert r["yaw turn about world y"] == [ERROR, ERROR]  # off the yawed plane's normal: refused by both alike


def test_a_state_taken_in_initialization_mode_restores_initialization_mode(results):
    """The phase was not in the state: restored after steps, the instance refused both its parameters (fixed) and
    its steps (not initialized)."""
    r = results["fmi2"]
    assert r["init state restored"] == r["init state: set parameter"] == r["init state: exit"] == 0
    assert r["init state: step"] == 0 and abs(r["init state: angle"] - 0.1) < 0.01


def test_outputs_in_initialization_mode_are_the_start_state_of_the_parameters_set_so_far(results):
    """FMI's InitialUnknowns: a host that reads them to initialize what it connects got 0 rad and 0 N (the start
    values) for a berry set at -0.3 rad."""
    during, refused, again, after = results["fmi2"]["init outputs"]
    assert during[0] == -0.3 and during[1] > 0.0
    assert refused == during  # parameters the validator refuses: the last outputs stand
    assert again == after and after[0] == -0.2


def test_parameter_errors_name_the_fmu_variable_and_rtol_takes_its_whole_range(results):
    status, log = results["fmi2"]["param mass"]
    assert status == ERROR and "mass_left = -1.0: expected a number in (0, 10] kg" in log
    assert results["fmi2"]["param rtol"][0] == 0  # the derived atol, rtol·1e-2 = 1e-16, was outside atol's range


def test_contact_parameters_of_a_scene_without_contact_are_refused(results):
    """They acted on nothing and were accepted (contact_law 7 read back as 7)."""
    status, log = results["fmi2"]["no contact restitution"]
    assert status == ERROR and "no [contact] table" in log and "restitution = 0.5" in log


def test_a_pair_pressed_past_any_contact_law_is_a_warning_with_the_step_taken(results):
    """A host has no run warnings and no /diagnostics: doStep returns Warning, the step taken, with the message a run
    and the ROS node give, as a pair gets pressed past 0.2 of its smaller radius, once per excursion. Here a contact
    law of 1 N/m lets the raised berry swing far past the bound into the other, twice; the warnings come exactly at
    the steps whose end the FMU's own penetration output puts past the bound after a step within it, and the run
    goes on to the end.
    FMI 3 logs the same two warnings (fmpy's FMI 3 doStep does not return the status)."""
    r = results["fmi2"]["deep"]
    bound, steps = r["bound"], r["steps"]
    assert all(st == 0 for st, *_ in steps) and r["t"] == pytest.approx(0.6)  # never refused
    deeper = [k for k, s in enumerate(steps) if s[3] > bound and (k == 0 or steps[k - 1][3] <= bound)]
    warned = [k for k, s in enumerate(steps) if s[1] == 1]
    assert len(deeper) == 2 and warned == deeper, (deeper, warned)
    assert all(s[1] == 0 and not s[2] for k, s in enumerate(steps) if k not in warned)
    for k in warned:
        t = (k + 1) * 1e-3
        assert re.fullmatch(rf"step to t = {t:.9g} s taken, but berries 'left' and 'right' overlapped by "
                            rf"{steps[k][3] * 1e3:.3g} mm at t = {t:.6g} s, beyond {bound * 1e3:.3g} mm \(0.2 of the "
                            r"smaller radius\), where no contact law holds: .*", steps[k][2]), steps[k][2]
    assert all(math.isfinite(s[4]) for s in steps)
    r3 = results["fmi3"]["deep"]
    assert [k for k, (st, m) in enumerate(r3["steps"]) if "where no contact law holds" in m] == warned
    assert all(st == 0 for st, _ in r3["steps"]) and r3["time"] == pytest.approx(0.6)


def test_parameters_that_change_which_pairs_can_touch_are_refused_naming_them(results):
    """The outputs name the built scene's pairs. A hinge moved so far that the pair can never touch dropped it: reading
    its output raised IndexError (Fatal), and the host's next call crashed. A far berry's hinge moved within reach
    brought back a pair the build had left out, and every later pair's output then showed another pair's force. Now
    exitInitializationMode refuses both, naming the parameter; the outputs read without error meanwhile, and the
    instance initializes once the parameter is back."""
    r = results["fmi2"]
    assert r["reach dropped: read"] == r["reach dropped: read after"] == [0]
    status, log = r["reach dropped: exit"]
    assert status == ERROR and "hinge_x_left = -1.0: puts berries 'left' and 'right' out of each other's reach" in log
    assert "(left_right)" in log
    assert r["reach dropped: exit again"] == 0 and r["reach dropped: step"] == 0
    status, log = r["reach added: exit"]
    assert status == ERROR and "hinge_x_far = -0.045: puts berries 'left' and 'far' within reach" in log, log
    assert r["reach kept: exit"] == 0  # moved, but still out of reach: the pairs are the built ones


def test_calls_out_of_fmi_order_are_refused_and_change_nothing(results):
    """enterInitializationMode and exitInitializationMode in Step Mode returned OK and restarted the run at t = 0;
    doStep after terminate went on integrating; a setReal refused for one value set the others. Each is now refused,
    and the instance then steps exactly as a twin that never made those calls."""
    r = results["fmi2"]
    assert r["order: enter init"] == r["order: set a fixed parameter"] == r["order: exit init"] == ERROR
    assert r["order: set two, one NaN"] == ERROR and r["order: base_ax"] == 2.0
    assert r["order: steps"] == [0] * 40
    assert r["order: same angle"][0] == r["order: same angle"][1]
    step, set_input, angle = r["order: after terminate"]
    assert step == set_input == ERROR and angle == r["order: same angle"][0]


def test_fmi3_calls_this_fmu_has_nothing_for_are_errors_the_host_survives(results):
    """pythonfmu3 throws a C++ exception from most of them (std::logic_error: the host aborted) or raised in Python
    (updateDiscreteStates: Fatal); enterEventMode and enterConfigurationMode returned OK."""
    r = results["fmi3"]
    assert r["unsupported"] == {name: ERROR for name in r["unsupported"]}
    assert r["unsupported: empty get"] == 0 and r["unsupported: step after"] == 0


def test_fmi3_do_step_sets_every_output_argument(results):
    """pythonfmu3 wrote none of the flags (a host's pre-filled True came back as 'event handling needed' and 'early
    return') and gave the step's end as lastSuccessfulTime after a Discard or an Error. Now all flags are False and
    lastSuccessfulTime is where the FMU is: the step's end, or its time before a refused step."""
    ok, discard, error = results["fmi3"]["doStep outputs"]
    assert ok == [0, [False] * 3, pytest.approx(2e-3, abs=1e-15)]
    assert discard[0] == 2 and discard[1:] == [[False] * 3, pytest.approx(2e-3, abs=1e-15)]
    assert error[0] == ERROR and error[1:] == [[False] * 3, pytest.approx(2e-3, abs=1e-15)]

"""What the FMI 2.0 and 3.0 slaves share: the core, the description, the access rules and the FMU state.

No method pythonfmu calls may raise: pythonfmu turns an exception into fmiFatal and drops the Python
slave, so the host's next call would crash. Every refusal instead goes to the FMU's binary (shim.c)
through `grapefmu_refuse(status, message)`, which logs the message and makes the current FMI call
return that status; the slave's values and state stay as they were. The binary is the one forwarding the
current call (report.in_call): the same FMU extracted twice in one process shares this module's classes."""
from __future__ import annotations

import functools
import ctypes
import math
from pathlib import Path

from grapefmu import GrapefmuError, __version__
from grapefmu.model.bounds import bound
from grapefmu.model.model import SolverSettings
from grapefmu.solver.warmup import notice

from .core import ERROR, OK, WARNING, FmuCore
from .report import binaries, in_call, refuse

#: s: the largest start time's magnitude, a scene's longest run (solver.t_end): beyond it the time's resolution
#: is too coarse for event location (at 1e300 s no step moves the time at all)
MAX_START = bound(SolverSettings, "t_end").hi


def kinds(causality, variability, initial) -> dict[tuple[str, bool], dict]:
    """Registration keywords per (causality, is real) from one FMI version's enums (same member names
    in FMI 2.0 and 3.0): inputs and outputs continuous when real, parameters fixed, outputs calculated
    (from the parameters at the end of initialization)."""
    out = {}
    for real in (True, False):
        var = variability.continuous if real else variability.discrete
        out["input", real] = {"causality": causality.input, "variability": var}
        out["output", real] = {"causality": causality.output, "variability": var, "initial": initial.calculated}
        out["parameter", real] = {"causality": causality.parameter, "variability": variability.fixed,
                                  "initial": initial.exact}
    return out


class Refusal:
    """What _fmu_state_from_bytes returns for bytes it cannot trust: setting it is refused again."""

    def __init__(self, message: str):
        self.message = message


class GrapeSlaveMixin:
    scene_file = "scene.toml"
    TYPES: dict            # per FMI version: the variable class of each of our types
    ACCESS: dict           # per FMI version: {get/set method suffix: variable class} of every FMI type
    KINDS: dict            # per FMI version: kinds(...)
    EXPERIMENT: type       # per FMI version: its DefaultExperiment
    UNITS = False          # whether the version's variables carry a unit
    #: the binaries of every instance made in this process (of any extraction): report.in_call picks the one in a call
    _binaries: list = []

    def __init_subclass__(cls, **kw):
        super().__init_subclass__(**kw)
        for suffix, kind in cls.ACCESS.items() if "ACCESS" in cls.__dict__ else ():
            setattr(cls, f"get_{suffix}", lambda self, vrs, kind=kind: self._get(vrs, kind))
            setattr(cls, f"set_{suffix}", lambda self, vrs, values, kind=kind: self._set(vrs, values, kind))

    # --- set-up -----------------------------------------------------------------------------------
    def _setup(self, kwargs) -> None:
        resources = Path(kwargs.get("resources") or ".")
        GrapeSlaveMixin._binaries += [b for b in binaries(resources, type(self).__name__)
                                      if b not in GrapeSlaveMixin._binaries]
        self.core = FmuCore(resources / self.scene_file)
        self.description = (f"grapefmu {__version__}: berries on hinged twigs that swing and collide under "
                            f"base excitation; scene '{self.core.scene.name}'")
        self.author = "grapefmu"
        self.version = __version__
        self.start_time = 0.0
        sv = self.core.scene.solver
        self.default_experiment = self.EXPERIMENT(start_time=0.0, stop_time=sv.t_end, step_size=sv.output_interval,
                                                  tolerance=sv.rtol)
        self.phase = "instantiated"  # -> "initialization" -> "step" (core.PHASES)

    @functools.cached_property
    def _getters(self) -> dict:
        """{variable class: {value reference: getter}} of every variable."""
        out: dict = {kind: {} for kind in self.ACCESS.values()}
        for vr, var in self.vars.items():
            out[type(var)][vr] = var.getter
        return out

    @functools.cached_property
    def _inputs(self) -> dict:
        """{variable class: {value reference: (name, largest magnitude)}} of the real inputs, for _set's fast path
        (a bound of 0: only 0 is accepted there, anything else gets value_problem's message)."""
        out: dict = {}
        bounds = self._inputs_from = self.core.input_bounds
        for vr, var in self.vars.items():
            if var.causality.name == "input" and var.name in bounds:
                out.setdefault(type(var), {})[vr] = (var.name, bounds[var.name])
        return out

    def _bounds_changed(self) -> None:
        """A new solver (its scene's orientation) may allow other turns: _inputs is built again from the core's
        input_bounds when they are new."""
        if self.__dict__.get("_inputs_from") is not self.core.input_bounds:
            self.__dict__.pop("_inputs", None)

    def _register(self, var) -> None:
        kw = {"description": var.description, **self._accessors(var), **self.KINDS[var.causality, var.type == "real"]}
        if self.UNITS and var.type == "real" and var.unit not in ("", "1"):
            kw["unit"] = var.unit
        self.register_variable(self.TYPES[var.type](var.name, **kw))

    def _accessors(self, var) -> dict:
        core, values, name = self.core, self.core.values, var.name
        getter = (lambda: core.output(name)) if var.causality == "output" else (lambda: values[name])
        return {"getter": getter, "setter": lambda x: values.__setitem__(name, x)}

    @classmethod
    def _refuse(cls, message: str, status: int = ERROR) -> None:
        refuse(GrapeSlaveMixin._binaries, status, message.encode("utf-8", "replace"))

    def _start(self, start_time) -> bool:
        """Take the host's start time (setupExperiment, or FMI 3's enterInitializationMode through the binary);
        refused (False) unless finite and within ±MAX_START s."""
        t = float(start_time or 0.0)
        if not (math.isfinite(t) and abs(t) <= MAX_START):
            self._refuse(f"startTime {start_time!r} s: expected a finite time within ±{MAX_START:g} s; refused, the "
                         f"start stays {self.start_time!r} s")
            return False
        self.start_time = t
        return True

    # --- variable access --------------------------------------------------------------------------
    def _variable(self, vr, kind, setting: bool):
        """The variable behind value reference `vr` if this call may use it, else None (refused)."""
        var = self.vars.get(vr)
        what = kind.__name__
        if var is None or not isinstance(var, kind):
            self._refuse(f"value reference {vr} is not a {what} variable of this FMU")
            return None
        if not setting:
            return var
        c = var.causality.name
        if c not in ("input", "parameter"):
            self._refuse(f"{var.name} has causality {c}: only inputs and parameters can be set")
            return None
        if c == "parameter" and self.phase == "step":
            self._refuse(f"{var.name} is a fixed parameter: it can be set only before exitInitializationMode")
            return None
        return var

    def _get(self, vrs, kind) -> list:
        try:
            return self._read(vrs, kind)
        except Exception as e:  # noqa: BLE001 - nothing may reach pythonfmu; this is a bug, reported as Error
            self._refuse(f"get{kind.__name__}: {type(e).__name__}: {e}")
            return ["" if kind.__name__ == "String" else 0] * len(vrs)

    def _read(self, vrs, kind) -> list:
        try:  # every reference readable as this kind: the common call, one dictionary lookup each
            getters = self._getters[kind]
            return [getters[vr]() for vr in vrs]
        except KeyError:
            pass
        out = []
        for vr in vrs:
            var = self._variable(vr, kind, False)
            out.append(var.getter() if var is not None else "" if kind.__name__ == "String" else 0)
        return out

    def _set(self, vrs, values, kind) -> None:
        """All the call's values, or none when one is refused (the FMU keeps its values)."""
        if self.phase == "terminated":
            self._refuse(f"set{kind.__name__}: the FMU is terminated; reset it to set values again; refused")
            return
        inputs = self._inputs.get(kind, {})
        try:  # finite floats within range on inputs: the common call, checked inline
            for vr, x in zip(vrs, values, strict=True):
                name, bound = inputs[vr]
                if not (type(x) is float and -bound <= x <= bound):
                    break
            else:
                for vr, x in zip(vrs, values):
                    self.core.values[inputs[vr][0]] = x
                return
        except (KeyError, ValueError):
            pass
        if len(vrs) != len(values):
            self._refuse(f"set{kind.__name__}: {len(vrs)} value references but {len(values)} values")
            return
        accepted = []
        for vr, x in zip(vrs, values):
            var = self._variable(vr, kind, True)
            problem = var is not None and self.core.value_problem(var.name, x)
            if problem:
                self._refuse(problem)
            elif var is not None:
                accepted.append((var, x))
        if len(accepted) < len(vrs):
            if accepted:
                self._refuse(f"set{kind.__name__}: none of the call's {len(vrs)} values set, as one was refused")
            return
        for var, x in accepted:
            var.setter(x)

    # --- modes and steps --------------------------------------------------------------------------
    def _in_phase(self, call: str, phase: str) -> bool:
        """Whether the FMU is in `phase` (core.PHASES), as `call` requires; refused (False) otherwise, the FMU keeping
        its state (pythonfmu lets any call through in any state)."""
        if self.phase == phase:
            return True
        after = {"instantiated": "instantiate or reset", "initialization": "enterInitializationMode",
                 "step": "exitInitializationMode", "terminated": "terminate"}
        self._refuse(f"{call}: not allowed after {after[self.phase]} (it must follow {after[phase]}); refused, the FMU "
                     "keeps its state")
        return False

    def enter_initialization_mode(self):
        if not self._in_phase("enterInitializationMode", "instantiated"):
            return
        if self.FMI == 3:  # pythonfmu3 passes FMI 3's startTime to nobody: the binary kept it
            given, t = in_call(GrapeSlaveMixin._binaries, "grapefmu_start_time", [], ctypes.c_double)
            if given and not self._start(t):
                return
        self.phase = "initialization"

    def exit_initialization_mode(self):
        if not self._in_phase("exitInitializationMode", "initialization"):
            return
        notice(lambda line: self._refuse(line, OK))  # logged (status OK) before the core's first compile
        err = self.core.initialize(self.start_time)
        self._bounds_changed()
        if err:
            self._refuse(err)
        else:
            self.phase = "step"

    def _step(self, current_time, step_size) -> None:
        """Integrate the communication step. What the core says goes to the binary, which makes doStep return it:
        Error or Discard with the state unchanged, Warning with the step taken (do_step itself always returns True)."""
        if self.phase == "terminated":
            said = (ERROR, f"doStep: not allowed after terminate; refused, the FMU stays at t = {self.core.time!r} s")
        else:
            try:
                said = self.core.step(current_time, step_size)
            except Exception as e:  # noqa: BLE001 - nothing may reach pythonfmu; this is a bug, reported as Error
                said = (ERROR, f"doStep failed: {type(e).__name__}: {e}")
        if said:
            self._refuse(said[1], said[0])
            if said[0] > WARNING and self.FMI == 3:  # the time it stays at: FMI 3's lastSuccessfulTime
                in_call(GrapeSlaveMixin._binaries, "grapefmu_reached", [ctypes.c_double], None, self.core.time)

    def terminate(self):
        self.phase = "terminated"

    # --- FMU state --------------------------------------------------------------------------------
    def _get_fmu_state(self):
        return self.core.get_state(self.phase)

    def _set_fmu_state(self, state):
        if isinstance(state, Refusal):
            self._refuse(f"setFMUState: {state.message}")
            return
        try:
            self.core.set_state(state)
            self.phase = state["phase"]
            self._bounds_changed()
        except GrapefmuError as e:
            self._refuse(f"setFMUState refused, the FMU keeps its state: {e}")
        except Exception as e:  # noqa: BLE001 - a state object the host made up
            self._refuse(f"setFMUState refused, not a state of this FMU ({type(e).__name__}: {e})")

    @staticmethod
    def _fmu_state_to_bytes(state) -> bytes:
        return FmuCore.state_to_bytes(state)

    @classmethod
    def _fmu_state_from_bytes(cls, data: bytes):
        try:
            return FmuCore.state_from_bytes(data)
        except GrapefmuError as e:
            cls._refuse(f"deserializeFMUState refused: {e}")
            return Refusal(str(e))


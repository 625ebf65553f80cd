"""FMI 2.0 co-simulation slave (pythonfmu). pythonfmu turns a Python exception into fmi2Fatal and a
False from do_step into fmi2Discard, so nothing here raises: errors are logged with fmi2Error
status and the step is refused (fmi2Discard), the state left as it was."""
from __future__ import annotations

from pathlib import Path

from pythonfmu import Boolean, Fmi2Causality, Fmi2Initial, Fmi2Slave, Fmi2Variability, Integer, Real
from pythonfmu.enums import Fmi2Status

from grapefmu import __version__

from .core import FmuCore

TYPES = {"real": Real, "integer": Integer, "boolean": Boolean}


class GrapeFmi2Slave(Fmi2Slave):
    scene_file = "scene.toml"

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.core = FmuCore(Path(kwargs.get("resources") or ".") / self.scene_file)
        self.description = (f"grapefmu {__version__}: berries on hinged twigs that swing and collide under "
                            f"base excitation; scene '{self.core.scene.name}'")
        self.author = "grapefmu"
        self.version = __version__
        self.start_time = 0.0
        for var in self.core.vars:
            self._register(var)

    def _register(self, var):
        values = self.core.values
        kw = {"description": var.description,
              "getter": lambda n=var.name: values[n],
              "setter": lambda x, n=var.name: values.__setitem__(n, x)}
        if var.causality == "input":
            kw.update(causality=Fmi2Causality.input,
                      variability=Fmi2Variability.continuous if var.type == "real" else Fmi2Variability.discrete)
        elif var.causality == "output":
            kw.update(causality=Fmi2Causality.output, initial=Fmi2Initial.exact,
                      variability=Fmi2Variability.continuous if var.type == "real" else Fmi2Variability.discrete)
        else:
            kw.update(causality=Fmi2Causality.parameter, variability=Fmi2Variability.fixed, initial=Fmi2Initial.exact)
        self.register_variable(TYPES[var.type](var.name, **kw))

    def setup_experiment(self, start_time, stop_time=None, tolerance=None):
        self.start_time = float(start_time or 0.0)

    def exit_initialization_mode(self):
        err = self.core.initialize(self.start_time)
        if err:
            self.log(err, Fmi2Status.error)

    def do_step(self, current_time, step_size):
        err = self.core.step(current_time, step_size)
        if err:
            self.log(err, Fmi2Status.error)
            return False
        return True

    def _get_fmu_state(self):
        return self.core.get_state()

    def _set_fmu_state(self, state):
        self.core.set_state(state)

    @staticmethod
    def _fmu_state_to_bytes(state) -> bytes:
        return FmuCore.state_to_bytes(state)

    @staticmethod
    def _fmu_state_from_bytes(state: bytes):
        return FmuCore.state_from_bytes(state)

"""FMI 2.0 co-simulation slave (pythonfmu). pythonfmu turns a Python exception into fmi2Fatal and a
False from do_step into fmi2Discard, so nothing here raises: errors are logged with fmi2Error
status and the step is refused (fmi2Discard), the state left as it was."""
from __future__ import annotations

from pythonfmu import Boolean, Fmi2Causality, Fmi2Initial, Fmi2Slave, Fmi2Variability, Integer, Real
from pythonfmu.enums import Fmi2Status

from .common import GrapeSlaveMixin, kinds


class GrapeFmi2Slave(GrapeSlaveMixin, Fmi2Slave):
    TYPES = {"real": Real, "integer": Integer, "boolean": Boolean}
    INITIAL = Fmi2Initial
    KINDS = kinds(Fmi2Causality, Fmi2Variability, Fmi2Initial)

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self._setup(kwargs)
        for var in self.core.vars:
            self._register(var)

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

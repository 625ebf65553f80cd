"""FMI 2.0 co-simulation slave (pythonfmu); refusals are reported as common.py describes."""
from __future__ import annotations

from pythonfmu import Boolean, Fmi2Causality, Fmi2Initial, Fmi2Slave, Fmi2Variability, Integer, Real, String

from pythonfmu.default_experiment import DefaultExperiment

from .common import GrapeSlaveMixin, kinds


class GrapeFmi2Slave(GrapeSlaveMixin, Fmi2Slave):
    TYPES = {"real": Real, "integer": Integer, "boolean": Boolean}
    ACCESS = {"real": Real, "integer": Integer, "boolean": Boolean, "string": String}
    EXPERIMENT = DefaultExperiment
    FMI = 2
    KINDS = kinds(Fmi2Causality, Fmi2Variability, Fmi2Initial)

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self._setup(kwargs)
        for var in self.core.vars:
            self._register(var)

    def setup_experiment(self, start_time, stop_time=None, tolerance=None):
        self._start(start_time)  # the stop time is enforced by the FMU's binary

    def do_step(self, current_time, step_size):
        self._step(current_time, step_size)
        return True  # a refusal or a warning already set the call's status (Error, Discard or Warning)

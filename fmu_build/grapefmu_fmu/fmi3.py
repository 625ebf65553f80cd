"""FMI 3.0 co-simulation slave (pythonfmu3), with units on every variable and the `time` independent
variable; refusals are reported as common.py describes."""
from __future__ import annotations

from xml.etree.ElementTree import Element

from pythonfmu3 import (Boolean, Fmi3Causality, Fmi3Initial, Fmi3Slave, Fmi3Variability, Float64, Int32, Int64, String,
                        UInt64)
from pythonfmu3.fmi3slave import Fmi3StepResult
from pythonfmu3.unit import Unit

from pythonfmu3.default_experiment import DefaultExperiment

from .common import GrapeSlaveMixin, kinds
from .units import BASE_UNITS


class _UnitWithoutBase(Unit):
    """A unit whose SI exponents are not whole numbers (N/m^1.5): FMI allows leaving BaseUnit out."""

    def to_xml(self):
        return Element(self.tag, {"name": self.name})


class GrapeFmi3Slave(GrapeSlaveMixin, Fmi3Slave):
    TYPES = {"real": Float64, "integer": Int32, "boolean": Boolean}
    ACCESS = {"float64": Float64, "int32": Int32, "int64": Int64, "uint64": UInt64, "boolean": Boolean,
              "string": String}
    EXPERIMENT = DefaultExperiment
    FMI = 3
    KINDS = kinds(Fmi3Causality, Fmi3Variability, Fmi3Initial)
    UNITS = True

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self._setup(kwargs)
        units = {v.unit for v in self.core.vars if v.unit not in ("", "1")} | {"s"}
        self.register_units([Unit(u, **BASE_UNITS[u]) if BASE_UNITS[u] is not None else _UnitWithoutBase(u)
                             for u in sorted(units)])
        self.register_variable(Float64("time", causality=Fmi3Causality.independent,
                                       variability=Fmi3Variability.continuous, unit="s",
                                       description="Simulation time", getter=lambda: self.core.time))
        for var in self.core.vars:
            self._register(var)

    def setup_experiment(self, start_time):  # not called by pythonfmu3: enter_initialization_mode asks the binary
        self._start(start_time)

    def do_step(self, current_time, step_size):
        self._step(current_time, step_size)
        return Fmi3StepResult()  # a refusal or a warning already set the call's status (Error, Discard or Warning)

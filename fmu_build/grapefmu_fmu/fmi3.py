"""FMI 3.0 co-simulation slave (pythonfmu3), with units on every variable and the `time`
independent variable. A refused step returns fmi3Error with a logged message, never Fatal."""
from __future__ import annotations

from xml.etree.ElementTree import Element

from pythonfmu3 import Boolean, Fmi3Causality, Fmi3Initial, Fmi3Slave, Fmi3Status, Fmi3Variability, Float64, Int32
from pythonfmu3.fmi3slave import Fmi3StepResult
from pythonfmu3.unit import Unit

from .common import GrapeSlaveMixin, kinds
from .units import BASE_UNITS


class _UnitWithoutBase(Unit):
    """A unit whose SI exponents are not whole numbers (N/m^1.5): FMI allows leaving BaseUnit out."""

    def to_xml(self):
        return Element(self.tag, {"name": self.name})


class GrapeFmi3Slave(GrapeSlaveMixin, Fmi3Slave):
    TYPES = {"real": Float64, "integer": Int32, "boolean": Boolean}
    INITIAL = Fmi3Initial
    KINDS = kinds(Fmi3Causality, Fmi3Variability, Fmi3Initial)
    UNITS = True

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self._setup(kwargs)
        self.time = 0.0
        units = {v.unit for v in self.core.vars if v.unit not in ("", "1")} | {"s"}
        self.register_units([Unit(u, **BASE_UNITS[u]) if BASE_UNITS.get(u) is not None else _UnitWithoutBase(u)
                             for u in sorted(units)])
        self.register_variable(Float64("time", causality=Fmi3Causality.independent,
                                       variability=Fmi3Variability.continuous, unit="s",
                                       description="Simulation time"))
        for var in self.core.vars:
            self._register(var)

    def enter_initialization_mode(self):
        pass

    def exit_initialization_mode(self):
        err = self.core.initialize(self.start_time)
        if err:
            self.log(err, Fmi3Status.error)

    def do_step(self, current_time, step_size):
        err = self.core.step(current_time, step_size)
        if err:
            self.log(err, Fmi3Status.error)
            return Fmi3StepResult(status=Fmi3Status.error)
        self.time = current_time + step_size
        return Fmi3StepResult()

    def _get_fmu_state(self):
        return self.core.get_state() | {"time": self.time}

    def _set_fmu_state(self, state):
        self.time = state.get("time", self.time)
        self.core.set_state(state)

"""What the FMI 2.0 and 3.0 slaves share: the core, the description, and the FMU-state hooks."""
from __future__ import annotations

from pathlib import Path

from grapefmu import __version__

from .core import FmuCore


def kinds(causality, variability, initial) -> dict[tuple[str, bool], dict]:
    """Registration keywords per (causality, is real) from one FMI version's enums (same member names
    in FMI 2.0 and 3.0): inputs and outputs continuous when real, parameters fixed, outputs exact."""
    out = {}
    for real in (True, False):
        var = variability.continuous if real else variability.discrete
        out["input", real] = {"causality": causality.input, "variability": var}
        out["output", real] = {"causality": causality.output, "variability": var, "initial": initial.exact}
        out["parameter", real] = {"causality": causality.parameter, "variability": variability.fixed,
                                  "initial": initial.exact}
    return out


class GrapeSlaveMixin:
    scene_file = "scene.toml"
    TYPES: dict            # per FMI version: the variable class of each type
    KINDS: dict            # per FMI version: kinds(...)
    INITIAL: type          # per FMI version: its `initial` enum
    UNITS = False          # whether the version's variables carry a unit

    def _register(self, var) -> None:
        kw = {"description": var.description, **self._accessors(var.name), **self.KINDS[var.causality, var.type == "real"]}
        if var.channel is not None and var.causality == "output":
            kw["initial"] = getattr(self.INITIAL, var.channel.fmi_initial)
        if self.UNITS and var.type == "real" and var.unit not in ("", "1"):
            kw["unit"] = var.unit
        self.register_variable(self.TYPES[var.type](var.name, **kw))

    def _setup(self, kwargs) -> None:
        self.core = FmuCore(Path(kwargs.get("resources") or ".") / self.scene_file)
        self.description = (f"grapefmu {__version__}: berries on hinged twigs that swing and collide under "
                            f"base excitation; scene '{self.core.scene.name}'")
        self.author = "grapefmu"
        self.version = __version__
        self.start_time = 0.0

    def _accessors(self, name: str) -> dict:
        values = self.core.values
        return {"getter": lambda: values[name], "setter": lambda x: values.__setitem__(name, x)}

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

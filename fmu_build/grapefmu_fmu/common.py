"""What the FMI 2.0 and 3.0 slaves share: the core, the description, and the FMU-state hooks."""
from __future__ import annotations

from pathlib import Path

from grapefmu import __version__

from .core import FmuCore


class GrapeSlaveMixin:
    scene_file = "scene.toml"

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

"""grapefmu: berries on hinged twigs that swing and collide when a gripper moves the rachis."""
from .errors import GrapefmuError, SceneError, SolverError
from .model import Model, Scene
from .scenefile import load_scene, parse_scene

__version__ = "0.1.0"

__all__ = ["GrapefmuError", "Model", "Scene", "SceneError", "SolverError", "__version__", "load_scene",
           "parse_scene", "simulate", "Solver"]


def __getattr__(name):
    # the solver pulls in numba; import it on first use so `grapefmu --help` stays instant
    if name in ("Solver", "simulate"):
        from .solver import api
        return getattr(api, name)
    raise AttributeError(name)

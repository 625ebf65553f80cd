"""The immutable, validated model and scene (what is simulated, not how)."""
from .contact import ContactLaw, hunt_crossley_chi, kelvin_voigt_damping
from .excitation import Excitation
from .model import Berry, ContactPair, Coupling, Model, Scene, SolverSettings, Thresholds
from .scene import load_scene, parse_scene

__all__ = ["Berry", "ContactLaw", "ContactPair", "Coupling", "Excitation", "Model", "Scene", "SolverSettings",
           "Thresholds", "hunt_crossley_chi", "kelvin_voigt_damping", "load_scene", "parse_scene"]

"""The immutable, validated model and scene (what is simulated, not how): pure data, no physics."""
from .contact import ContactLaw, Law, hunt_crossley_chi, kelvin_voigt_damping
from .excitation import Excitation
from .model import Berry, ContactPair, Coupling, Model, ModelArrays, Scene, SolverSettings, Thresholds

__all__ = ["Berry", "ContactLaw", "ContactPair", "Coupling", "Excitation", "Law", "Model", "ModelArrays", "Scene",
           "SolverSettings", "Thresholds", "hunt_crossley_chi", "kelvin_voigt_damping"]

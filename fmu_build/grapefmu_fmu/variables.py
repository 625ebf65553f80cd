"""The FMU's variables for a given model: one set per berry and per contact pair, and no more."""
from __future__ import annotations

from dataclasses import dataclass

from grapefmu.model.model import Model


@dataclass(frozen=True)
class Var:
    name: str
    type: str          # "real", "integer", "boolean"
    causality: str     # "input", "output", "parameter"
    unit: str          # SI symbol as FMI writes it ("" for dimensionless)
    description: str
    exact: bool = False  # output with initial="exact": its start value sets the initial state


def pair_suffix(model: Model, p: int) -> str:
    """The default two-berry scene's single pair has plain names (contact_force); scenes with more pairs
    suffix each with its berries (contact_force_left_right)."""
    return "" if len(model.pairs) == 1 else f"_{model.pair_name(p)}"


def variables(model: Model) -> list[Var]:
    law = model.pairs[0].law.kind if model.pairs else "kelvin-voigt"
    k_unit = "N/m" if law == "kelvin-voigt" else "N/m1.5"
    c_unit = "N.s/m" if law == "kelvin-voigt" else "1"
    v = [Var("base_ax", "real", "input", "m/s2", "Rachis (gripper) acceleration along x, held over the step"),
         Var("base_ay", "real", "input", "m/s2", "Rachis (gripper) acceleration along y, held over the step")]
    for b in model.names:
        v += [Var(f"angle_{b}", "real", "output", "rad", f"Twig angle of berry {b} from hanging (+ toward +x)", True),
              Var(f"angular_velocity_{b}", "real", "output", "rad/s", f"Twig angular velocity of berry {b}", True),
              Var(f"pedicel_force_{b}", "real", "output", "N", f"Pedicel (twig) tension of berry {b}")]
    for p in range(len(model.pairs)):
        s = pair_suffix(model, p)
        pn = model.pair_name(p).replace("_", " and ", 1)
        v += [Var(f"contact_force{s}", "real", "output", "N", f"Normal contact force between {pn}"),
              Var(f"penetration{s}", "real", "output", "m", f"Contact penetration between {pn}"),
              Var(f"in_contact{s}", "boolean", "output", "", f"True while {pn} overlap")]
    v += [Var("collision_count", "integer", "output", "", "Impacts so far (berry pairs coming into contact)"),
          Var("peak_contact_force", "real", "output", "N", "Largest contact force so far"),
          Var("dissipated_energy", "real", "output", "J", "Energy dissipated so far by hinges, coupling and contacts"),
          Var("detachment_risk", "boolean", "output", "",
              "True once any pedicel force has exceeded the scene's detachment force")]
    for b in model.names:
        v += [Var(f"mass_{b}", "real", "parameter", "kg", f"Mass of berry {b}"),
              Var(f"radius_{b}", "real", "parameter", "m", f"Radius of berry {b}"),
              Var(f"twig_length_{b}", "real", "parameter", "m", f"Twig length (hinge to centre) of berry {b}"),
              Var(f"hinge_x_{b}", "real", "parameter", "m", f"Hinge position of berry {b} along the rachis"),
              Var(f"hinge_stiffness_{b}", "real", "parameter", "N.m/rad", f"Torsional hinge stiffness of berry {b}"),
              Var(f"hinge_damping_{b}", "real", "parameter", "N.m.s/rad", f"Torsional hinge damping of berry {b}")]
    v += [Var("coupling_stiffness", "real", "parameter", "N/m", "Coupling (paper's k3) on horizontal separation"),
          Var("coupling_damping", "real", "parameter", "N.s/m", "Coupling damping (paper's c3)"),
          Var("contact_law", "integer", "parameter", "", "Contact law: 0 kelvin-voigt, 1 hertz, 2 hunt-crossley"),
          Var("contact_stiffness", "real", "parameter", k_unit,
              "Contact stiffness: k in N/m (kelvin-voigt) or K in N/m^1.5 (hertz, hunt-crossley)"),
          Var("contact_damping", "real", "parameter", c_unit,
              "Contact damping: c in N.s/m (kelvin-voigt) or chi (hunt-crossley); used when restitution is 0"),
          Var("restitution", "real", "parameter", "1",
              "Target coefficient of restitution; > 0 calibrates the contact damping from it"),
          Var("gravity", "real", "parameter", "m/s2", "Gravitational acceleration"),
          Var("rtol", "real", "parameter", "1", "Relative tolerance of the event-driven solver")]
    return v

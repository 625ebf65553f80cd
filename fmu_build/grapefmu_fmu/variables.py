"""The FMU's variables for a given model.

The full set has one group per angle, per berry and per contact pair; the summary set, the default
for clusters (more than FULL_LIMIT berries or pairs), has only the cluster totals, so a co-simulation
master is not flooded with thousands of variables of idle pairs. Both have the inputs, the totals and
the scene-wide parameters."""
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


FULL_LIMIT = 16
OUTPUT_SETS = ("full", "summary")


def default_outputs(model: Model) -> str:
    return "full" if model.n_berries <= FULL_LIMIT and len(model.pairs) <= FULL_LIMIT else "summary"


def variables(model: Model, outputs: str = "full") -> list[Var]:
    law = model.pairs[0].law.kind if model.pairs else "kelvin-voigt"
    k_unit = "N/m" if law == "kelvin-voigt" else "N/m1.5"
    c_unit = "N.s/m" if law == "kelvin-voigt" else "1"
    full = outputs == "full"
    v = [Var("base_ax", "real", "input", "m/s2", "Rachis (gripper) acceleration along x, held over the step"),
         Var("base_az", "real", "input", "m/s2", "Rachis (gripper) acceleration along z (up), held over the step")]
    for d in model.dof_names if full else ():
        v += [Var(f"angle_{d}", "real", "output", "rad", f"Twig angle {d} (0 hanging for a planar twig)", True),
              Var(f"angular_velocity_{d}", "real", "output", "rad/s", f"Twig angular velocity {d}", True)]
    for b in model.names if full else ():
        v += [Var(f"pedicel_force_{b}", "real", "output", "N", f"Pedicel (twig) tension of berry {b}")]
    for p in range(len(model.pairs)) if full else ():
        s = pair_suffix(model, p)
        pn = model.pair_name(p).replace("_", " and ", 1)
        v += [Var(f"contact_force{s}", "real", "output", "N", f"Normal contact force between {pn}"),
              Var(f"penetration{s}", "real", "output", "m", f"Contact penetration between {pn}"),
              Var(f"in_contact{s}", "boolean", "output", "", f"True while {pn} overlap")]
    v += [Var("collision_count", "integer", "output", "", "Impacts so far (berry pairs coming into contact)"),
          Var("peak_contact_force", "real", "output", "N", "Largest contact force so far"),
          Var("dissipated_energy", "real", "output", "J", "Energy dissipated so far by hinges, coupling and contacts"),
          Var("detachment_risk", "boolean", "output", "",
              "True once any pedicel force has exceeded the scene's detachment force"),
          Var("active_pairs", "integer", "output", "", "Berry pairs in contact now"),
          Var("max_contact_force", "real", "output", "N", "Largest contact force now"),
          Var("max_pedicel_force", "real", "output", "N", "Largest pedicel tension now"),
          Var("berries_over_detachment_force", "integer", "output", "",
              "Berries whose pedicel tension has exceeded the detachment force so far"),
          Var("bruising_impacts", "integer", "output", "",
              "Finished impacts over the bruise force or bruise energy so far")]
    for b in (model.berries if full else ()):
        if b.spherical:
            continue  # a spherical twig's hinge is placed by the cluster generator, not tuned alone
        n = b.name
        v += [Var(f"mass_{n}", "real", "parameter", "kg", f"Mass of berry {n}"),
              Var(f"radius_{n}", "real", "parameter", "m", f"Radius of berry {n}"),
              Var(f"twig_length_{n}", "real", "parameter", "m", f"Twig length (hinge to centre) of berry {n}"),
              Var(f"hinge_x_{n}", "real", "parameter", "m", f"Hinge position of berry {n} along the rachis"),
              Var(f"hinge_stiffness_{n}", "real", "parameter", "N.m/rad", f"Torsional hinge stiffness of berry {n}"),
              Var(f"hinge_damping_{n}", "real", "parameter", "N.m.s/rad", f"Torsional hinge damping of berry {n}")]
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

"""The FMU's variables for a given model: inputs and outputs from grapefmu's output catalogue, plus the
scene parameters a co-simulation user tunes.

The full set has one variable per angle, per berry and per contact pair; the summary set, the default
for clusters (more than PER_PAIR_LIMIT berries or pairs), has only the cluster channels, so a
co-simulation master is not flooded with thousands of variables of idle pairs."""
from __future__ import annotations

from dataclasses import dataclass

from grapefmu.model.model import Model
from grapefmu.results.catalogue import CHANNELS, PER_PAIR_LIMIT, Channel

OUTPUT_SETS = ("full", "summary")
#: the rachis' initial orientation as parameters: fixed-axis roll, pitch, yaw (REP-103, R = Rz(yaw) Ry(pitch) Rx(roll))
ORIENTATION = ("rachis_roll", "rachis_pitch", "rachis_yaw")


@dataclass(frozen=True)
class Var:
    name: str
    type: str          # "real", "integer", "boolean"
    causality: str     # "input", "output", "parameter"
    unit: str          # SI symbol as FMI writes it ("" for dimensionless)
    description: str
    channel: Channel | None = None   # the catalogue channel of an input or output
    element: int = 0                 # its element (angle, berry or pair index)


def default_outputs(model: Model) -> str:
    return "full" if model.n_berries <= PER_PAIR_LIMIT and len(model.pairs) <= PER_PAIR_LIMIT else "summary"


def channel_vars(model: Model, outputs: str = "full") -> list[Var]:
    """The catalogue's FMU channels as variables (per-element channels only in the full set)."""
    out = []
    for c in CHANNELS:
        if not c.fmu or (c.per not in ("cluster", "obstacle") and outputs != "full"):
            continue
        for k, el in enumerate(c.element_names(model)):
            what = f" ({el.replace('_', ' and ', 1) if c.per == 'pair' else el})" if el else ""
            out.append(Var(c.column(el), c.type, c.fmi_causality, c.unit, c.description + what, c, k))
    return out


def variables(model: Model, outputs: str = "full") -> list[Var]:
    berry_pairs = [p for p in model.pairs if p.j < model.n_berries]  # [contact]; obstacles keep their own laws
    law = berry_pairs[0].law.kind if berry_pairs else "kelvin-voigt"
    k_unit = "N/m" if law == "kelvin-voigt" else "N/m1.5"
    c_unit = "N.s/m" if law == "kelvin-voigt" else "1"
    v = channel_vars(model, outputs)
    for d in (model.dof_names if outputs == "full" else ()):
        v += [Var(f"initial_angle_{d}", "real", "parameter", "rad", f"Twig angle {d} at the start time"),
              Var(f"initial_angular_velocity_{d}", "real", "parameter", "rad/s",
                  f"Twig angular velocity {d} at the start time")]
    for b in (model.berries if outputs == "full" else ()):
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
              "Contact damping: c in N.s/m (kelvin-voigt) or chi (hunt-crossley); 0 when restitution sets it"),
          Var("restitution", "real", "parameter", "1",
              "Target coefficient of restitution; > 0 calibrates the contact damping (contact_damping must be 0)"),
          *(Var(name, "real", "parameter", "rad", f"Rachis (gripper) initial {what} about the world {axis} axis "
                "(fixed axes, REP-103)") for name, what, axis in zip(ORIENTATION, ("roll", "pitch", "yaw"), "xyz")),
          Var("gravity", "real", "parameter", "m/s2", "Gravitational acceleration"),
          Var("rtol", "real", "parameter", "1", "Relative tolerance of the event-driven solver")]
    return v

"""What the FMU does, independent of the FMI version and of pythonfmu.

Parameters are collected as numbers, turned into a scene and validated by grapefmu's own scene
checks when initialization ends; each do_step integrates the whole communication step with the
event-driven solver (so results do not depend on the master's step) and refuses, leaving the state
untouched, anything it cannot integrate."""
from __future__ import annotations

import copy
import io
import math
import tomllib
from pathlib import Path

import numpy as np

from grapefmu import GrapefmuError, Solver
from grapefmu.model.contact import LAWS
from grapefmu.model.scene import parse_scene, scene_from_dict
from grapefmu.physics.dynamics import observe
from grapefmu.solver import core
from grapefmu.solver.solver import SolverState

from .variables import OUTPUT_SETS, Var, default_outputs, pair_suffix, variables

MAX_INPUT = 1e3  # m/s², the scene validator's bound on accelerations


OUTPUTS_FILE = "outputs.txt"  # in the resources next to the scene: "full" or "summary"


class FmuCore:
    def __init__(self, scene_path: str | Path):
        scene_path = Path(scene_path)
        self.base_dir = scene_path.parent
        self.doc = tomllib.loads(scene_path.read_text())
        self.scene = parse_scene(scene_path.read_text(), base_dir=self.base_dir, name=scene_path.stem)
        self.model = self.scene.model
        chosen = self.base_dir / OUTPUTS_FILE
        self.outputs = chosen.read_text().strip() if chosen.exists() else default_outputs(self.model)
        if self.outputs not in OUTPUT_SETS:
            raise GrapefmuError(f"{OUTPUTS_FILE}: expected one of {OUTPUT_SETS}, got {self.outputs!r}")
        self.full = self.outputs == "full"
        self.vars: list[Var] = variables(self.model, self.outputs)
        self.bruising = 0
        self.values: dict[str, float | int | bool] = self._start_values()
        self.solver: Solver | None = None
        self.error: str | None = None

    # --- values -----------------------------------------------------------------------------------
    def _start_values(self) -> dict:
        m, sc = self.model, self.scene
        val: dict = {"base_ax": 0.0, "base_az": 0.0}
        if self.full:
            for k, d in enumerate(m.dof_names):
                val.update({f"angle_{d}": sc.angles[k], f"angular_velocity_{d}": sc.angular_velocities[k]})
            for b in m.berries:
                val[f"pedicel_force_{b.name}"] = 0.0
                if not b.spherical:
                    val.update({f"mass_{b.name}": b.mass, f"radius_{b.name}": b.radius,
                                f"twig_length_{b.name}": b.twig_length, f"hinge_x_{b.name}": b.hinge_x,
                                f"hinge_stiffness_{b.name}": b.hinge_stiffness,
                                f"hinge_damping_{b.name}": b.hinge_damping})
            for p in range(len(m.pairs)):
                s = pair_suffix(m, p)
                val.update({f"contact_force{s}": 0.0, f"penetration{s}": 0.0, f"in_contact{s}": False})
        val.update({"active_pairs": 0, "max_contact_force": 0.0, "max_pedicel_force": 0.0,
                    "berries_over_detachment_force": 0, "bruising_impacts": 0})
        law = m.pairs[0].law if m.pairs else None
        cp = m.couplings[0] if m.couplings else None
        val.update({"collision_count": 0, "peak_contact_force": 0.0, "dissipated_energy": 0.0, "detachment_risk": False,
                    "coupling_stiffness": cp.stiffness if cp else 0.0, "coupling_damping": cp.damping if cp else 0.0,
                    "contact_law": law.code if law else 0, "contact_stiffness": law.stiffness if law else 2000.0,
                    "contact_damping": law.damping if law else 0.0,
                    "restitution": (law.restitution or 0.0) if law else 0.0,
                    "gravity": m.gravity, "rtol": sc.solver.rtol})
        return val

    def scene_from_parameters(self):
        """The scene the parameter values describe, checked by the same validator as a TOML file."""
        v = self.values
        doc = copy.deepcopy(self.doc)
        doc.pop("excitation", None)  # the inputs drive the rachis
        for b in doc["berries"] if self.full else ():
            n = b["name"]
            if b.get("kind", "planar") == "spherical":
                b["angle"] = [v[f"angle_{n}_swing"], v[f"angle_{n}_tilt"]]
                b["angular_velocity"] = [v[f"angular_velocity_{n}_swing"], v[f"angular_velocity_{n}_tilt"]]
                continue
            for key in ("mass", "radius", "twig_length", "hinge_x", "hinge_stiffness", "hinge_damping"):
                b[key] = v[f"{key}_{n}"]
            b["angle"] = v[f"angle_{n}"]
            b["angular_velocity"] = v[f"angular_velocity_{n}"]
        if "contact" in doc:
            code = v["contact_law"]
            if not (isinstance(code, int) and 0 <= code < len(LAWS)):
                raise GrapefmuError(f"contact_law: expected 0, 1 or 2, got {code!r}")
            c = {k: doc["contact"][k] for k in ("pairs", "allow_tension") if k in doc["contact"]}
            c.update(law=LAWS[code], stiffness=v["contact_stiffness"])
            if LAWS[code] != "hertz":
                if v["restitution"] > 0:
                    c["restitution"] = v["restitution"]
                else:
                    c["damping"] = v["contact_damping"]
            doc["contact"] = c
        if v["coupling_stiffness"] or v["coupling_damping"]:
            pairs = doc.get("coupling", {}).get("pairs")
            doc["coupling"] = {"stiffness": v["coupling_stiffness"], "damping": v["coupling_damping"],
                               **({"pairs": pairs} if pairs else {})}
        else:
            doc.pop("coupling", None)
        doc["gravity"] = v["gravity"]
        doc.setdefault("solver", {})["rtol"] = v["rtol"]
        doc["solver"]["atol"] = min(doc["solver"].get("atol", 1e-10), v["rtol"] * 1e-2) if v["rtol"] > 0 else 1e-10
        doc["solver"]["method"] = "event"
        return scene_from_dict(doc, self.base_dir, name=self.scene.name)

    def initialize(self, start_time: float = 0.0) -> str | None:
        """Build the solver from the parameters; returns an error message instead of raising."""
        try:
            self.scene = self.scene_from_parameters()
            self.solver = Solver(self.scene)
            self.solver.state.fl[core.T] = start_time
            self.error = None
            self.bruising = 0
            self._update_outputs()
        except GrapefmuError as e:
            self.solver = None
            self.error = f"initialization refused: {e}"
        return self.error

    # --- stepping ---------------------------------------------------------------------------------
    def step(self, t: float, dt: float) -> str | None:
        """Integrate [t, t + dt] with the inputs held. Returns an error message (state unchanged) or None."""
        if self.solver is None:
            return self.error or "do_step before initialization"
        if not (math.isfinite(dt) and dt > 0):
            return f"communication step: expected a finite step > 0 s, got {dt!r}"
        if abs(t - self.solver.t) > 1e-9 * max(1.0, abs(t)):
            return f"currentCommunicationPoint {t!r} s does not continue from the FMU's time {self.solver.t!r} s"
        for name in ("base_ax", "base_az"):
            a = self.values[name]
            if not (isinstance(a, (int, float)) and math.isfinite(a) and abs(a) <= MAX_INPUT):
                return f"input {name} = {a!r}: expected a finite acceleration within ±{MAX_INPUT:g} m/s²; step refused"
        try:
            self.solver.advance(dt, (float(self.values["base_ax"]), float(self.values["base_az"])))
        except GrapefmuError as e:
            return f"step [{t:.9g}, {t + dt:.9g}] s refused: {e}"
        th = self.scene.thresholds
        imp = self.solver.take_impacts()
        self.bruising += int(((imp.peak_force >= th.bruise_force) | (imp.dissipated >= th.bruise_energy)).sum())
        self._update_outputs()
        return None

    def _update_outputs(self) -> None:
        s, m, v = self.solver, self.model, self.values
        S = s.state
        n, d, p = m.n_berries, m.n_dof, len(m.pairs)
        if not hasattr(self, "_obs"):
            sfx = [pair_suffix(m, k) for k in range(p)]
            self._obs = (np.zeros((n, 3)), np.zeros(2 * d + n + 3 * p + 3))
            self._real_names = ([f"angle_{x}" for x in m.dof_names] + [f"angular_velocity_{x}" for x in m.dof_names]
                                + [f"pedicel_force_{b}" for b in m.names] + [f"contact_force{x}" for x in sfx]
                                + [f"penetration{x}" for x in sfx])
            self._bool_names = [f"in_contact{x}" for x in sfx]
        fext, out = self._obs
        held = s._held or (0.0, 0.0)
        observe(S.y, S.mode, S.v_onset, S.smooth, held[0], held[1], s.M, S.peak_force, S.peak_tension, fext, out)
        if self.full:
            vals = out.tolist()
            k = len(self._real_names)
            v.update(zip(self._real_names, vals))
            v.update(zip(self._bool_names, (x > 0.5 for x in vals[k: k + len(self._bool_names)])))
        o = 2 * d + n
        peak_f, peak_t, dissipated = out[-3:].tolist()
        v["active_pairs"] = int(np.count_nonzero(S.mode))
        v["max_contact_force"] = float(out[o: o + p].max(initial=0.0))
        v["max_pedicel_force"] = float(out[2 * d: o].max())
        v["berries_over_detachment_force"] = int(np.count_nonzero(S.peak_tension > self.scene.thresholds.detachment_force))
        v["bruising_impacts"] = self.bruising
        v["collision_count"] = int(S.it[core.N_IMPACTS])
        v["peak_contact_force"] = peak_f
        v["dissipated_energy"] = dissipated
        v["detachment_risk"] = v["detachment_risk"] or peak_t > self.scene.thresholds.detachment_force

    # --- FMU state --------------------------------------------------------------------------------
    def get_state(self) -> dict:
        return {"values": dict(self.values), "solver": self.solver.get_state() if self.solver else None,
                "error": self.error, "bruising": self.bruising}

    def set_state(self, state: dict) -> None:
        self.values.clear()  # in place: the FMI variables' getters and setters hold this dict
        self.values.update(state["values"])
        self.error = state["error"]
        self.bruising = state["bruising"]
        if state["solver"] is not None:
            if self.solver is None:
                self.solver = Solver(self.scene_from_parameters())
            self.solver.set_state(state["solver"])

    @staticmethod
    def state_to_bytes(state: dict) -> bytes:
        """npz without pickles: a serialized state can be stored and read back safely."""
        arrays = {}
        if state["solver"] is not None:
            arrays.update({f"solver.{k}": a for k, a in zip(SolverState._fields, state["solver"])})
        names = sorted(state["values"])
        arrays["value_names"] = np.array(names)
        arrays["value_data"] = np.array([float(state["values"][k]) for k in names])
        arrays["value_kind"] = np.array([type(state["values"][k]).__name__ for k in names])
        arrays["error"] = np.array(state["error"] or "")
        arrays["bruising"] = np.array(state["bruising"])
        buf = io.BytesIO()
        np.savez(buf, **arrays)
        return buf.getvalue()

    @staticmethod
    def state_from_bytes(data: bytes) -> dict:
        z = np.load(io.BytesIO(bytes(data)), allow_pickle=False)
        cast = {"bool": bool, "int": int, "float": float}
        values = {str(n): cast[str(k)](x) for n, x, k in zip(z["value_names"], z["value_data"], z["value_kind"])}
        solver = (SolverState(*(z[f"solver.{k}"].copy() for k in SolverState._fields))
                  if "solver.y" in z.files else None)
        return {"values": values, "solver": solver, "error": str(z["error"]) or None, "bruising": int(z["bruising"])}

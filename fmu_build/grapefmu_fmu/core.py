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
from grapefmu.errors import StateError
from grapefmu.model.contact import LAWS, Law
from grapefmu.scenefile import parse_scene, scene_from_dict
from grapefmu.solver import state as solver_state
from grapefmu.solver.solver import MAX_ACCEL

from .variables import OUTPUT_SETS, Var, default_outputs, variables


OUTPUTS_FILE = "outputs.txt"  # in the resources next to the scene: "full" or "summary"
INPUTS = ("base_ax", "base_az")
INPUT_BOUNDS = {name: MAX_ACCEL for name in INPUTS}  # the largest magnitude each input takes, m/s²
DISCARD, ERROR = 2, 3  # FMI 2 and 3 status codes
#: solver steps one communication step may take: beyond this the step is refused (Discard) in bounded time
STEP_BUDGET = 100_000


class FmuCore:
    def __init__(self, scene_path: str | Path):
        scene_path = Path(scene_path)
        self.base_dir = scene_path.parent
        text = scene_path.read_text(encoding="utf-8")  # whatever the host's locale
        self.doc = tomllib.loads(text)
        self.scene = parse_scene(text, base_dir=self.base_dir, name=scene_path.stem)
        self.model = self.scene.model
        chosen = self.base_dir / OUTPUTS_FILE
        self.outputs = chosen.read_text(encoding="utf-8").strip() if chosen.exists() else default_outputs(self.model)
        if self.outputs not in OUTPUT_SETS:
            raise GrapefmuError(f"{OUTPUTS_FILE}: expected one of {OUTPUT_SETS}, got {self.outputs!r}")
        self.full = self.outputs == "full"
        self.vars: list[Var] = variables(self.model, self.outputs)
        cast = {"real": float, "integer": int, "boolean": bool}
        plan: dict = {}
        for v in self.vars:
            if v.channel is not None and v.causality == "output":
                plan.setdefault(v.channel.name, (v.channel, []))[1].append((v.name, v.element, cast[v.type]))
        self._channel_of = {name: plan[c.name] for c, targets in plan.values() for name, _, _ in targets}
        self._fresh: dict[str, float | int | bool] = {}  # outputs already evaluated on the current state
        self._snap = None  # the solver's snapshot, refreshed when an output is first read after a step
        self._views: dict[str, np.ndarray] = {}  # channels whose value is a view on the state (_use)
        self.values: dict[str, float | int | bool] = self._start_values()
        self.solver: Solver | None = None
        self.error: str | None = None
        self.start_time = 0.0

    # --- values -----------------------------------------------------------------------------------
    def _start_values(self) -> dict:
        """Inputs and outputs start at zero (angles and rates at the scene's initial state, which their start
        values set), parameters at the scene's values."""
        m, sc = self.model, self.scene
        val: dict = {}
        for var in self.vars:
            if var.channel is not None:
                val[var.name] = {"real": 0.0, "integer": 0, "boolean": False}[var.type]
        for k, d in enumerate(m.dof_names if self.full else ()):
            val.update({f"initial_angle_{d}": sc.angles[k], f"initial_angular_velocity_{d}": sc.angular_velocities[k]})
        for b in m.berries if self.full else ():
            if not b.spherical:
                val.update({f"{key}_{b.name}": getattr(b, key) for key in (
                    "mass", "radius", "twig_length", "hinge_x", "hinge_stiffness", "hinge_damping")})
        law = m.pairs[0].law if m.pairs else None
        cp = m.couplings[0] if m.couplings else None
        val.update({"coupling_stiffness": cp.stiffness if cp else 0.0, "coupling_damping": cp.damping if cp else 0.0,
                    "contact_law": int(law.law) if law else int(Law.KELVIN_VOIGT),
                    "contact_stiffness": law.stiffness if law else 2000.0,
                    "contact_damping": law.damping if law and not law.restitution else 0.0,
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
                b["angle"] = [v[f"initial_angle_{n}_swing"], v[f"initial_angle_{n}_tilt"]]
                b["angular_velocity"] = [v[f"initial_angular_velocity_{n}_swing"],
                                         v[f"initial_angular_velocity_{n}_tilt"]]
                continue
            for key in ("mass", "radius", "twig_length", "hinge_x", "hinge_stiffness", "hinge_damping"):
                b[key] = v[f"{key}_{n}"]
            b["angle"] = v[f"initial_angle_{n}"]
            b["angular_velocity"] = v[f"initial_angular_velocity_{n}"]
        if "contact" in doc:
            code = v["contact_law"]
            if not (isinstance(code, int) and 0 <= code < len(LAWS)):
                raise GrapefmuError(f"contact_law: expected 0, 1 or 2, got {code!r}")
            c = {k: doc["contact"][k] for k in ("pairs", "allow_tension") if k in doc["contact"]}
            c.update(law=LAWS[code], stiffness=v["contact_stiffness"])
            e, damping = v["restitution"], v["contact_damping"]
            if e > 0 and damping > 0:
                raise GrapefmuError(f"restitution = {e!r} and contact_damping = {damping!r}: set one of them and "
                                    "leave the other 0 (restitution > 0 calibrates the damping)")
            if LAWS[code] == "hertz" and (e > 0 or damping > 0):
                raise GrapefmuError(f"contact_law = 1 (hertz) has no damping: restitution and contact_damping "
                                    f"must be 0, got {e!r} and {damping!r}")
            if e > 0:
                c["restitution"] = e
            elif LAWS[code] != "hertz":
                c["damping"] = damping
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
            self.start_time = start_time
            self._use(Solver(self.scene, t_start=start_time, max_steps=STEP_BUDGET))
            self.error = None
        except GrapefmuError as e:
            self._use(None)
            self.error = f"initialization refused: {e}"
        return self.error

    # --- stepping ---------------------------------------------------------------------------------
    @property
    def time(self) -> float:
        return self.solver.t if self.solver is not None else self.start_time

    def value_problem(self, name: str, value) -> str | None:
        """Why `value` cannot be set on variable `name`, or None. Inputs are checked here, when they are set;
        parameters together with the scene when initialization ends."""
        kind = type(self.values[name])
        if kind is bool:
            ok = isinstance(value, (bool, int)) and value in (0, 1)
        elif kind is int:
            ok = isinstance(value, int) and not isinstance(value, bool)
        else:
            ok = isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)
        if not ok:
            return f"{name} = {value!r}: expected a finite {kind.__name__}; value refused"
        if name in INPUT_BOUNDS and abs(value) > INPUT_BOUNDS[name]:
            return (f"input {name} = {value!r}: expected an acceleration within ±{INPUT_BOUNDS[name]:g} m/s²; "
                    "value refused")
        return None

    def step(self, t: float, dt: float) -> tuple[int, str] | None:
        """Integrate [t, t + dt] with the inputs held. Returns None, or (FMI status, message) with the state
        unchanged: Error for a request the FMU cannot accept, Discard when the solver could not finish."""
        if self.solver is None:
            return ERROR, self.error or "doStep before exitInitializationMode"
        if not (math.isfinite(dt) and dt > 0):
            return ERROR, f"communication step: expected a finite step > 0 s, got {dt!r}"
        if abs(t - self.solver.t) > 1e-9 * max(1.0, abs(t)):
            return ERROR, f"currentCommunicationPoint {t!r} s does not continue from the FMU's time {self.solver.t!r} s"
        try:
            self.solver.advance(dt, tuple(map(self.values.__getitem__, INPUTS)))
        except GrapefmuError as e:
            return DISCARD, f"step [{t:.9g}, {t + dt:.9g}] s not taken, the FMU keeps its state: {e}"
        self.solver.take_impacts()  # the totals count them; keep the list of finished impacts from growing
        self._stale()
        return None

    def _use(self, solver: Solver | None) -> None:
        """Step `solver` from now on. A channel whose value is a view on the solver's state vector (angles,
        rates) is current after every step without a snapshot: it is kept and read directly."""
        self.solver = solver
        self._views = {}
        if solver is not None:
            snap = solver.snapshot()
            for channel, _ in self._channel_of.values():
                v = channel.value(snap)
                if isinstance(v, np.ndarray) and np.shares_memory(v, solver.state.physical.y):
                    self._views[channel.name] = v
        self._stale()

    def _stale(self) -> None:
        self._fresh = {}
        self._snap = None

    def output(self, name: str):
        """An output's value on the current state. Outputs are evaluated when first read after a step, one
        catalogue channel at a time on one snapshot, so a master that reads a few pays for a few."""
        if name in self._fresh:
            return self._fresh[name]
        if self.solver is None:
            return self.values[name]
        channel, targets = self._channel_of[name]
        v = self._views.get(channel.name)
        if v is None:
            if self._snap is None:
                self._snap = self.solver.snapshot()
            v = channel.value(self._snap)
        v = np.asarray(v)[0].tolist()
        for target, k, cast in targets:
            self._fresh[target] = self.values[target] = cast(v[k] if type(v) is list else v)
        return self.values[name]

    # --- FMU state --------------------------------------------------------------------------------
    def get_state(self) -> dict:
        return {"values": dict(self.values), "solver": self.solver.get_state() if self.solver else None,
                "error": self.error}

    def set_state(self, state: dict) -> None:
        """Restore a state from get_state (or state_from_bytes); anything else is a StateError and changes nothing."""
        values = state["values"]
        if set(values) != set(self.values):
            raise StateError(f"FMU state: variables {sorted(set(values) ^ set(self.values))[:5]} do not match this FMU's")
        for name, x in values.items():
            problem = self.value_problem(name, x) if type(x) is type(self.values[name]) else f"{name}: wrong type"
            if problem:
                raise StateError(f"FMU state: {problem}")
        solver = self.solver
        if state["solver"] is not None:
            solver = solver or Solver(self.scene_from_parameters(), max_steps=STEP_BUDGET)
            solver.set_state(state["solver"])  # refuses before anything changes
        self._use(solver if state["solver"] is not None else None)
        self.values.clear()  # in place: the FMI variables' getters and setters hold this dict
        self.values.update(values)
        self.error = state["error"]

    @staticmethod
    def state_to_bytes(state: dict) -> bytes:
        """npz without pickles: a serialized state can be stored and read back safely."""
        arrays = {}
        if state["solver"] is not None:
            arrays.update({f"solver.{k}": a for k, a in solver_state.flatten(state["solver"]).items()})
        names = sorted(state["values"])
        arrays["value_names"] = np.array(names)
        arrays["value_data"] = np.array([float(state["values"][k]) for k in names])
        arrays["value_kind"] = np.array([type(state["values"][k]).__name__ for k in names])
        arrays["error"] = np.array(state["error"] or "")
        buf = io.BytesIO()
        np.savez(buf, **arrays)
        return buf.getvalue()

    @staticmethod
    def state_from_bytes(data: bytes) -> dict:
        """The state state_to_bytes wrote; anything else is a StateError (set_state then checks the solver
        part against the instance's own)."""
        try:
            z = np.load(io.BytesIO(bytes(data)), allow_pickle=False)
            cast = {"bool": bool, "int": int, "float": float}
            values = {str(n): cast[str(k)](x) for n, x, k in zip(z["value_names"], z["value_data"], z["value_kind"])}
            solver = None
            if any(k.startswith("solver.") for k in z.files):
                solver = solver_state.unflatten({k[len("solver."):]: z[k].copy() for k in z.files
                                                 if k.startswith("solver.")})
            return {"values": values, "solver": solver, "error": str(z["error"]) or None}
        except StateError:
            raise
        except Exception as e:  # noqa: BLE001 - a corrupted buffer fails in many ways inside numpy's reader
            raise StateError(f"serialized FMU state: not one this FMU wrote ({type(e).__name__}: {e})") from None

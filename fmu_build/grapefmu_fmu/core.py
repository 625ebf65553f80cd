"""What the FMU does, independent of the FMI version and of pythonfmu.

Parameters are collected as numbers, turned into a scene and validated by grapefmu's own scene
checks when initialization ends; each do_step integrates the whole communication step with the
event-driven solver (so results do not depend on the master's step) and refuses, leaving the state
untouched, anything it cannot integrate. The inputs are the output catalogue's: the rachis' linear and
angular acceleration, held over the step, and its angular velocity, set at the step's start."""
from __future__ import annotations

import copy
import functools
import io
import math
import operator
import re
import tomllib
from pathlib import Path

import numpy as np

from grapefmu import GrapefmuError, Solver
from grapefmu.errors import SceneError, StateError
from grapefmu.model.contact import LAWS, Law
from grapefmu.model.bounds import bound
from grapefmu.model.model import SolverSettings, off_axis
from grapefmu.physics.excitation import ACCEL_COMPONENTS, accel
from grapefmu.results.catalogue import CHANNELS
from grapefmu.results.trust import overlap_words, pressed_too_deep
from grapefmu.scenefile import parse_scene, scene_from_dict
from grapefmu.solver import state as solver_state
from grapefmu.model.excitation import MAX_ACCEL, MAX_ANGULAR_ACCEL, MAX_ANGULAR_VELOCITY

from .variables import ORIENTATION, OUTPUT_SETS, Var, default_outputs, variables


OUTPUTS_FILE = "outputs.txt"  # in the resources next to the scene: "full" or "summary"
_INPUT_CHANNELS = [c for c in CHANNELS if c.fmu and c.fmi_causality == "input"]
#: the rachis acceleration (ACCEL_COMPONENTS: m/s², rad/s², world frame), held over each communication step
ACCEL_INPUTS = tuple(c.name for c in _INPUT_CHANNELS if c.topic == "rachis/accel")
#: the rachis angular velocity (ω_x, ω_y, ω_z: rad/s, world frame), set at the start of each communication step
OMEGA_INPUTS = tuple(c.name for c in _INPUT_CHANNELS if c.topic == "rachis/twist")
INPUTS = ACCEL_INPUTS + OMEGA_INPUTS
assert len(ACCEL_INPUTS) == len(ACCEL_COMPONENTS) and len(OMEGA_INPUTS) == 3 and len(INPUTS) == len(_INPUT_CHANNELS)
#: what each input is, and the largest magnitude it takes: the solver's own bounds
_KIND = {"m/s2": ("an acceleration", MAX_ACCEL, "m/s²"), "rad/s2": ("an angular acceleration", MAX_ANGULAR_ACCEL, "rad/s²"),
         "rad/s": ("an angular velocity", MAX_ANGULAR_VELOCITY, "rad/s")}
INPUT_KIND = {c.name: _KIND[c.unit] for c in _INPUT_CHANNELS}
INPUT_BOUNDS = {name: kind[1] for name, kind in INPUT_KIND.items()}
#: the angular inputs per world axis x, y, z: (angular acceleration, angular velocity)
ANGULAR_INPUTS = tuple(zip(ACCEL_INPUTS[3:], OMEGA_INPUTS))
OK, WARNING, DISCARD, ERROR, FATAL = range(5)  # fmi2Status and fmi3Status share these codes
#: the FMI phases an FMU state can be taken in (common.py): before, during and after initialization, and after
#: terminate (only a reset, or a state set, leaves it)
PHASES = ("instantiated", "initialization", "step", "terminated")
#: the parameters of the scene's [contact] law
CONTACT_PARAMETERS = ("contact_law", "contact_stiffness", "contact_damping", "restitution")


def held_inputs(excitation, t) -> np.ndarray:
    """The inputs (INPUTS, one row per time of t) that give the FMU `excitation` held from each time of t to the
    next: (a, α) sampled at t, and ω at t as that held α leaves it (world frame, so ω(t_k+1) = ω(t_k) + α_k Δt
    exactly, from the excitation's initial ω). A master that feeds them reproduces a run of the held excitation."""
    t = np.asarray(t, dtype=float)
    a = accel(excitation, t)
    turned = np.cumsum(a[:-1, 3:] * np.diff(t)[:, None], axis=0)
    return np.column_stack([a, np.asarray(excitation.angular_velocity) + np.vstack([np.zeros((1, 3)), turned])])


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
        self._snap = None  # the solver's snapshot, refreshed after a step (_deep) or when an output is first read
        self._deep_pair = None  # the pair _deep_warning last said was pressed too deep
        self._views: dict[str, np.ndarray] = {}  # channels whose value is a view on the state (_use)
        self.values: dict[str, float | int | bool] = self._start_values()
        #: a planar berry's swing plane is the rachis' x–z plane: the world direction of its normal (the rachis' y
        #: axis) once initialization fixes the orientation, about which alone the rachis may turn; else None
        self.plane_normal: tuple[float, float, float] | None = None
        self.input_bounds = self._input_bounds()
        self._held = operator.itemgetter(*ACCEL_INPUTS)
        self._omega = operator.itemgetter(*OMEGA_INPUTS)
        self.solver: Solver | None = None
        self.error: str | None = None
        self.start_time = 0.0

    # --- values -----------------------------------------------------------------------------------
    def _start_values(self) -> dict:
        """Inputs and outputs start at zero (angles and rates at the scene's initial state, which their start
        values set), parameters at the scene's values (the rachis' orientation from its [excitation])."""
        m, sc = self.model, self.scene
        val: dict = {}
        for var in self.vars:
            if var.channel is not None:
                val[var.name] = {"real": 0.0, "integer": 0, "boolean": False}[var.type]
        rpy = self.doc.get("excitation", {}).get("orientation", (0.0, 0.0, 0.0))
        val.update({name: float(x) for name, x in zip(ORIENTATION, rpy)})
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

    def scene_from_parameters(self, values: dict | None = None):
        """The scene the parameter values (this FMU's, or `values`) describe, checked by the same validator as a TOML
        file; an error names the FMU's variable (mass_left), not the scene file's key (berries[0].mass)."""
        v = self.values if values is None else values
        try:
            return self._scene_of(v)
        except SceneError as e:
            name = self._variable_of(e.key)
            if name is None:
                raise
            raise GrapefmuError(f"{name} = {v[name]!r}: {str(e)[len(e.key) + 2:]}") from None

    def _variable_of(self, key: str) -> str | None:
        """The FMU variable a scene-file key is set from, if any (berries[0].mass -> mass_left)."""
        m = re.fullmatch(r"berries\[(\d+)\]\.(\w+)(?:\[(\d)\])?", key)
        if m:
            b = self.model.berries[int(m[1])]
            field = {"angle": "initial_angle", "angular_velocity": "initial_angular_velocity"}.get(m[2], m[2])
            name = f"{field}_{b.name}" + (f"_{('swing', 'tilt')[int(m[3] or 0)]}" if b.spherical else "")
        else:
            name = {"contact.stiffness": "contact_stiffness", "contact.damping": "contact_damping",
                    "contact.restitution": "restitution", "contact.law": "contact_law",
                    "coupling.stiffness": "coupling_stiffness", "coupling.damping": "coupling_damping",
                    "gravity": "gravity", "solver.rtol": "rtol"}.get(key)
        return name if name in self.values else None

    def _scene_of(self, v: dict):
        doc = copy.deepcopy(self.doc)
        # the inputs drive the rachis; the parameters give its initial orientation
        doc["excitation"] = {"kind": "none", "orientation": [v[name] for name in ORIENTATION]}
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
        if "contact" not in doc:  # no contact pairs: the contact parameters act on nothing, so they keep their start
            start = self._start_values()
            changed = [k for k in CONTACT_PARAMETERS if v[k] != start[k]]
            if changed:
                raise GrapefmuError(f"{changed[0]} = {v[changed[0]]!r}: this scene has no [contact] table, so no "
                                    f"contact pairs for {', '.join(CONTACT_PARAMETERS)} to act on; leave them at "
                                    "their start values")
        else:
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
        atol = bound(SolverSettings, "atol")  # rtol·1e-2, kept inside atol's bound (rtol's least, 1e-14, would not be)
        doc["solver"]["atol"] = max(min(doc["solver"].get("atol", 1e-10), v["rtol"] * 1e-2), 10.0 * atol.lo) \
            if v["rtol"] > 0 else 1e-10
        doc["solver"]["method"] = "event"
        try:
            scene = scene_from_dict(doc, self.base_dir, name=self.scene.name)
        except SceneError as e:  # the orientation is checked by the scene's validator: name the parameters
            if not e.key.startswith("excitation.orientation"):
                raise
            why = str(e)[len(e.key) + 2:]
            if e.key == "excitation.orientation":  # a planar scene's swing plane tilted
                raise GrapefmuError(f"{', '.join(f'{k} = {v[k]!r}' for k in ORIENTATION)}: {why}; for planar berries "
                                    f"{ORIENTATION[0]} must be 0") from None
            raise GrapefmuError(f"{ORIENTATION[int(e.key[-2])]}: {why}") from None
        self._refuse_other_pairs(scene.model, v)
        return scene

    def _refuse_other_pairs(self, model, v: dict) -> None:
        """Refuse parameters that change which pairs can touch (a hinge, twig or radius that puts two berries within
        or out of reach of each other): the FMU's outputs name the pairs of the scene it was built from, one per
        element, and a pair more or less would shift every pair's output onto another."""
        built = [(p.i, p.j) for p in self.model.pairs]
        now = [(p.i, p.j) for p in model.pairs]
        if now == built:
            return
        i, j = next(p for p in now + built if (p in now) != (p in built))
        a, b = self.model.body_names[i], self.model.body_names[j]
        start = self._start_values()
        changed = [f"{k} = {v[k]!r}" for k in (f"{q}_{n}" for n in (a, b) for q in ("hinge_x", "twig_length", "radius"))
                   if k in v and v[k] != start[k]]
        what = ", ".join(changed) or "these parameters"
        if (i, j) in now:
            raise GrapefmuError(f"{what}: puts berries '{a}' and '{b}' within reach of each other, a contact pair this "
                                f"FMU was built without (its outputs are for the pairs it was built with); build an "
                                f"FMU from a scene with these values (grapefmu build-fmu)")
        pair = self.model.pair_name(built.index((i, j)))
        raise GrapefmuError(f"{what}: puts berries '{a}' and '{b}' out of each other's reach, which drops their "
                            f"contact pair ({pair}), whose outputs this FMU has; keep them within reach, or build an "
                            "FMU from a scene with these values (grapefmu build-fmu)")

    def _input_bounds(self) -> dict[str, float]:
        """The largest magnitude each input takes: the solver's bound, or 0 for an angular input about a world axis
        that a planar scene's rachis cannot turn about: z before initialization (its swing plane stays vertical),
        then every axis its plane's normal has no component along (x and z at the default orientation). A turn
        about another axis between x and y is refused at doStep (_turn_problem)."""
        planar = not all(b.spherical for b in self.model.berries)
        n = self.plane_normal
        fixed = [k for k in range(3) if (n[k] == 0.0 if n is not None else k == 2)] if planar else []
        zero = {name for k in fixed for name in ANGULAR_INPUTS[k]}
        return {name: 0.0 if name in zero else bound for name, bound in INPUT_BOUNDS.items()}

    def initialize(self, start_time: float = 0.0) -> str | None:
        """Build the solver from the parameters; returns an error message instead of raising."""
        try:
            self.scene = self.scene_from_parameters()
            self.start_time = start_time
            self._use(Solver(self.scene, t_start=start_time, driven=True))
            self.error = None
        except GrapefmuError as e:
            self._use(None)
            self.error = f"initialization refused: {e}"
        return self.error

    # --- stepping ---------------------------------------------------------------------------------
    @property
    def time(self) -> float:
        return self.solver.t if self.solver is not None else self.start_time

    def value_problem(self, name: str, value, bounds: dict[str, float] | None = None) -> str | None:
        """Why `value` cannot be set on variable `name`, or None. Inputs are checked here, when they are set, within
        `bounds` (default input_bounds); parameters together with the scene when initialization ends."""
        kind = type(self.values[name])
        if kind is bool:
            ok = isinstance(value, (bool, int)) and value in (0, 1)
        elif kind is int:
            ok = isinstance(value, int) and not isinstance(value, bool)
        else:
            ok = isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)
        bound = (self.input_bounds if bounds is None else bounds).get(name)
        if not ok and not (bound is not None and type(value) is float):  # an input's NaN or ±inf: its range says why
            return f"{name} = {value!r}: expected a finite {kind.__name__}; value refused"
        if bound is not None and not abs(value) <= bound:
            what, _, unit = INPUT_KIND[name]
            if bound == 0.0:
                return f"input {name} = {value!r}: {self._planar_turn()}; value refused"
            return f"input {name} = {value!r}: expected {what} within ±{bound:g} {unit}; value refused"
        return None

    def _planar_turn(self) -> str:
        """Why a planar scene refuses a turn."""
        n = self.plane_normal
        axis = f"{tuple(round(c, 6) for c in n)} (world)" if n is not None else "(horizontal: set by rachis_yaw)"
        zero = ", ".join(name for name, bound in self.input_bounds.items() if bound == 0.0)
        return (f"this scene has planar berries, which swing in the rachis' x–z plane, so the rachis may turn only "
                f"about its y axis {axis}: {zero} must be 0 (use spherical berries for any rotation)")

    def _turn_problem(self, alpha: tuple, omega: tuple, n: tuple | None = None) -> str | None:
        """Why a planar scene (plane_normal set, or its normal n) cannot take this held angular acceleration and
        angular velocity (about an axis other than its plane's normal), or None: the solver's own check, made here so
        the step is refused (Error) rather than attempted (Discard)."""
        n = self.plane_normal if n is None else n
        for names, w in zip((ACCEL_INPUTS[3:], OMEGA_INPUTS), (alpha, omega)):
            if off_axis(w, n):
                return (f"inputs {', '.join(f'{k} = {x!r}' for k, x in zip(names, w))}: not along the rachis' y axis "
                        f"{tuple(round(c, 6) for c in n)} (world), the normal of this scene's planar berries' swing "
                        "plane, the only axis the rachis may turn about (use spherical berries for any rotation)")
        return None

    def step(self, t: float, dt: float) -> tuple[int, str] | None:
        """Integrate [t, t + dt] with the accelerations held and the rachis' angular velocity set to the ω inputs
        at t. Returns None, or (FMI status, message): Error for a request the FMU cannot accept and Discard when the
        solver could not finish, the state unchanged; Warning, the step taken, when it pressed a pair past the depth
        any contact law holds at (_deep_warning)."""
        if self.solver is None:
            return ERROR, self.error or "doStep before exitInitializationMode"
        if not (math.isfinite(dt) and dt > 0):
            return ERROR, f"communication step: expected a finite step > 0 s, got {dt!r}"
        if not (math.isfinite(t) and abs(t - self.solver.t) <= 1e-9 * max(1.0, abs(t))):
            return ERROR, f"currentCommunicationPoint {t!r} s does not continue from the FMU's time {self.solver.t!r} s"
        held, omega = self._held(self.values), self._omega(self.values)
        if self.plane_normal is not None and (held[3] or held[4] or held[5] or omega[0] or omega[1] or omega[2]):
            problem = self._turn_problem(held[3:], omega)
            if problem:
                return ERROR, f"step [{t:.9g}, {t + dt:.9g}] s refused, the FMU keeps its state: {problem}"
        try:
            self.solver.advance(dt, held, omega)
        except GrapefmuError as e:
            return DISCARD, f"step [{t:.9g}, {t + dt:.9g}] s not taken, the FMU keeps its state: {e}"
        self.solver.take_impacts()  # the totals count them; keep the list of finished impacts from growing
        self._stale()
        return self._deep_warning(t + dt)

    def _deep(self) -> tuple[int, int, float, float] | None:
        """The pair pressed past the depth any contact law holds at now (results/trust.py, as a run's warnings and the
        ROS node's diagnostics judge it), on the snapshot the outputs are then read from. Only a pair in contact can
        be (or one evaluated inline under step control): with none, no snapshot (0.4 µs instead of about 5)."""
        if not self.solver.touching:
            return None
        self._snap = self.solver.snapshot()
        return pressed_too_deep(self.solver.model, self._snap.observation.penetration)

    def _deep_warning(self, t: float) -> tuple[int, str] | None:
        """Warning when the state at t has a pair pressed too deep (_deep): an FMU has no other way to tell its host
        that its outputs stopped being physical. Once as a pair gets there (the deepest one), again only when another
        pair becomes the deepest or the pair comes back within the bound first."""
        hit = self._deep()
        was, self._deep_pair = self._deep_pair, None if hit is None else hit[1]
        if hit is None or hit[1] == was:
            return None
        return WARNING, f"step to t = {t:.9g} s taken, but {overlap_words(self.solver.model, *hit[1:], t)}"

    def _use(self, solver: Solver | None) -> None:
        """Step `solver` from now on. A channel whose value is a view on the solver's state vector (angles,
        rates) is current after every step without a snapshot: it is kept and read directly. A new solver's
        scene also says which turns the inputs may ask for (plane_normal, input_bounds)."""
        if solver is not self.solver:
            n = solver.model.plane_normal(solver.scene.excitation) if solver is not None else None
            self.plane_normal = None if n is None else tuple(float(c) for c in n)
            self.input_bounds = self._input_bounds()
        self.solver = solver
        self._views = {}
        if solver is not None:
            snap = solver.snapshot()
            for channel, _ in self._channel_of.values():
                v = channel.value(snap)
                if isinstance(v, np.ndarray) and np.shares_memory(v, solver.state.physical.y):
                    self._views[channel.name] = v
        self._stale()
        self._deep_pair = None if solver is None or (hit := self._deep()) is None else hit[1]  # _deep_warning

    def _stale(self) -> None:
        self._fresh = {}
        self._snap = None

    def output(self, name: str):
        """An output's value on the current state. Outputs are evaluated when first read after a step, one
        catalogue channel at a time on one snapshot, so a master that reads a few pays for a few."""
        if name in self._fresh:
            return self._fresh[name]
        channel, targets = self._channel_of[name]
        if self.solver is None:  # Initialization Mode: the state the parameters set so far give (FMI's InitialUnknowns)
            snap = self._initial_snapshot()
            if snap is None:
                return self.values[name]
            v = np.asarray(channel.value(snap))[0].tolist()
            for target, k, cast in targets:
                self.values[target] = cast(v[k] if type(v) is list else v)
            return self.values[name]
        v = self._views.get(channel.name)
        if v is None:
            if self._snap is None:
                self._snap = self.solver.snapshot()
            v = channel.value(self._snap)
        v = np.asarray(v)[0].tolist()
        for target, k, cast in targets:
            self._fresh[target] = self.values[target] = cast(v[k] if type(v) is list else v)
        return self.values[name]

    def _initial_snapshot(self):
        """The start state of the parameters as they are now (None while they cannot make one), taken again only when
        a parameter changes: what the outputs read before initialization ends. Nothing may raise from a getter."""
        key = tuple(self.values[k] for k in self._parameters)
        if getattr(self, "_probe_key", None) != key:
            try:
                self._probe = Solver(self.scene_from_parameters(), t_start=self.start_time, driven=True).snapshot()
            except Exception:  # noqa: BLE001 - parameters the validator refuses, or anything else: the last values stand
                self._probe = None
            self._probe_key = key
        return self._probe

    # --- FMU state --------------------------------------------------------------------------------
    def get_state(self, phase: str) -> dict:
        """The whole FMU: values, solver state, error and the FMI phase (`phase`: PHASES) it was taken in."""
        return {"values": dict(self.values), "solver": self.solver.get_state() if self.solver else None,
                "error": self.error, "phase": phase}

    def set_state(self, state: dict) -> None:
        """Restore a state from get_state (or state_from_bytes); anything else is a StateError and changes nothing.
        A state taken after initialization carries its solver: its parameters must give a scene the solver state
        belongs to (its fingerprint), whatever this instance's parameters are now (another instance's state
        brings its own yaw or initial angles; one whose parameters were altered is refused)."""
        values = state["values"]
        if set(values) != set(self.values):
            raise StateError(f"FMU state: variables {sorted(set(values) ^ set(self.values))[:5]} do not match this FMU's")
        # inputs within the solver's bounds here; the turns a planar scene takes depend on the state's own orientation
        # parameters (another instance's yaw), judged below once its solver says which axis that is
        bounds = INPUT_BOUNDS if state.get("solver") is not None else None
        for name, x in values.items():
            problem = self.value_problem(name, x, bounds) if type(x) is type(self.values[name]) else \
                f"{name}: wrong type"
            if problem:
                raise StateError(f"FMU state: {problem}")
        phase = state.get("phase")
        if phase not in PHASES or (phase != "terminated" and (state["solver"] is not None) != (phase == "step")):
            raise StateError(f"FMU state: phase {state.get('phase')!r} does not fit its solver state")
        solver = None
        if state["solver"] is not None:
            same = self.solver is not None and all(values[k] == self.values[k] for k in self._parameters)
            solver = self.solver if same else Solver(self.scene_from_parameters(values), driven=True)
            n = solver.model.plane_normal(solver.scene.excitation)
            problem = n and self._turn_problem(self._held(values)[3:], self._omega(values), tuple(map(float, n)))
            if problem:
                raise StateError(f"FMU state: {problem}")
            solver.set_state(state["solver"])  # refuses before anything changes
        self._use(solver)
        if solver is not None:
            self.scene = solver.scene
        self.values.clear()  # in place: the FMI variables' getters and setters hold this dict
        self.values.update(values)
        self.error = state["error"]

    @functools.cached_property
    def _parameters(self) -> list[str]:
        return [v.name for v in self.vars if v.causality == "parameter"]

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
        arrays["phase"] = np.array(state["phase"])
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
            bad = [str(n) for n, x, k in zip(z["value_names"], z["value_data"], z["value_kind"])
                   if str(k) != "float" and x != cast[str(k)](x)]  # an integer or a flag stored as 2.7
            if bad:
                raise StateError(f"serialized FMU state: {bad[0]} is not a whole number")
            solver = None
            if any(k.startswith("solver.") for k in z.files):
                solver = solver_state.unflatten({k[len("solver."):]: z[k].copy() for k in z.files
                                                 if k.startswith("solver.")})
            return {"values": values, "solver": solver, "error": str(z["error"]) or None, "phase": str(z["phase"])}
        except StateError:
            raise
        except Exception as e:  # noqa: BLE001 - a corrupted buffer fails in many ways inside numpy's reader
            raise StateError(f"serialized FMU state: not one this FMU wrote ({type(e).__name__}: {e})") from None

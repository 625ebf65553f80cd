"""Read a scene from TOML, validating every value (one clear error naming the key and range)."""
from __future__ import annotations

import math
import re
import tomllib
from importlib import resources
from pathlib import Path
from collections.abc import Callable
from typing import Any

import numpy as np

from ..errors import SceneError
from ..model import excitation as exc
from . import validate as v
from ..model.bounds import Bound, bound
from ..model.contact import (EFFECTIVE_MODULUS, LAW_BOUNDS, LAWS, RESTITUTION, ContactLaw, Law, hertz_stiffness,
                             hunt_crossley_chi, kelvin_voigt_damping, refuses_tension)
from ..model.model import (ANGLE, ANGULAR_VELOCITY, CONTACT_LOCATIONS, INTEGRATORS, MAX_OVERLAP_FRACTION, METHODS,
                           OBSTACLE_KINDS, RACHIS_FRAME, Berry, ContactPair, Coupling, Model, Obstacle, Scene,
                           SolverSettings, Thresholds)
from .budget import check_state

NAME_RE = re.compile(r"^[A-Za-z_][A-Za-z0-9_]{0,31}$")
#: scene and sweep files are a few kB (a 300-berry cluster is about 100 kB); a larger file is a wrong path
MAX_FILE_BYTES = 64 * 2**20

TOP_KEYS = {"name", "gravity", "berries", "contact", "coupling", "obstacles", "excitation", "solver", "thresholds"}
BERRY_KEYS = {"name", "mass", "radius", "twig_length", "hinge_x", "hinge", "hinge_stiffness", "hinge_damping",
              "angle", "angular_velocity", "kind", "azimuth", "rest_angles"}
CONTACT_KEYS = {"law", "stiffness", "effective_modulus", "damping", "restitution", "allow_tension", "pairs"}
COUPLING_KEYS = {"stiffness", "damping", "pairs"}
#: each obstacle kind's own keys (required first), besides name, kind, attached, the law's and the thresholds'
OBSTACLE_SHAPE_KEYS = {"plane": ("point", "normal"), "box": ("centre", "size", "yaw"), "capsule": ("ends", "radius")}
OBSTACLE_KEYS = {"name", "kind", "attached", "bruise_force", "bruise_energy"} | (CONTACT_KEYS - {"pairs"})
#: the rachis' initial orientation ([roll, pitch, yaw], rad, fixed axes) and angular velocity ([ω_x, ω_y, ω_z],
#: rad/s, world frame): any excitation but a pose table (whose first row gives them) may set them
START_KEYS = {"orientation", "angular_velocity"}
EXCITATION_KEYS = {
    "none": {"kind"} | START_KEYS,
    "constant": {"kind", "accel", "angular_accel"} | START_KEYS,
    "impulse": {"kind", "peak", "angular_peak", "start", "duration"} | START_KEYS,
    "sine": {"kind", "amplitude", "angular_amplitude", "frequency", "start", "duration"} | START_KEYS,
    "sweep": {"kind", "amplitude", "angular_amplitude", "f_start", "f_stop", "start", "duration"} | START_KEYS,
    "pick-and-place": {"kind", "moves", "start", "jerk_fraction"} | START_KEYS,
    "csv": {"kind", "file", "text", "hold", "after"} | START_KEYS,
    "pose-table": {"kind", "file", "text"},
}
SOLVER_KEYS = {"method", "rtol", "atol", "t_end", "output_interval", "fixed_step", "zeno_window", "zeno_max_events",
               "max_steps", "contact_location", "islands", "integrator"}
THRESHOLD_KEYS = {"detachment_force", "bruise_force", "bruise_energy", "fatigue_fraction"}


def default_scene_path() -> Path:
    """The packaged default scene: the paper's dual system with Kyoho-like berries (docs/parameters.md)."""
    return Path(str(resources.files("grapefmu") / "scenes" / "default.toml"))


def read_text(path: str | Path, what: str = "scene file", key: str | None = None) -> str:
    """A small UTF-8 text file; a missing, unreadable, oversized or non-UTF-8 file is a SceneError naming it (on
    `key` with the path in its message, for a file a scene names; else on the path)."""
    path = Path(path)

    def refused(why: str) -> SceneError:
        return SceneError(key, f"{path}: {why}") if key else SceneError(str(path), why)
    try:
        with open(path, "rb") as fh:
            data = fh.read(MAX_FILE_BYTES + 1)
    except OSError as e:
        raise refused(f"cannot read {what}: {e.strerror or e}") from None
    except ValueError:  # a NUL in the path, which no file name holds
        raise refused(f"cannot read {what}: a file name holds no NUL character") from None
    if len(data) > MAX_FILE_BYTES:
        raise refused(f"a {what} of at most {MAX_FILE_BYTES // 2**20} MiB is expected; this one is larger")
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as e:
        raise refused(f"a {what} must be UTF-8 text; byte {data[e.start]:#04x} at offset {e.start} is not") from None


def loads_toml(text: str, where: str = "<toml>") -> dict[str, Any]:
    """TOML text as a document; every way it can be malformed is a SceneError naming `where`."""
    try:
        return tomllib.loads(text)
    except RecursionError:
        raise SceneError(where, "arrays or tables are nested too deeply to read (a few hundred levels at most)") from None
    except ValueError as e:  # TOMLDecodeError, and integers of more than 4300 digits
        raise SceneError(where, f"not valid TOML: {e}") from None


def load_scene(path: str | Path) -> Scene:
    path = Path(path)
    text = read_text(path)
    return scene_from_dict(loads_toml(text, str(path)), path.parent, source=text, name=path.stem)


def parse_scene(text: str, base_dir: Path | None = None, name: str = "scene") -> Scene:
    return scene_from_dict(loads_toml(text), base_dir or Path.cwd(), source=text, name=name)


def scene_from_dict(doc: dict[str, Any], base_dir: Path, source: str = "", name: str = "scene") -> Scene:
    v.no_unknown_keys("", doc, TOP_KEYS)
    name = doc.get("name", name)
    if not isinstance(name, str):
        raise SceneError("name", f"expected a string, got {v.show(name)}")
    gravity = v.within("gravity", doc.get("gravity", Model.gravity), bound(Model, "gravity"))
    berries, angles, rates = _berries(doc.get("berries"))
    pairs, pruned = _contact(doc.get("contact"), berries) if "contact" in doc else ([], 0)
    couplings = _coupling(doc["coupling"], berries) if "coupling" in doc else ()
    thresholds = _thresholds(doc.get("thresholds", {}))
    obstacles, touching = _obstacles(doc["obstacles"], berries, thresholds) if "obstacles" in doc else ([], [])
    model = Model(tuple(berries), tuple(pairs) + tuple(touching), tuple(couplings), gravity, pruned, tuple(obstacles))
    _distinct_names(model)
    solver = _solver(doc.get("solver", {}))
    check_state(len(model.pairs), solver.zeno_max_events)  # values in range that together would not fit
    excitation = _excitation(doc.get("excitation", {"kind": "none"}), base_dir, solver.t_end)
    if not source:
        from .toml_out import dumps
        source = dumps({"name": name, **{k: v for k, v in doc.items() if k != "name"}})
    scene = Scene(model, tuple(angles), tuple(rates), excitation, solver, thresholds, source, name)
    _check_overlap(scene)
    return scene


def _berries(raw: Any) -> tuple[list[Berry], list[float], list[float]]:
    if not isinstance(raw, list) or not raw:
        raise SceneError("berries", "expected at least one [[berries]] table")
    berries, angles, rates, seen = [], [], [], set()
    for n, b in enumerate(raw):
        key = f"berries[{n}]"
        v.table(key, b)
        v.no_unknown_keys(key, b, BERRY_KEYS)
        for req in ("name", "mass", "radius", "twig_length"):
            if req not in b:
                raise SceneError(f"{key}.{req}", "missing (required)")
        if ("hinge_x" in b) == ("hinge" in b):
            raise SceneError(f"{key}.hinge", "give hinge_x (on the rod) or hinge = [x, y, z], exactly one")
        nm = _name(key, b["name"], seen)
        mass, radius, length = (v.within(f"{key}.{f}", b[f], bound(Berry, f)) for f in ("mass", "radius", "twig_length"))
        if "hinge_x" in b:
            hinge = (v.within(f"{key}.hinge_x", b["hinge_x"], bound(Berry, "hinge_x")), 0.0, 0.0)
        else:
            hinge = v.vector(f"{key}.hinge", b["hinge"], 3, bound(Berry, "hinge_x"))
        kh, ch = (v.within(f"{key}.{f}", b.get(f, 0.0), bound(Berry, f)) for f in ("hinge_stiffness", "hinge_damping"))
        spherical = v.choice(f"{key}.kind", b.get("kind", "planar"), ("planar", "spherical")) == "spherical"
        nd = 2 if spherical else 1
        if not spherical:
            for k in ("azimuth", "rest_angles"):
                if k in b:
                    raise SceneError(f"{key}.{k}", "only for kind = \"spherical\" berries")
        azimuth = v.within(f"{key}.azimuth", b.get("azimuth", 0.0), bound(Berry, "azimuth"))
        rest = v.vector(f"{key}.rest_angles", b.get("rest_angles", [0.0, 0.0]), 2, bound(Berry, "rest_angles"))
        q = _angles(f"{key}.angle", b.get("angle", [0.0] * nd if spherical else 0.0), nd, ANGLE)
        w = _angles(f"{key}.angular_velocity", b.get("angular_velocity", [0.0] * nd if spherical else 0.0), nd,
                    ANGULAR_VELOCITY)
        berry = Berry(nm, mass, radius, length, hinge[0], kh, ch, hinge[1], hinge[2], spherical, azimuth, rest)
        why = berry.refusal(key) or berry.refuses_swing(f"{key}.angle[0]", "swing", q[0])
        if why:
            raise SceneError(*why)
        angles.extend(q)
        rates.extend(w)
        berries.append(berry)
    return berries, angles, rates


def _name(key: str, raw: Any, seen: set[str]) -> str:
    """A body's name: an identifier no other berry or obstacle has (it names columns, variables, topics)."""
    if not isinstance(raw, str) or not NAME_RE.match(raw):
        raise SceneError(f"{key}.name", f"expected an identifier of letters, digits and _ (at most 32), got {v.show(raw)}")
    if raw in seen:
        raise SceneError(f"{key}.name", f"{raw!r} already names a berry or an obstacle")
    seen.add(raw)
    return raw


def _distinct_names(model: Model) -> None:
    """Refuse names that combine into another's: a berry's TF frames (rachis, <berry>, <berry>_hinge:
    recording/frames.py), its angles (<berry>, or <berry>_swing and _tilt) and a pair's name (<a>_<b>) each name a
    frame, a column, a topic or an FMU variable, and two alike write one over the other (berries a, b_c, a_b and c
    give pairs a_b_c twice)."""
    nb, bodies = model.n_berries, model.body_names

    def key(k: int) -> str:
        return f"berries[{k}].name" if k < nb else f"obstacles[{k - nb}].name"

    kinds = {"frame": [(RACHIS_FRAME, None)] + [(f, k) for k, fs in enumerate(model.frame_names) for f in fs],
             "angle": list(zip(model.dof_names, (k for k, b in enumerate(model.berries) for _ in range(b.ndof)))),
             "contact pair": [(model.pair_name(p), max(pr.i, pr.j)) for p, pr in enumerate(model.pairs)]}
    for what, named in kinds.items():
        seen: dict[str, int | None] = {}
        for name, k in named:
            if name in seen and seen[name] is None:
                raise SceneError(key(k), f"{name!r} names the rachis' frame; rename the berry")
            if name in seen:
                raise SceneError(key(k), f"{bodies[k]!r} gives the {what} name {name!r}, which {bodies[seen[name]]!r} "
                                 "gives too (names joined by _ can make another's); rename one")
            seen[name] = k


def _angles(key: str, raw: Any, nd: int, b: Bound) -> tuple[float, ...]:
    """One number for a planar berry, [swing, tilt] for a spherical one."""
    if nd == 1:
        return (v.within(key, raw, b),)
    return v.vector(key, raw, 2, b)


def _within_reach(a: Berry, b: Berry) -> bool:
    """Whether two berries can ever touch: the rachis is rigid, so hinges keep their distance, and
    berries farther apart than l_i + l_j + r_i + r_j at the hinges never meet."""
    return _hinge_distance(a, b) <= _reach(a) + _reach(b)


def _reach(b: Berry) -> float:
    return b.twig_length + b.radius


def _hinge_distance(a: Berry, b: Berry) -> float:
    return math.dist((a.hinge_x, a.hinge_y, a.hinge_z), (b.hinge_x, b.hinge_y, b.hinge_z))


def _all_pairs(berries: list[Berry]) -> list[tuple[int, int]]:
    """Every pair within reach, found along the sorted x axis so a long row is not an N² search."""
    reach = 2 * max((_reach(b) for b in berries), default=0.0)
    order = sorted(range(len(berries)), key=lambda i: berries[i].hinge_x)
    out = []
    for a, i in enumerate(order):
        for j in order[a + 1:]:
            if berries[j].hinge_x - berries[i].hinge_x > reach:
                break
            if _within_reach(berries[i], berries[j]):
                out.append((min(i, j), max(i, j)))
    return sorted(out)


def _pair_list(key: str, raw: Any, berries: list[Berry], default: list[tuple[int, int]]) -> list[tuple[int, int]]:
    if raw is None:
        return default
    index = {b.name: i for i, b in enumerate(berries)}
    if not isinstance(raw, list):
        raise SceneError(key, "expected a list of [name, name] pairs")
    out = []
    for n, p in enumerate(raw):
        if not (isinstance(p, list) and len(p) == 2 and all(isinstance(s, str) for s in p)):
            raise SceneError(f"{key}[{n}]", f"expected [name, name], got {v.show(p)}")
        for s in p:
            if s not in index:
                raise SceneError(f"{key}[{n}]", f"unknown berry {v.show(s)}; berries: {v.show(', '.join(index))}")
        i, j = index[p[0]], index[p[1]]
        if i == j:
            raise SceneError(f"{key}[{n}]", "a berry cannot pair with itself")
        pr = (min(i, j), max(i, j))
        if pr in out:
            raise SceneError(f"{key}[{n}]", f"duplicate pair {p!r}")
        out.append(pr)
    return out


def _contact(raw: Any, berries: list[Berry]) -> tuple[list[ContactPair], int]:
    """The contact pairs (only those that can ever touch) and how many listed or possible pairs were left out."""
    key = "contact"
    v.table(key, raw)
    v.no_unknown_keys(key, raw, CONTACT_KEYS)
    make = _law_of(key, raw)
    listed = _pair_list(f"{key}.pairs", raw.get("pairs"), berries, _all_pairs(berries))
    kept = [(i, j) for i, j in listed if _within_reach(berries[i], berries[j])]
    possible = len(listed) if raw.get("pairs") is not None else len(berries) * (len(berries) - 1) // 2
    pairs = []
    for i, j in kept:
        bi, bj = berries[i], berries[j]
        pairs.append(ContactPair(i, j, make(bi.mass * bj.mass / (bi.mass + bj.mass), bi.radius, bj.radius)))
    return pairs, possible - len(kept)


def _law_of(key: str, raw: dict) -> Callable[[float, float, float], ContactLaw]:
    """The contact law a [contact] or [[obstacles]] table asks for, checked once, as a function of what the
    pair adds (effective mass kg, radii m: a restitution or an effective modulus depends on them)."""
    law = v.choice(f"{key}.law", raw.get("law", "kelvin-voigt"), LAWS)
    clamp = not v.boolean(f"{key}.allow_tension", raw.get("allow_tension", False))
    why = refuses_tension(law, clamp)
    if why:
        raise SceneError(f"{key}.allow_tension", why)
    if "damping" in raw and "restitution" in raw:
        raise SceneError(f"{key}.restitution", "give damping or restitution, not both")
    if law != "kelvin-voigt" and "stiffness" in raw and "effective_modulus" in raw:
        raise SceneError(f"{key}.effective_modulus", "give stiffness or effective_modulus, not both")
    if law == "kelvin-voigt" and "effective_modulus" in raw:
        raise SceneError(f"{key}.effective_modulus", "only for the hertz and hunt-crossley laws")
    if law == "hertz" and ("damping" in raw or "restitution" in raw):
        raise SceneError(f"{key}.{'damping' if 'damping' in raw else 'restitution'}",
                         "the hertz law is elastic; use hunt-crossley for a damped Hertz contact")
    e = v.within(f"{key}.restitution", raw["restitution"], RESTITUTION) if "restitution" in raw else None
    bounds = LAW_BOUNDS[Law.from_label(law)]
    if law == "kelvin-voigt":  # a damping from e stays in its bound: c = 2ζ√(k m*) ≤ 2√(10⁹ N/m · 10 kg)
        k = v.within(f"{key}.stiffness", raw.get("stiffness", 2000.0), bounds["stiffness"])
        c = None if e is not None else v.within(f"{key}.damping", raw.get("damping", 0.0), bounds["damping"])
        return lambda m_eff, r_i, r_j: ContactLaw(law, k, kelvin_voigt_damping(e, k, m_eff) if c is None else c,
                                                  clamp, e)
    emod = (v.within(f"{key}.effective_modulus", raw["effective_modulus"], EFFECTIVE_MODULUS)
            if "effective_modulus" in raw else None)
    k = None if emod is not None else v.within(f"{key}.stiffness", raw.get("stiffness", 1.1e5), bounds["stiffness"])
    c = 0.0 if law == "hertz" else hunt_crossley_chi(e) if e is not None else \
        v.within(f"{key}.damping", raw.get("damping", 0.0), bounds["damping"])
    if not bounds["damping"].holds(c):
        raise SceneError(f"{key}.restitution", f"{e!r} needs χ = {c:.4g}, outside the {law} law's damping "
                         f"({bounds['damping'].allowed}); give a larger restitution")
    return lambda m_eff, r_i, r_j: ContactLaw(law, hertz_stiffness(emod, r_i, r_j) if k is None else k, c, clamp, e)


def _obstacles(raw: Any, berries: list[Berry], thresholds: Thresholds) -> tuple[list[Obstacle], list[ContactPair]]:
    """[[obstacles]]: planes, boxes and capsules fixed in the world or attached to the gripper, each with its
    contact law and bruise thresholds, and a contact pair of every berry with every obstacle (the broad phase
    watches only the near ones)."""
    if not isinstance(raw, list):
        raise SceneError("obstacles", "expected [[obstacles]] tables")
    out, pairs, seen = [], [], {b.name for b in berries}
    for n, o in enumerate(raw):
        key = f"obstacles[{n}]"
        v.table(key, o)
        kind = v.choice(f"{key}.kind", o.get("kind", "plane"), OBSTACLE_KINDS)
        shape = OBSTACLE_SHAPE_KEYS[kind]
        v.no_unknown_keys(key, o, OBSTACLE_KEYS | set(shape))
        for req in ("name", *shape[:2]):
            if req not in o:
                raise SceneError(f"{key}.{req}", f"missing (required for kind = {kind!r})")
        nm = _name(key, o["name"], seen)
        attached = v.choice(f"{key}.attached", o.get("attached", "world"), ("world", "gripper")) == "gripper"
        point = bound(Obstacle, "point")
        if kind == "plane":  # any length: made unit here
            normal = np.array(v.vector(f"{key}.normal", o["normal"], 3, Bound(-1e3, 1e3)))
            length = float(np.linalg.norm(normal))
            if not length > 1e-9:
                raise SceneError(f"{key}.normal", "expected a non-zero vector [x, y, z] pointing out of the solid")
            shape_of = {"point": v.vector(f"{key}.point", o["point"], 3, point),
                        "normal": tuple(float(x) for x in normal / length)}
            r_obstacle = math.inf
        elif kind == "box":
            edge = bound(Obstacle, "size")._replace(lo_open=True)  # > 0 for a box (OBSTACLE_SIZES)
            shape_of = {"point": v.vector(f"{key}.centre", o["centre"], 3, point),
                        "size": v.vector(f"{key}.size", o["size"], 3, edge),
                        "yaw": v.within(f"{key}.yaw", o.get("yaw", 0.0), bound(Obstacle, "yaw"))}
            r_obstacle = math.inf
        else:
            ends = o["ends"]
            if not (isinstance(ends, list) and len(ends) == 2):
                raise SceneError(f"{key}.ends", f"expected [[x, y, z], [x, y, z]] in m, got {v.show(ends)}")
            a, b = (v.vector(f"{key}.ends[{e}]", ends[e], 3, point) for e in range(2))
            r_obstacle = v.within(f"{key}.radius", o["radius"], bound(Obstacle, "radius")._replace(lo_open=True))
            shape_of = {"point": a, "end": b, "radius": r_obstacle}
        contact = {k: o[k] for k in CONTACT_KEYS - {"pairs"} if k in o}
        make = _law_of(key, contact)
        force, energy = (v.within(f"{key}.{f}", o.get(f, getattr(thresholds, f)), bound(Obstacle, f))
                         for f in ("bruise_force", "bruise_energy"))
        obstacle = Obstacle(nm, kind, attached=attached, bruise_force=force, bruise_energy=energy, **shape_of)
        why = obstacle.refusal(key)
        if why:  # the shape's own rules (a box's edges > 0, a capsule's ends apart); the scene file says centre, ends
            where = {"point": "centre" if kind == "box" else "point", "end": "ends"}
            name = why[0].rsplit(".", 1)[1]
            raise SceneError(f"{key}.{where.get(name, name)}", why[1])
        out.append(obstacle)
        j = len(berries) + n
        pairs += [ContactPair(i, j, make(b.mass, b.radius, r_obstacle)) for i, b in enumerate(berries)]
    return out, pairs


def _coupling(raw: Any, berries: list[Berry]) -> list[Coupling]:
    key = "coupling"
    v.table(key, raw)
    v.no_unknown_keys(key, raw, COUPLING_KEYS)
    k, c = (v.within(f"{key}.{f}", raw.get(f, 0.0), bound(Coupling, f)) for f in ("stiffness", "damping"))
    order = sorted(range(len(berries)), key=lambda i: berries[i].hinge_x)
    neighbours = [tuple(sorted(p)) for p in zip(order, order[1:])]
    out = [Coupling(i, j, k, c) for i, j in _pair_list(f"{key}.pairs", raw.get("pairs"), berries, neighbours)]
    for cp in out:
        if berries[cp.i].spherical or berries[cp.j].spherical:
            raise SceneError(f"{key}.pairs", "the k3/c3 coupling acts on the horizontal separation of planar berries only")
    return out


def _solver(raw: Any) -> SolverSettings:
    key = "solver"
    v.table(key, raw)
    v.no_unknown_keys(key, raw, SOLVER_KEYS)
    d = SolverSettings()

    def setting(name: str) -> float:
        return v.within(f"{key}.{name}", raw.get(name, getattr(d, name)), bound(SolverSettings, name))

    def count(name: str) -> int | None:
        b, given = bound(SolverSettings, name), raw.get(name, getattr(d, name))
        return None if given is None else v.integer(f"{key}.{name}", given, int(b.lo), int(b.hi))

    t_end = setting("t_end")
    s = SolverSettings(
        method=v.choice(f"{key}.method", raw.get("method", d.method), METHODS),
        rtol=setting("rtol"), atol=setting("atol"), t_end=t_end,
        output_interval=setting("output_interval"),  # at most t_end: s.refusal()
        fixed_step=setting("fixed_step"), zeno_window=setting("zeno_window"),
        zeno_max_events=count("zeno_max_events"), max_steps=count("max_steps"),
        contact_location=v.choice(f"{key}.contact_location", raw.get("contact_location", d.contact_location),
                                  CONTACT_LOCATIONS),
        islands=_islands(f"{key}.islands", raw.get("islands", d.islands)),
        integrator=v.choice(f"{key}.integrator", raw.get("integrator", d.integrator), INTEGRATORS),
    )
    why = s.refusal()
    if why:
        raise SceneError(*why)
    return s


def _islands(key: str, raw: Any) -> bool | str:
    if raw == "auto" or isinstance(raw, bool):
        return raw
    raise SceneError(key, f"expected true, false or \"auto\", got {v.show(raw)}")


def _excitation(raw: Any, base_dir: Path, t_end: float) -> exc.Excitation:
    key = "excitation"
    v.table(key, raw)
    kind = v.choice(f"{key}.kind", raw.get("kind", "none"), tuple(EXCITATION_KEYS))
    v.no_unknown_keys(key, raw, EXCITATION_KEYS[kind])
    ex = _motion(kind, raw, key, base_dir, t_end)
    if "orientation" in raw or "angular_velocity" in raw:
        rpy = v.vector(f"{key}.orientation", raw.get("orientation", [0.0, 0.0, 0.0]), 3,
                       Bound(-2 * math.pi, 2 * math.pi, unit="rad"))
        w = v.vector(f"{key}.angular_velocity", raw.get("angular_velocity", [0.0, 0.0, 0.0]), 3,
                     Bound(-exc.MAX_ANGULAR_VELOCITY, exc.MAX_ANGULAR_VELOCITY, unit="rad/s"))
        ex = ex.starting(exc.quaternion_from_rpy(*rpy), w)
    return ex




def _table(raw: dict, key: str, base_dir: Path, what: str) -> tuple[str, str, str]:
    """(CSV text, where it was read, its scene key) of a table given as a file or inline as `text` (which is how
    a recording carries it: scenefile.scene_toml)."""
    if ("file" in raw) == ("text" in raw):
        raise SceneError(f"{key}.file", f"give file (a path to a {what}) or text (the {what} itself), exactly one")
    name = "text" if "text" in raw else "file"
    given = raw[name]
    if not isinstance(given, str):
        raise SceneError(f"{key}.{name}", f"expected {'the text of' if name == 'text' else 'a path to'} a {what}, "
                                          f"got {v.show(given)}")
    if name == "text":
        return given, "inline CSV", f"{key}.text"
    path = base_dir / given
    return read_text(path, what, f"{key}.file"), str(path), f"{key}.file"


def _motion(kind: str, raw: dict, key: str, base_dir: Path, t_end: float) -> exc.Excitation:
    acc = exc.MAX_ACCEL
    accel = Bound(-acc, acc, unit="m/s²")
    alpha = Bound(-exc.MAX_ANGULAR_ACCEL, exc.MAX_ANGULAR_ACCEL, unit="rad/s²")
    if kind == "none":
        return exc.constant()
    if kind == "constant":
        return exc.constant(v.linear(f"{key}.accel", raw.get("accel", [0.0, 0.0, 0.0]), accel),
                            v.vector(f"{key}.angular_accel", raw.get("angular_accel", [0.0, 0.0, 0.0]), 3, alpha))
    if kind == "csv":
        text, path, where = _table(raw, key, base_dir, "CSV of time, ax, az")
        after = v.choice(f"{key}.after", raw["after"], exc.AFTER) if "after" in raw else None
        ex = exc.read_csv(text, path, where, v.boolean(f"{key}.hold", raw.get("hold", False)), after)
        table = ex.arrays.table  # time, a (3), α (3): each against its own bound (α was held to a's)
        if abs(table[:, 1:4]).max() > acc:
            raise SceneError(where, f"accelerations must stay within ±{acc:g} m/s²")
        if abs(table[:, 4:7]).max() > exc.MAX_ANGULAR_ACCEL:
            raise SceneError(where, f"angular accelerations must stay within ±{exc.MAX_ANGULAR_ACCEL:g} rad/s²")
        return ex
    if kind == "pose-table":
        return exc.read_pose_table(*_table(raw, key, base_dir, "CSV pose table"))
    start = v.number(f"{key}.start", raw.get("start", 0.0), 0.0, 1e5, unit="s")
    if kind == "pick-and-place":
        moves_raw = raw.get("moves")
        if not isinstance(moves_raw, list) or not moves_raw:
            raise SceneError(f"{key}.moves", "expected a list of {displacement = [dx, dy, dz], duration = T} tables "
                                             "(optionally rotation = [rx, ry, rz])")
        moves = []
        for n, m in enumerate(moves_raw):
            mk = f"{key}.moves[{n}]"
            v.table(mk, m)
            v.no_unknown_keys(mk, m, {"displacement", "duration", "rotation"})
            d = v.linear(f"{mk}.displacement", m.get("displacement", [0.0, 0.0, 0.0]), Bound(-10.0, 10.0, unit="m"))
            T = v.number(f"{mk}.duration", m.get("duration"), 1e-3, 1e4, unit="s")
            r = v.vector(f"{mk}.rotation", m.get("rotation", [0.0, 0.0, 0.0]), 3, Bound(-4 * math.pi, 4 * math.pi,
                                                                                         unit="rad"))
            moves.append((d, T, r))
        jf = v.within(f"{key}.jerk_fraction", raw.get("jerk_fraction", 0.125), exc.JERK_FRACTION)
        ex = exc.pick_and_place(moves, start, jf)
        peak = abs(ex.arrays.table[:, 1:4]).max()
        if peak > acc:
            raise SceneError(f"{key}.moves", f"peak acceleration {peak:.3g} m/s² exceeds ±{acc:g} m/s²; lengthen a move")
        peak = abs(ex.arrays.table[:, 4:7]).max()
        if peak > exc.MAX_ANGULAR_ACCEL:
            raise SceneError(f"{key}.moves", f"peak angular acceleration {peak:.3g} rad/s² exceeds ±{exc.MAX_ANGULAR_ACCEL:g} "
                                             "rad/s²; lengthen a move")
        return ex
    if kind == "impulse":
        peak = v.linear(f"{key}.peak", raw.get("peak"), accel)
        angular = v.vector(f"{key}.angular_peak", raw.get("angular_peak", [0.0, 0.0, 0.0]), 3, alpha)
        dur = v.number(f"{key}.duration", raw.get("duration", 0.01), 1e-6, 10.0, unit="s")
        return exc.impulse(peak, start, dur, angular)
    amp = v.linear(f"{key}.amplitude", raw.get("amplitude"), accel)
    angular = v.vector(f"{key}.angular_amplitude", raw.get("angular_amplitude", [0.0, 0.0, 0.0]), 3, alpha)
    dur = v.number(f"{key}.duration", raw.get("duration", max(t_end - start, 1e-3)), 1e-3, 1e5, unit="s")
    if kind == "sine":
        f = v.number(f"{key}.frequency", raw.get("frequency"), 0.0, 1e4, lo_open=True, unit="Hz")
        return exc.chirp("sine", amp, f, f, start, dur, angular)
    f0 = v.number(f"{key}.f_start", raw.get("f_start"), 0.0, 1e4, lo_open=True, unit="Hz")
    f1 = v.number(f"{key}.f_stop", raw.get("f_stop"), 0.0, 1e4, lo_open=True, unit="Hz")
    return exc.chirp("sweep", amp, f0, f1, start, dur, angular)


def _thresholds(raw: Any) -> Thresholds:
    key = "thresholds"
    v.table(key, raw)
    v.no_unknown_keys(key, raw, THRESHOLD_KEYS)
    d = Thresholds()
    return Thresholds(**{f: v.within(f"{key}.{f}", raw.get(f, getattr(d, f)), bound(Thresholds, f))
                         for f in ("detachment_force", "bruise_force", "bruise_energy", "fatigue_fraction")})


def _check_overlap(scene: Scene) -> None:
    """Reject starts, and hanging rest states, that overlap far beyond what a contact law can mean (a hinge_x or an
    angle mistyped); a start is checked again, on the model's keys, wherever a scene is run (Solver). The start is
    the run's own: the rachis in its start orientation, where obstacles fixed in the world meet the berries. The
    hanging rest counts pairs of berries only: a berry held aside by a finger pad or leaning on a crate wall rests
    against it."""
    from ..physics.kinematics import deepest_overlap, overlaps
    from ..physics.layout import initial, layout_of

    model = scene.model
    bound = MAX_OVERLAP_FRACTION * model.contact_radius
    states = [("initial", initial(layout_of(scene), scene), scene.arrays, bound)]
    if model.planar:
        berries = np.array([pr.j < model.n_berries for pr in model.pairs], dtype=bool)
        states.append(("hanging rest", np.zeros(2 * model.n_dof), model.arrays, np.where(berries, bound, np.inf)))
    for label, y, arrays, bounds in states:
        hit = deepest_overlap(overlaps(y, arrays)[None], bounds)
        if hit is None:
            continue
        _, p, delta, limit = hit
        pr, nb = model.pairs[p], model.n_berries
        if pr.j >= nb:
            k = pr.j - nb
            key = f"obstacles[{k}].{OBSTACLE_SHAPE_KEYS[model.obstacles[k].kind][0]}"
        else:
            key = f"berries[{pr.j}].hinge_x" if label == "hanging rest" else f"berries[{pr.j}].angle"
        raise SceneError(key, model.overlap_words(p, delta, limit, label))

"""A small TOML writer for scene documents (tables, arrays of tables, numbers, strings, bools, lists),
so that a scene built in code carries the same reproducible text as one read from a file."""
from __future__ import annotations

import json
import math
import tomllib
from dataclasses import fields
from typing import Any

from ..errors import SceneError
from .parse import parse_scene  # (parse imports dumps when it writes a scene built from a dict)


def _value(v: Any, key: str) -> str:
    """v as a TOML value; key names it in the document (berries[1].mass) if it cannot be one."""
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        if math.isnan(v):
            return "nan"
        if math.isinf(v):
            return "inf" if v > 0 else "-inf"
        return repr(v)
    if isinstance(v, str):
        return json.dumps(v, ensure_ascii=False)
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_value(x, f"{key}[{i}]") for i, x in enumerate(v)) + "]"
    if isinstance(v, dict):
        return "{ " + ", ".join(f"{k} = {_value(x, f'{key}.{k}')}" for k, x in v.items()) + " }"
    raise SceneError(key, f"expected a number, string, boolean, list or table (leave a setting out to take its "
                          f"default), got {type(v).__name__} {v!r}")


def dumps(doc: dict[str, Any]) -> str:
    lines = []
    tables = []
    for k, v in doc.items():
        if isinstance(v, dict):
            tables.append((k, v, False))
        elif isinstance(v, list) and v and all(isinstance(x, dict) for x in v):
            tables.append((k, v, True))
        else:
            lines.append(f"{k} = {_value(v, k)}")
    for k, v, many in tables:
        for i, item in enumerate(v if many else [v]):
            lines.append("")
            lines.append(f"[[{k}]]" if many else f"[{k}]")
            lines.extend(f"{kk} = {_value(vv, f'{k}[{i}].{kk}' if many else f'{k}.{kk}')}" for kk, vv in item.items())
    return "\n".join(lines) + "\n"


def scene_toml(scene) -> str:
    """The TOML text that reads back as `scene`, for a recording or an FMU to name the scene that ran: the text it
    was read from while that still describes it and names no CSV file. Otherwise that document with a CSV table
    inline (`text`, so a recording replays where the file is not) and what a change in code (`dataclasses.replace`)
    commonly touches written anew (name, gravity, the berries and their initial state, solver, thresholds), read
    back to prove it. A change the document cannot carry that way (its contacts, couplings, obstacles, excitation,
    or a berry's law its file derives from the berry) is refused, as is a scene built in code without a document:
    write it as one (scene_from_dict) to record it."""
    X = scene.excitation
    if scene.source and scene.source_key == scene.key and not X.text:
        return scene.source
    if not scene.source:
        raise SceneError("source", "a scene built in code without a scene document cannot name itself in a recording "
                                   "or an FMU; build it from one (scenefile.scene_from_dict or parse_scene)")
    doc = tomllib.loads(scene.source)
    doc["name"], doc["gravity"] = scene.name, scene.model.gravity
    k = 0
    for b, raw in zip(scene.model.berries, doc["berries"]):
        n = 2 if b.spherical else 1
        q, w = scene.angles[k:k + n], scene.angular_velocities[k:k + n]
        k += n
        for f in ("hinge_x", "hinge", "kind", "azimuth", "rest_angles"):
            raw.pop(f, None)
        raw.update(name=b.name, mass=b.mass, radius=b.radius, twig_length=b.twig_length,
                   hinge_stiffness=b.hinge_stiffness, hinge_damping=b.hinge_damping,
                   **({"hinge": [b.hinge_x, b.hinge_y, b.hinge_z]} if b.hinge_y or b.hinge_z
                      else {"hinge_x": b.hinge_x}),
                   **({"kind": "spherical", "azimuth": b.azimuth, "rest_angles": list(b.rest_angles)}
                      if b.spherical else {}),
                   angle=list(q) if b.spherical else q[0], angular_velocity=list(w) if b.spherical else w[0])
    for section, settings in (("solver", scene.solver), ("thresholds", scene.thresholds)):
        doc[section] = {f.name: v for f in fields(settings) if (v := getattr(settings, f.name)) is not None}
    if X.text:  # a table read from a file travels with the scene: a recording replays where the file is not
        doc["excitation"] = {**{k: v for k, v in doc.get("excitation", {}).items() if k != "file"}, "text": X.text}
    text = dumps(doc)
    try:
        again = parse_scene(text, name=scene.name).key
    except SceneError as e:
        raise SceneError("source", f"this scene, changed in code, is one its scene document would refuse ({e}); "
                                   "make the change in the document (scenefile.scene_from_dict) to record it") from None
    if again != scene.key:
        raise SceneError("source", "this scene was changed in code beyond its name, gravity, berries, initial state, "
                                   "solver and thresholds (its contacts, couplings, obstacles or excitation), so the "
                                   "TOML it was read from no longer describes it; make the change in the scene "
                                   "document (scenefile.scene_from_dict) to record it")
    return text

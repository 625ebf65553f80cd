"""The sweep specification (TOML) and the runs it expands to.

    scene = "cluster.toml"         # the base scene, relative to this file
    mode = "grid"                  # or "monte-carlo", or "list" (run k takes the k-th value of every parameter)
    samples = 200                  # monte-carlo: number of runs
    seed = 1                       # monte-carlo: the draws are fixed by the seed

    [[parameters]]
    key = "contact.stiffness"      # a key of the base scene: tables by name, lists by [i] or [*]
    values = [1000.0, 2000.0]      # grid: every combination of every parameter's values
    # monte-carlo: distribution = "uniform" (low, high), "normal" (mean, sd) or "choice" (values);
    # a key with [*] draws one value per element (per berry) unless shared = true (one draw for all)

Every run's inputs are fixed here, in the driver, before anything is executed: the rows cannot
depend on the executor, the number of workers or the order runs finish in.
"""
from __future__ import annotations

import copy
import hashlib
import itertools
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import SceneError
from ..scenefile import validate as v
from ..scenefile.parse import loads_toml, read_text

KEY_RE = re.compile(r"([A-Za-z_][A-Za-z0-9_]*)(?:\[(\d{1,9}|\*)\])?")
SPEC_KEYS = {"scene", "mode", "samples", "seed", "parameters"}
PARAM_KEYS = {"key", "values", "distribution", "low", "high", "mean", "sd", "shared"}
MAX_RUNS = 1_000_000
#: changes when the same spec text expands to different runs or rows (2: per-element draws for [*] keys; 3: the
#: rows name the bruised and detached berries), so a journal or table of an older expansion is never mixed in
FORMAT = 3
MODES = ("grid", "monte-carlo", "list")


@dataclass(frozen=True)
class Parameter:
    key: str
    values: tuple[Any, ...] = ()
    distribution: str = "grid"
    a: float = 0.0
    b: float = 0.0
    each: int = 0  # monte-carlo over a [*] key: one draw per element (this many), as a list; 0: one draw

    def draw(self, rng: np.random.Generator) -> Any:
        if self.each:
            return [self._one(rng) for _ in range(self.each)]
        return self._one(rng)

    def _one(self, rng: np.random.Generator) -> Any:
        if self.distribution == "uniform":
            return float(rng.uniform(self.a, self.b))
        if self.distribution == "normal":
            return float(rng.normal(self.a, self.b))
        return self.values[int(rng.integers(len(self.values)))]


@dataclass(frozen=True)
class SweepSpec:
    base: dict[str, Any]          # the base scene document
    base_dir: Path
    mode: str
    parameters: tuple[Parameter, ...]
    samples: int
    seed: int
    text: str                     # the spec and scene as read, for the fingerprint

    @property
    def fingerprint(self) -> str:
        """Identifies the runs: a journal or output written for another spec is never mixed in."""
        return hashlib.sha256(f"grapefmu sweep {FORMAT}\n{self.text}".encode()).hexdigest()[:16]

    def runs(self) -> list[dict[str, Any]]:
        """The inputs of every run, in run order: {key: value}."""
        keys = [p.key for p in self.parameters]
        if self.mode == "grid":
            return [dict(zip(keys, combo)) for combo in itertools.product(*(p.values for p in self.parameters))]
        if self.mode == "list":
            return [dict(zip(keys, row)) for row in zip(*(p.values for p in self.parameters))]
        rng = np.random.default_rng(self.seed)
        return [{p.key: p.draw(rng) for p in self.parameters} for _ in range(self.samples)]


def load_spec(path: str | Path) -> SweepSpec:
    path = Path(path)
    text = read_text(path, "sweep spec")
    doc = loads_toml(text, str(path))
    v.no_unknown_keys("", doc, SPEC_KEYS)
    if not isinstance(doc.get("scene"), str):
        raise SceneError("scene", "expected the path of the base scene TOML")
    scene_path = path.parent / doc["scene"]
    scene_text = read_text(scene_path)
    base = loads_toml(scene_text, str(scene_path))
    mode = v.choice("mode", doc.get("mode", "grid"), MODES)
    raw = doc.get("parameters")
    if not isinstance(raw, list) or not raw:
        raise SceneError("parameters", "expected at least one [[parameters]] table")
    params = tuple(_parameter(f"parameters[{n}]", p, mode, base) for n, p in enumerate(raw))
    samples = v.integer("samples", doc.get("samples", 100), 1, MAX_RUNS)  # checked in any mode: a grid ignores it
    samples = samples if mode == "monte-carlo" else 0
    seed = v.integer("seed", doc.get("seed", 1), 0, 2**63 - 1)
    spec = checked(SweepSpec(base, scene_path.parent, mode, params, samples, seed, text + "\n---\n" + scene_text))
    _refuse_what_no_run_changes(spec, doc["scene"])
    return spec


def _refuse_what_no_run_changes(spec: SweepSpec, scene: str) -> None:
    """A base scene the validator refuses alike in the first, middle and last run, on a key no parameter sets (a
    typo, a value out of range): every run would be refused, so the sweep is, before any runs (it ran them all, each
    a row saying so, and exited 0). An error that depends on what is swept differs between the runs, or names a
    swept key, and is left to the runs."""
    from ..scenefile import scene_from_dict

    runs = spec.runs()
    said = set()
    for k in sorted({0, len(runs) // 2, len(runs) - 1}):
        try:
            scene_from_dict(scene_doc(spec, runs[k]), spec.base_dir)
            return
        except SceneError as e:
            said.add((e.key, str(e)))
    if len(said) == 1:
        key, why = said.pop()
        swept = [re.compile(re.escape(p.key).replace(r"\[\*\]", r"\[\d+\]") + r"(?:$|[.\[])") for p in spec.parameters]
        if not any(r.match(key) for r in swept):
            raise SceneError(key, f"{why[len(key) + 2:]} (in the base scene {scene}, which no parameter changes: every "
                                  "run would be refused)")


def same_value(doc: dict, keys: list[str], where: str = "parameters") -> None:
    """Refuse keys of which two reach the same value of doc (berries[*].mass and berries[0].mass): the run would set it
    twice, the last one silently winning."""
    marked = copy.deepcopy(doc)
    for n, key in enumerate(keys):
        for container, name in slots(marked, key, where):
            if isinstance(container[name], _Mark):
                raise SceneError(where, f"{key!r} and {keys[container[name].n]!r} set the same value")
            container[name] = _Mark(n)


class _Mark:
    def __init__(self, n: int):
        self.n = n


def checked(spec: SweepSpec) -> SweepSpec:
    """A spec, read from a file or built in code (risk/), whose runs can be expanded: no key twice, a grid of at
    most MAX_RUNS runs, a list whose parameters have one value per run each."""
    params = spec.parameters
    if len({p.key for p in params}) != len(params):
        raise SceneError("parameters", "a key is swept twice")
    same_value(spec.base, [p.key for p in params])
    if spec.mode == "grid" and np.prod([len(p.values) for p in params], dtype=float) > MAX_RUNS:
        raise SceneError("parameters", f"the grid has more than {MAX_RUNS} runs")
    if spec.mode == "list":
        for n, p in enumerate(params):
            if len(p.values) != len(params[0].values):
                raise SceneError(f"parameters[{n}].values", f"a list sweep takes one value per run: "
                                 f"{len(params[0].values)} in parameters[0], {len(p.values)} here")
    return spec


def _parameter(key: str, raw: Any, mode: str, base: dict) -> Parameter:
    v.table(key, raw)
    v.no_unknown_keys(key, raw, PARAM_KEYS)
    path = raw.get("key")
    if not isinstance(path, str):
        raise SceneError(f"{key}.key", "expected a path into the scene such as \"contact.stiffness\"")
    count = len(slots(copy.deepcopy(base), path, f"{key}.key"))  # the path exists in the base scene
    if mode != "monte-carlo":
        if "distribution" in raw:
            raise SceneError(f"{key}.distribution", f"a {mode} sweep takes values lists only; distribution "
                                                    "(uniform, normal or choice) is for monte-carlo")
        if "shared" in raw:
            raise SceneError(f"{key}.shared", f"a {mode} sweep sets every element of a [*] key to each value; "
                                              "shared is for monte-carlo")
        _takes_only(key, raw, {"key", "values"}, f"a {mode} sweep")
        return Parameter(path, _values(f"{key}.values", raw.get("values")))
    dist = v.choice(f"{key}.distribution", raw.get("distribution"), ("uniform", "normal", "choice"))
    _takes_only(key, raw, {"key", "distribution", "shared", *DISTRIBUTION_KEYS[dist]}, f"distribution {dist!r}")
    shared = v.boolean(f"{key}.shared", raw.get("shared", False))
    if "shared" in raw and "[*]" not in path:
        raise SceneError(f"{key}.shared", f"shared draws one value for every element of a [*] key; {path!r} has none")
    each = count if "[*]" in path and not shared else 0
    if dist == "choice":
        return Parameter(path, _values(f"{key}.values", raw.get("values")), "choice", each=each)
    if dist == "uniform":
        lo = v.number(f"{key}.low", raw.get("low"), -1e12, 1e12)
        hi = v.number(f"{key}.high", raw.get("high"), lo, 1e12)
        return Parameter(path, (), "uniform", lo, hi, each)
    return Parameter(path, (), "normal", v.number(f"{key}.mean", raw.get("mean"), -1e12, 1e12),
                     v.number(f"{key}.sd", raw.get("sd"), 0.0, 1e12), each)


#: what each distribution is drawn from
DISTRIBUTION_KEYS = {"uniform": ("low", "high"), "normal": ("mean", "sd"), "choice": ("values",)}


def _takes_only(key: str, raw: dict, allowed: set[str], what: str) -> None:
    """Refuse a parameter's key its mode or distribution does not read (it was silently ignored: low and high in a
    grid, mean and sd in a uniform draw)."""
    extra = sorted(set(raw) - allowed)
    if extra:
        raise SceneError(f"{key}.{extra[0]}", f"{what} does not read it (it takes {', '.join(sorted(allowed))})")


def _values(key: str, raw: Any) -> tuple[Any, ...]:
    if not isinstance(raw, list) or not raw:
        raise SceneError(key, "expected a non-empty list of values")
    for x in raw:
        if not isinstance(x, (int, float, str, bool, list)):
            raise SceneError(key, f"expected numbers, strings, booleans or lists, got {x!r}")
    return tuple(raw)


def slots(doc: dict, path: str, where: str = "key") -> list[tuple[Any, Any]]:
    """Every (container, name or index) a dotted path reaches in doc, in document order; [*] reaches every
    element of a list."""
    parts = path.split(".")
    targets: list[Any] = [doc]
    found: list[tuple[Any, Any]] = []
    for n, part in enumerate(parts):
        m = KEY_RE.fullmatch(part)
        if not m:
            raise SceneError(where, f"{path!r}: {part!r} is not a name, name[i] or name[*]")
        name, index = m.groups()
        last = n == len(parts) - 1
        nxt = []
        for t in targets:
            if not isinstance(t, dict) or name not in t:
                raise SceneError(where, f"{path!r}: the base scene has no {'.'.join(parts[:n + 1])!r} "
                                        "(write the key into the scene, with its default, to sweep it)")
            if index is None:
                if last:
                    found.append((t, name))
                else:
                    nxt.append(t[name])
                continue
            seq = t[name]
            if not isinstance(seq, list):
                raise SceneError(where, f"{path!r}: {name!r} is not a list")
            idx = range(len(seq)) if index == "*" else [int(index)]
            for i in idx:
                if i >= len(seq):
                    raise SceneError(where, f"{path!r}: {name!r} has only {len(seq)} entries")
                if last:
                    found.append((seq, i))
                else:
                    nxt.append(seq[i])
        targets = nxt
    return found


def values_at(doc: dict, path: str, where: str = "key") -> list[Any]:
    """The values a dotted path reaches in doc, in document order (one for a plain key, one per element for [*])."""
    return [container[name] for container, name in slots(doc, path, where)]


def apply(doc: dict, path: str, value: Any, where: str = "key", each: bool = False) -> None:
    """Set doc at a dotted path; [*] sets every element of a list (with `each`, element k to value[k])."""
    reached = slots(doc, path, where)
    if each and (not isinstance(value, list) or len(value) != len(reached)):
        raise SceneError(where, f"{path!r}: expected {len(reached)} values, one per element, got {value!r}")
    for k, (container, name) in enumerate(reached):
        container[name] = value[k] if each else value


def scene_doc(spec: SweepSpec, inputs: dict[str, Any]) -> dict:
    doc = copy.deepcopy(spec.base)
    each = {p.key for p in spec.parameters if p.each}
    for key, value in inputs.items():
        apply(doc, key, value, each=key in each)
    return doc


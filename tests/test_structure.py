"""The structure the code promises: each fact in one place, imports in one direction, docs and code agree."""
from __future__ import annotations

import ast
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SRC = ROOT / "src" / "grapefmu"
#: the core's subpackages, lowest first: a package imports only packages before it (and the top-level modules)
LAYERS = ["model", "physics", "scenefile", "results", "solver", "recording", "cluster", "sweep", "fit", "risk", "paper",
          "bench"]


def imports(path: Path) -> set[str]:
    """Absolute names of the grapefmu modules (and third-party roots) a file imports, lazy imports included."""
    tree = ast.parse(path.read_text())
    pkg = ["grapefmu", *path.relative_to(SRC).parts[:-1]]
    out = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            out |= {a.name for a in node.names}
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = pkg[: len(pkg) - node.level + 1]
                out.add(".".join(base + ([node.module] if node.module else [])))
            else:
                out.add(node.module)
    return out


def sub(name: str) -> str | None:
    parts = name.split(".")
    return parts[1] if parts[0] == "grapefmu" and len(parts) > 1 and parts[1] in LAYERS else None


def test_core_imports_point_one_way_and_no_face():
    """The command line reaches the FMU builder and the ROS replayer through entry points (`grapefmu.faces`)."""
    bad = []
    for f in SRC.rglob("*.py"):
        here = sub("grapefmu." + ".".join(f.relative_to(SRC).with_suffix("").parts))
        for name in imports(f):
            root = name.split(".")[0]
            if root in ("rclpy", "pythonfmu", "pythonfmu3", "fmpy", "grapefmu_ros", "grapefmu_fmu"):
                bad.append(f"{f.relative_to(ROOT)} imports the face {name}")
            there = sub(name)
            if here and there and LAYERS.index(there) > LAYERS.index(here):
                bad.append(f"{f.relative_to(ROOT)} ({here}) imports {name} ({there}), a layer above it")
    assert not bad, "\n".join(bad)


def test_faces_use_only_the_solver_api():
    """The FMU and the ROS node reach the physics through Solver, never its compiled internals."""
    for f in [*(ROOT / "fmu_build").rglob("*.py"), *(ROOT / "ros_node").rglob("*.py")]:
        tree = ast.parse(f.read_text())
        names = {n.module for n in ast.walk(tree) if isinstance(n, ast.ImportFrom) and n.module}
        names |= {a.name for n in ast.walk(tree) if isinstance(n, ast.Import) for a in n.names}
        for name in names:
            assert not re.match(r"grapefmu\.(physics\.(dynamics|forces|kinematics|observe)|solver\.(loop|events|"
                                r"broadphase|sampling|step))", name), f"{f.relative_to(ROOT)} imports {name}"


def test_model_arrays_are_named_not_indexed():
    """No numeric column indexing of model arrays outside the model module."""
    pattern = re.compile(r"\.berry\[[^\]]*,\s*\d|\.pair\[[^\]]*,\s*\d|\.coupling\[[^\]]*,\s*\d")
    hits = [f"{f.relative_to(ROOT)}:{n}" for f in [*SRC.rglob("*.py"), *(ROOT / "tests").glob("*.py"),
                                                    *(ROOT / "fmu_build").rglob("*.py"), *(ROOT / "ros_node").rglob("*.py")]
            for n, line in enumerate(f.read_text().splitlines(), 1) if pattern.search(line)]
    assert not hits, hits


def test_model_doc_and_code_cite_the_same_sections():
    """Every `docs/model.md §N` the code cites exists, and every section of the derivation is cited by the code."""
    doc = (ROOT / "docs" / "model.md").read_text()
    sections = {int(m.group(1)): m.group(2) for m in re.finditer(r"^## (\d+)\. (.+)$", doc, re.M)}
    cited = set()
    for f in SRC.rglob("*.py"):
        for m in re.finditer(r"model\.md §(\d+)(?:[–-](\d+))?", f.read_text()):
            lo, hi = int(m.group(1)), int(m.group(2) or m.group(1))
            cited |= set(range(lo, hi + 1))
    assert cited <= set(sections), f"code cites missing sections {sorted(cited - set(sections))}"
    derivation = {n for n, title in sections.items() if not title.startswith(("Names", "Mapping"))}
    assert derivation <= cited, f"sections no code cites: {sorted(derivation - cited)}"


@pytest.mark.parametrize("pattern", [r"(?<!\w)pedicel_force", r"(?<!\w)n_berries_over", r"(?<!\w)energy_dissipated",
                                     r"(?<!\w)pair_idx", r"(?<!\w)pair_par", r"(?<!\w)time_s\b", r"[a-z]_n\b"])
def test_one_name_per_concept(pattern):
    """Retired synonyms (pedicel force for the pedicel tension, energy_dissipated for dissipated_energy, unit
    suffixes on message fields and FMU variables) appear nowhere in code, docs or the interfaces."""
    files = [*SRC.rglob("*.py"), *(ROOT / "docs").glob("*.md"), ROOT / "README.md", ROOT / "recordings" / "README.md",
             *(ROOT / "fmu_build").rglob("*.py"), *(ROOT / "ros_node").rglob("*.py")]
    if pattern.endswith(("_n\\b", "time_s\\b")):  # unit suffixes belong to file columns, summary keys, sweep columns
        files = [f for f in files if f.name not in ("worker.py", "sweeps.md", "risk.md", "fit_and_risk.md", "run.py",
                                                     "catalogue.py", "cli.py", "plot.py", "outputs.md", "README.md")]
    hits = [f"{f.relative_to(ROOT)}: {m.group(0)}" for f in files
            for m in [re.search(pattern, f.read_text())] if m]
    assert not hits, hits


def test_names_table_lists_every_catalogue_channel_used_by_the_model():
    from grapefmu.results.catalogue import CHANNELS
    doc = (ROOT / "docs" / "model.md").read_text()
    names = doc[doc.index("## 8. Names"):doc.index("## 9.")]
    for c in CHANNELS:
        if c.per in ("angle", "berry", "pair", "obstacle"):
            assert f"`{c.name}" in names, c.name


def test_outputs_doc_is_the_catalogue():
    """docs/outputs.md carries exactly what `grapefmu outputs` prints."""
    from grapefmu.results.catalogue import markdown
    assert markdown() in (ROOT / "docs" / "outputs.md").read_text()

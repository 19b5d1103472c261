"""The layering of the code base: which package may import which, and no import cycles anywhere.

Layers, bottom up (``../shared/docs/architecture.md``)::

    cli                                    parses, calls the layers below, prints
    batch  evaluation  training            jobs over datasets; measurements; model training
    pipeline                               the stages wired together (per-sample context)
    render    scenegen                     the renderer; the generator of the bundled scenes
    lighting  placement                    the scene's light; where objects go
    datasets  assets                       nuScenes reading/writing; meshes and materials
    core                                   conventions, errors, I/O, rays, depth (a leaf)

Every import counts, at module level or inside a function. The renderer reads the lighting only through
its public types (``lighting.light``). A failing test names the importing module and what it imported.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
PACKAGE_DIRS = {"augment": "streetaug.augment", "cli": "streetaug.cli", "placement": "streetaug.placement",
                "datasets": "streetaug.datasets"}

# group -> module prefixes; the first matching prefix (longest first) names a module's group
GROUPS = {
    "core": ["streetaug.augment.core"],
    "datasets": ["streetaug.datasets"],
    "assets": ["streetaug.augment.assets"],
    "lighting": ["streetaug.augment.lighting"],
    "placement": ["streetaug.placement"],
    "render": ["streetaug.augment.render"],
    "scenegen": ["streetaug.augment.scenegen"],
    "pipeline": ["streetaug.augment.pipeline"],
    "batch": ["streetaug.augment.batch"],
    "evaluation": ["streetaug.augment.evaluation"],
    "training": ["streetaug.augment.training"],
    "cli": ["streetaug.cli"],
    "package": ["streetaug.augment"],  # streetaug/augment/__init__.py itself
}

_BELOW_PIPELINE = {"core", "datasets", "assets", "lighting", "placement", "render"}
ALLOWED = {
    "core": set(),
    "datasets": {"core"},
    "assets": {"core"},
    "lighting": {"core", "datasets"},
    "placement": {"core", "datasets", "assets"},
    "render": {"core", "assets", "lighting:streetaug.augment.lighting.light"},
    "scenegen": {"core", "datasets", "assets", "lighting"},
    "pipeline": _BELOW_PIPELINE,
    "batch": _BELOW_PIPELINE | {"pipeline"},
    "evaluation": _BELOW_PIPELINE | {"pipeline", "scenegen", "batch"},
    "training": _BELOW_PIPELINE | {"scenegen"},
    "cli": set(GROUPS) - {"cli"},
    "package": set(),
}


def project_modules(root: Path = REPO) -> dict[str, Path]:
    """Dotted name -> file of every project module (packages by their ``__init__``)."""
    modules = {}
    for folder, package in PACKAGE_DIRS.items():
        for path in sorted((root / folder).rglob("*.py")):
            parts = list(path.relative_to(root / folder).with_suffix("").parts)
            if parts[-1] == "__init__":
                parts = parts[:-1]
            modules[".".join([package, *parts])] = path
    return modules


def _absolute(node: ast.ImportFrom, module: str, is_package: bool) -> str:
    if not node.level:
        return node.module or ""
    base = module.split(".") if is_package else module.split(".")[:-1]
    base = base[: len(base) - (node.level - 1)]
    return ".".join(base + ([node.module] if node.module else []))


def import_edges(modules: dict[str, Path]) -> list[tuple[str, str]]:
    """(importer, imported) pairs between project modules, every import statement of every module."""
    edges = []
    for module, path in modules.items():
        is_package = path.name == "__init__.py"
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if isinstance(node, ast.Import):
                targets = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom):
                base = _absolute(node, module, is_package)
                targets = [f"{base}.{a.name}" if f"{base}.{a.name}" in modules else base for a in node.names]
            else:
                continue
            for target in targets:
                while target and target not in modules:
                    target = target.rpartition(".")[0]
                if target and target != module:
                    edges.append((module, target))
    return edges


def group_of(module: str) -> str:
    best = max((p for ps in GROUPS.values() for p in ps if module == p or module.startswith(p + ".")), key=len)
    return next(g for g, ps in GROUPS.items() if best in ps)


def layer_violations(edges: list[tuple[str, str]]) -> list[str]:
    """Imports that break :data:`ALLOWED`, as readable lines."""
    bad = []
    for src, dst in edges:
        gs, gd = group_of(src), group_of(dst)
        if gs == gd:
            continue
        allowed = ALLOWED[gs]
        ok = gd in allowed or any(a == f"{gd}:{dst}" or (a.startswith(gd + ":") and dst.startswith(a.split(":")[1] + "."))
                                  for a in allowed)
        if not ok:
            bad.append(f"{src} ({gs}) imports {dst} ({gd})")
    return sorted(set(bad))


def import_cycles(edges: list[tuple[str, str]]) -> list[list[str]]:
    """Strongly connected components of more than one module (Tarjan, iterative)."""
    graph: dict[str, set[str]] = {}
    for s, d in edges:
        graph.setdefault(s, set()).add(d)
        graph.setdefault(d, set())
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    cycles = []
    for root in graph:
        if root in index:
            continue
        work = [(root, iter(sorted(graph[root])))]
        index[root] = low[root] = len(index)
        stack.append(root)
        on_stack.add(root)
        while work:
            v, children = work[-1]
            w = next(children, None)
            if w is not None:
                if w not in index:
                    index[w] = low[w] = len(index)
                    stack.append(w)
                    on_stack.add(w)
                    work.append((w, iter(sorted(graph[w]))))
                elif w in on_stack:
                    low[v] = min(low[v], index[w])
                continue
            work.pop()
            if work:
                low[work[-1][0]] = min(low[work[-1][0]], low[v])
            if low[v] == index[v]:
                comp = []
                while True:
                    w = stack.pop()
                    on_stack.discard(w)
                    comp.append(w)
                    if w == v:
                        break
                if len(comp) > 1:
                    cycles.append(sorted(comp))
    return cycles


@pytest.fixture(scope="module")
def edges():
    return import_edges(project_modules())


def test_every_module_belongs_to_a_layer():
    for module in project_modules():
        assert group_of(module) in ALLOWED, module


def test_layers(edges):
    bad = layer_violations(edges)
    assert not bad, "imports against the layering:\n  " + "\n  ".join(bad)


def test_no_import_cycles(edges):
    cycles = import_cycles(edges)
    assert not cycles, "import cycles:\n  " + "\n  ".join(" <-> ".join(c) for c in cycles)


def test_package_cycles(edges):
    groups = [(group_of(s), group_of(d)) for s, d in edges if group_of(s) != group_of(d)]
    cycles = import_cycles(groups)
    assert not cycles, f"packages importing each other: {cycles}"


class TestTheCheckerItself:
    """The checks above must be able to fail: a wrong import and a cycle are caught."""

    def test_a_core_module_importing_the_pipeline_is_reported(self):
        bad = layer_violations([("streetaug.augment.core.frames", "streetaug.augment.pipeline.insert")])
        assert bad == ["streetaug.augment.core.frames (core) imports streetaug.augment.pipeline.insert (pipeline)"]

    def test_the_renderer_may_read_only_the_light_types(self):
        assert not layer_violations([("streetaug.augment.render.shade", "streetaug.augment.lighting.light")])
        assert layer_violations([("streetaug.augment.render.shade", "streetaug.augment.lighting.estimate")])

    def test_lighting_and_placement_do_not_import_each_other(self):
        assert layer_violations([("streetaug.placement.place", "streetaug.augment.lighting.sun")])
        assert layer_violations([("streetaug.augment.lighting.sun", "streetaug.placement.place")])

    def test_a_cycle_is_found(self):
        cycles = import_cycles([("a", "b"), ("b", "c"), ("c", "a"), ("c", "d")])
        assert cycles == [["a", "b", "c"]]

    def test_a_wrong_import_in_a_real_file_is_found(self, tmp_path):
        for folder in PACKAGE_DIRS:
            (tmp_path / folder).mkdir()
        (tmp_path / "augment" / "core").mkdir()
        (tmp_path / "augment" / "core" / "__init__.py").write_text("")
        (tmp_path / "augment" / "core" / "frames.py").write_text("from ..pipeline import run\n")
        (tmp_path / "augment" / "pipeline.py").write_text("from .core import frames\n")
        edges = import_edges(project_modules(tmp_path))
        assert layer_violations(edges) == [
            "streetaug.augment.core.frames (core) imports streetaug.augment.pipeline (pipeline)"]
        assert import_cycles(edges) == [["streetaug.augment.core.frames", "streetaug.augment.pipeline"]]

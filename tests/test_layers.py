"""drivelab's layering (docs/architecture.md): every import points down a layer, and no files import
each other.

The checker reads every module of ``drivelab/`` with ``ast`` (nothing is imported): ``import x``
and ``from x import y`` at module level and inside functions, relative imports resolved, ``from
package import module`` counted as an import of that module. An import is an edge importer →
imported; an edge is allowed inside a layer and to the layers below (or to those a layer names in
``may_import``), and the edges must not form a cycle between files.

Layers are folders: each layer is one package of ``drivelab/`` (the bottom one also holds the
single modules that import nothing of drivelab), and ``test_every_folder_is_a_layer`` fails on a
package that is no layer's. Not counted: the parent packages Python runs first (importing
``drivelab.sim.core.simulator`` runs ``drivelab/__init__.py``, which registers the gymnasium ids).
"""

from __future__ import annotations

import ast
from dataclasses import dataclass
from pathlib import Path

import networkx as nx

PACKAGE_DIR = Path(__file__).resolve().parents[1] / "drivelab"


@dataclass(frozen=True)
class Layer:
    """A layer: the modules under ``prefixes`` (a module belongs to its longest matching prefix).

    :param rank: height; imports go to lower ranks only (layers of one rank do not import each other).
    :param may_import: the other layers it may import; None: every layer of a lower rank.
    """

    name: str
    rank: int
    prefixes: tuple[str, ...]
    may_import: frozenset[str] | None = None


# docs/architecture.md's layers on today's package layout, bottom to top.
LAYERS = (
    # world/: WorldBatch, WorldState, RoadMap, geometry; plus the modules that import nothing of
    # drivelab (errors, the YAML loader that perception's sensor specs and the run config share,
    # numba's cache folder that the package sets before any kernel is compiled, the pinned
    # instruction set that recorded numbers are computed under)
    Layer(
        "base",
        0,
        ("drivelab.errors", "drivelab.world", "drivelab.yaml_io", "drivelab._numba_cache", "drivelab.isa"),
    ),
    # sim/: the compiled core, signalised junctions (lights, pedestrians, vehicles on routes), roads
    # from blocks, route tracking, and the highway-env reference; it knows no scenario by name
    Layer("sim", 1, ("drivelab.sim",)),
    # scenarios/: one folder per scenario (preset, spawn, its road, its simulator subclass, its
    # highway-env reference env) and the registry that lists them
    Layer("scenarios", 2, ("drivelab.scenarios",)),
    # sensors and reward terms read the WorldBatch only: not the simulators or scenarios below
    # them (shared geometry lives in the bottom layer), and not each other
    Layer("perception", 3, ("drivelab.perception",), may_import=frozenset({"base"})),
    Layer("rewards", 3, ("drivelab.rewards",), may_import=frozenset({"base"})),
    # the environments
    Layer("envs", 4, ("drivelab.envs",)),
    # agents, with the hyper-parameters shipped for them (data read by agents/sb3.py)
    Layer("agents", 5, ("drivelab.agents", "drivelab.hyperparams")),
    # runs, evaluation, comparisons; RunConfig is a training run's config (it checks the env's
    # options through envs/, and nothing below a run reads it)
    Layer("training", 6, ("drivelab.training", "drivelab.config")),
    # the Python API: ``drivelab`` itself (``drivelab/__init__.py``: importing it registers the
    # gymnasium ids; ``drivelab.make`` builds a DriveEnv, ``drivelab.load`` a trained agent) and
    # ``api.py`` (the loaded ``Model``, which reads runs through training/)
    Layer("api", 7, ("drivelab", "drivelab.api")),
    # the command line: ``drivelab`` (cli.py) and ``python -m drivelab`` (__main__.py, which calls it)
    Layer("cli", 8, ("drivelab.cli", "drivelab.__main__")),
)

# (importer, imported) edges the test tolerates while a re-layering is under way, each with its
# reason; it fails when one no longer occurs, so the list only shrinks. Empty: every import of
# drivelab points down.
KNOWN_VIOLATIONS: dict[tuple[str, str], str] = {}


# --- the checker ---------------------------------------------------------------------------------
def module_sources(package_dir: Path) -> dict[str, tuple[str, bool]]:
    """Dotted module name → (source text, is a package ``__init__``) for every ``.py`` below."""
    sources = {}
    for path in sorted(package_dir.rglob("*.py")):
        parts = path.relative_to(package_dir.parent).with_suffix("").parts
        is_package = parts[-1] == "__init__"
        name = ".".join(parts[:-1] if is_package else parts)
        sources[name] = (path.read_text(encoding="utf-8"), is_package)
    return sources


def _resolve(name: str, modules: set[str]) -> str:
    """The module ``name`` refers to: itself, else its longest prefix that is a module."""
    candidate = name
    while candidate not in modules and "." in candidate:
        candidate = candidate.rsplit(".", 1)[0]
    return candidate if candidate in modules else name


def import_graph(sources: dict[str, tuple[str, bool]], root: str = "drivelab") -> nx.DiGraph:
    """Importer → imported edges between the modules of ``sources`` (imports of ``root`` only),
    each edge with the ``line`` of its first import."""
    modules = set(sources)
    graph = nx.DiGraph()
    graph.add_nodes_from(modules)
    for module, (text, is_package) in sources.items():
        package = module if is_package else module.rpartition(".")[0]
        for node in ast.walk(ast.parse(text, filename=module)):
            targets = []
            if isinstance(node, ast.Import):
                targets = [_resolve(alias.name, modules) for alias in node.names]
            elif isinstance(node, ast.ImportFrom):
                if node.level:  # from . import x / from ..y import z
                    base = package.split(".")[: len(package.split(".")) - node.level + 1]
                    base = ".".join(base + ([node.module] if node.module else []))
                else:
                    base = node.module or ""
                for alias in node.names:  # ``from package import module`` imports the module
                    submodule = f"{base}.{alias.name}"
                    targets.append(submodule if submodule in modules else _resolve(base, modules))
            for target in targets:
                if (target == root or target.startswith(root + ".")) and target != module:
                    if not graph.has_edge(module, target):
                        graph.add_edge(module, target, line=node.lineno)
    return graph


def _matches(module: str, prefix: str) -> bool:
    # a dotted prefix covers its submodules; the bare top-level package covers only itself
    return module == prefix or ("." in prefix and module.startswith(prefix + "."))


def layer_of(module: str, layers: tuple[Layer, ...]) -> Layer | None:
    """The layer of ``module``: the one with its longest matching prefix (None: unmapped)."""
    best = max(
        ((len(prefix), layer) for layer in layers for prefix in layer.prefixes if _matches(module, prefix)),
        key=lambda pair: pair[0],
        default=None,
    )
    return best[1] if best else None


def allowed(importer: Layer, imported: Layer) -> bool:
    """Whether a module of ``importer`` may import one of ``imported``."""
    if importer.name == imported.name:
        return True
    if importer.may_import is not None:
        return imported.name in importer.may_import
    return imported.rank < importer.rank


def layer_problems(graph: nx.DiGraph, layers: tuple[Layer, ...]) -> dict[tuple[str, str], str]:
    """Every edge that does not point down (and every module no layer holds), with why."""
    problems = {}
    for module in sorted(graph.nodes):
        if layer_of(module, layers) is None:
            problems[(module, module)] = f"{module} belongs to no layer: add it to LAYERS"
    for importer, imported, data in sorted(graph.edges(data=True)):
        source, target = layer_of(importer, layers), layer_of(imported, layers)
        if source is not None and target is not None and not allowed(source, target):
            direction = "up" if target.rank > source.rank else "sideways"
            problems[(importer, imported)] = (
                f"{importer} (line {data['line']}, layer {source.name}) imports {imported} "
                f"(layer {target.name}): {direction}"
            )
    return problems


def cycles(graph: nx.DiGraph) -> list[list[str]]:
    """One cycle (a closed list of modules) per strongly connected component of two or more files."""
    found = []
    for component in nx.strongly_connected_components(graph):
        if len(component) > 1:
            edges = nx.find_cycle(graph.subgraph(component))
            found.append([edge[0] for edge in edges] + [edges[0][0]])
    return sorted(found)


def check(graph: nx.DiGraph, layers: tuple[Layer, ...], known: dict[tuple[str, str], str]) -> list[str]:
    """Everything wrong with ``graph``: layer violations and cycles not in ``known``, and entries of
    ``known`` that no longer occur or no longer break the layering."""
    messages = []
    violations = layer_problems(graph, layers)
    messages += [message for edge, message in violations.items() if edge not in known]
    in_cycle = {
        (a, b)
        for component in nx.strongly_connected_components(graph)
        for a, b in graph.subgraph(component).edges
    }
    for importer, imported in sorted(known):
        if not graph.has_edge(importer, imported):
            messages.append(f"stale KNOWN_VIOLATIONS entry: {importer} no longer imports {imported}")
        elif (importer, imported) not in violations and (importer, imported) not in in_cycle:
            messages.append(f"stale KNOWN_VIOLATIONS entry: {importer} → {imported} breaks no rule now")
    tolerated = graph.copy()
    tolerated.remove_edges_from(known)
    for cycle in cycles(tolerated):
        steps = [
            f"{a} (line {tolerated.edges[a, b]['line']})" for a, b in zip(cycle, cycle[1:], strict=False)
        ]
        messages.append("import cycle: " + " → ".join(steps + [cycle[-1]]))
    return messages


# --- drivelab itself -----------------------------------------------------------------------------
def test_drivelab_imports_point_down_and_form_no_cycle():
    graph = import_graph(module_sources(PACKAGE_DIR))
    assert len(graph) > 50 and graph.number_of_edges() > 100  # the walk found the package
    problems = check(graph, LAYERS, KNOWN_VIOLATIONS)
    assert not problems, "\n".join(problems)


def test_layer_table_places_the_modules_it_names():
    placed = {module: layer_of(module, LAYERS).name for module in module_sources(PACKAGE_DIR)}
    assert placed["drivelab.world.batch"] == "base"
    assert placed["drivelab.sim.core.traffic"] == "sim" and placed["drivelab.sim.junctions.rules"] == "sim"
    assert placed["drivelab.scenarios.circuits.reference_env"] == "scenarios"
    assert placed["drivelab.scenarios.town.simulator"] == "scenarios"
    assert placed["drivelab.envs.core"] == "envs" and placed["drivelab"] == "api"
    assert placed["drivelab.api"] == "api"
    assert placed["drivelab.training.run"] == "training" and placed["drivelab.cli"] == "cli"
    assert placed["drivelab.__main__"] == "cli"


def test_every_folder_is_a_layer():
    """Each package folder of ``drivelab/`` belongs to exactly one layer, named by its folder (a
    layer is a folder; the bottom layer also holds single modules)."""
    folders = sorted(path.name for path in PACKAGE_DIR.iterdir() if (path / "__init__.py").is_file())
    owners = {folder: [L.name for L in LAYERS if f"drivelab.{folder}" in L.prefixes] for folder in folders}
    assert all(len(names) == 1 for names in owners.values()), owners
    for layer in LAYERS:  # no layer reaches into another folder by a deeper prefix
        assert all(prefix.count(".") <= 1 for prefix in layer.prefixes), layer


# --- the checker on synthetic packages: it can fail -------------------------------------------------
TOY_LAYERS = (Layer("low", 0, ("toy.low",)), Layer("high", 1, ("toy.high",)), Layer("top", 2, ("toy",)))


def _toy(**modules: str) -> dict[str, tuple[str, bool]]:
    sources = {"toy": ("", True), "toy.low": ("", True), "toy.high": ("", True)}
    sources.update({name.replace("__", "."): (text, False) for name, text in modules.items()})
    return sources


def test_checker_reports_an_upward_import_inside_a_function():
    graph = import_graph(
        _toy(
            toy__low__a="import os\n\ndef f():\n    from ..high.b import thing\n", toy__high__b="thing = 1\n"
        ),
        root="toy",
    )
    assert graph.has_edge("toy.low.a", "toy.high.b")
    problems = check(graph, TOY_LAYERS, {})
    assert problems == ["toy.low.a (line 4, layer low) imports toy.high.b (layer high): up"]
    assert check(graph, TOY_LAYERS, {("toy.low.a", "toy.high.b"): "tolerated"}) == []


def test_checker_reports_a_two_file_cycle_by_name():
    graph = import_graph(
        _toy(toy__high__a="from toy.high import b\n", toy__high__b="from . import a\n"), root="toy"
    )
    problems = check(graph, TOY_LAYERS, {})
    assert len(problems) == 1 and problems[0].startswith("import cycle: ")
    assert "toy.high.a (line 1)" in problems[0] and "toy.high.b (line 1)" in problems[0]


def test_checker_reports_stale_known_entries_and_sideways_imports():
    layers = (*TOY_LAYERS, Layer("side", 1, ("toy.side",), may_import=frozenset({"low"})))
    graph = import_graph(
        _toy(toy__side="import toy.high.b\n", toy__high__b="import toy.low.c\n", toy__low__c=""), root="toy"
    )
    known = {("toy.high.b", "toy.low.c"): "points down", ("toy.low.c", "toy.high.b"): "gone"}
    assert check(graph, layers, known) == [
        "toy.side (line 1, layer side) imports toy.high.b (layer high): sideways",
        "stale KNOWN_VIOLATIONS entry: toy.high.b → toy.low.c breaks no rule now",
        "stale KNOWN_VIOLATIONS entry: toy.low.c no longer imports toy.high.b",
    ]

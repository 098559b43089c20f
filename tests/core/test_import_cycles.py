"""No import cycles between the modules of the library, the service and the worker (imports inside functions
included, package __init__s too): a cycle hides a missing layer and makes import order matter."""

from __future__ import annotations

import ast
import re
from pathlib import Path

import networkx as nx

ROOT = Path(__file__).resolve().parents[2]
PKG = ROOT / "pdeanim"
PACKAGES = ("pdeanim", "service", "worker")
INSTALLED = {"pdeanim": "pdeanim", "service": "pdeanim_service", "worker": "pdeanim_worker"}
"""Each folder and the package name it installs as (setup.py), the name its modules import it by."""


def _module_name(path: Path) -> str:
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    parts[0] = INSTALLED[parts[0]]
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _imports(path: Path, name: str, known: set[str]) -> set[str]:
    """The modules of ``known`` that ``path`` imports anywhere in its body: ``from p import m`` counts as an
    import of module p.m where that is one, else of p."""
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    found = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            targets = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                anchor = package.split(".")[: len(package.split(".")) - node.level + 1]
                base = ".".join([*anchor, base] if base else anchor)
            targets = [f"{base}.{a.name}" if f"{base}.{a.name}" in known else base for a in node.names]
        else:
            continue
        found |= {t for t in targets if t in known}
    return found - {name}


def import_graph(packages: tuple[str, ...] = ("pdeanim",), inits: bool = False) -> nx.DiGraph:
    """Who imports whom among the modules of ``packages`` (their __init__s too with ``inits``)."""
    files = {_module_name(p): p for pkg in packages for p in (ROOT / pkg).rglob("*.py")}
    modules = {n for n, p in files.items() if inits or p.name != "__init__.py"}
    graph = nx.DiGraph()
    for name in modules:
        graph.add_node(name)
        graph.add_edges_from((name, dep) for dep in _imports(files[name], name, modules))
    return graph


def test_graph_sees_the_imports() -> None:
    graph = import_graph()
    assert graph.number_of_nodes() > 40
    assert graph.has_edge("pdeanim.gltf.read", "pdeanim.poses")  # a known import, as a check of the parser


def test_library_has_no_import_cycles() -> None:
    cycles = sorted(sorted(c) for c in nx.simple_cycles(import_graph()))
    assert cycles == [], cycles


def test_library_service_and_worker_have_no_import_cycles() -> None:
    graph = import_graph(PACKAGES, inits=True)
    # a check of the parser
    assert graph.has_edge("pdeanim_service.store.queue", "pdeanim_service.store.parents")
    assert graph.has_edge("pdeanim_worker.windowtasks", "pdeanim_worker.clipstore")
    cycles = sorted(sorted(c) for c in nx.simple_cycles(graph))
    assert cycles == [], cycles


def _subpackage(module: str) -> str:
    """pdeanim.model.spline -> pdeanim.model; top-level modules (pdeanim.clip) stand for themselves."""
    parts = module.split(".")
    return ".".join(parts[:2])


def test_subpackages_import_one_way():
    """Between subpackages (model, curves, fit, cyclic, gltf, sim, cli, ...) and top-level modules, imports
    run one way: the graph of who imports whom has no cycle (e.g. curves may use the model, then the model
    never uses curves)."""
    graph = import_graph()
    packages = nx.DiGraph()
    packages.add_edges_from((_subpackage(a), _subpackage(b)) for a, b in graph.edges
                            if _subpackage(a) != _subpackage(b))
    cycles = sorted(sorted(c) for c in nx.simple_cycles(packages))
    assert cycles == [], cycles
    assert packages.has_edge("pdeanim.curves", "pdeanim.model")  # the floor uses the model's space basis
    assert packages.has_edge("pdeanim.fit", "pdeanim.curves")
    assert packages.has_edge("pdeanim.fit", "pdeanim.model")


def test_no_module_is_imported_by_name():
    """Every import in the library, the service and the worker is a plain import statement the graphs above
    see: no importlib.import_module, __import__ or "module:callable" strings (a registry of names hides its
    edges from the cycle tests). A string naming its own module (uvicorn's app factory with several HTTP
    processes, which needs one) hides no edge."""
    dynamic = []
    for path in (p for pkg in PACKAGES for p in (ROOT / pkg).rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Call):
                f = node.func
                name = f.attr if isinstance(f, ast.Attribute) else getattr(f, "id", "")
                if name in ("import_module", "__import__", "spec_from_file_location"):
                    dynamic.append(f"{path.relative_to(ROOT)}:{node.lineno}")
            elif isinstance(node, ast.Constant) and isinstance(node.value, str):
                named = re.fullmatch(r"((pdeanim|service|worker)(\.\w+)+):\w+", node.value)
                if named and named.group(1) != _module_name(path):
                    dynamic.append(f"{path.relative_to(ROOT)}:{node.lineno} {node.value!r}")
    assert dynamic == [], dynamic

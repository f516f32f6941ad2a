"""The import graph of prsm_fmu is acyclic and follows the layers of docs/architecture.md §2.

The graph is built from the source with :mod:`ast` (no module is imported), counting every
import statement, including those inside functions: a function-level import that closes a cycle
still makes the modules depend on each other.  Importing ``a.b.c`` also runs the ``__init__`` of
``a.b``, so an import adds an edge to every package on the way that is not already a package of
the importing module.

Layers, lowest first (a module may import its own layer or lower ones, never a higher one):

0. ``params``, ``geometry``, ``friction`` — parameter types and the laws they feed; ``units``
   (the unit spellings) and ``profiles`` (prescribed speed profiles), which import nothing;
1. ``mechanics``, ``kinematics`` — the mechanism's equations;
2. ``models``, ``steppers`` (siblings: a stepper knows a model only by its protocol, so
   ``steppers`` never imports ``models``) and ``presets`` (parameter sets built from the types
   below);
3. ``simulate``, ``steady_state`` and the package's ``__init__`` that re-exports them,
   ``engine`` (which steps a model: the compiled core or the Python steppers) and ``compiled``
   (C compiled with gcc on first use and cached: the engine's, the CSV formatter's);
4. ``slave`` and ``configure`` — what the FMU needs, with ``fmu_state`` (its serialized state)
   and ``fmu_exit`` (its exit-time guard);
5. the tools that use the package: ``cli``, ``report``, ``results`` (what they read off a run),
   ``design_checks``, ``sweep``, ``regress``, ``arguments`` (their argument checks),
   ``fmu_log``, ``fmu_variables``, ``fmi_enum`` and ``result_plot`` (what a host reads off an
   FMU), ``atomic`` (outputs written whole), ``command`` and ``extras`` (how a command ends:
   Ctrl-C, a missing optional extra), ``csv_format``, ``csv_compiled``, ``figures`` and ``png``
   (how results are written: CSV text, its compiled formatter, figure setup, the PNG encoder),
   ``workers`` (processes started ahead of their work).

Layers 0–3 (the physics and its time stepping) import neither an FMI library nor the tools
outside the package (``system_models``, ``fmu_build``), with one exception: ``engine`` imports
the compiled core's ctypes interface, ``fmu_build.native_stepper`` (where the C lives; inside
an FMU its packed copy), and nothing else of ``fmu_build``.
"""

from __future__ import annotations

import ast
from pathlib import Path

import prsm_fmu

PACKAGE_DIR = Path(prsm_fmu.__file__).parent

#: layer of each top-level module or subpackage of prsm_fmu ("" is the package's __init__)
LAYERS = {
    "params": 0, "param_ranges": 0, "geometry": 0, "friction": 0, "units": 0, "profiles": 0,
    "schedule": 0,
    "mechanics": 1, "kinematics": 1,
    "models": 2, "steppers": 2, "presets": 2,
    "simulate": 3, "steady_state": 3, "": 3, "engine": 3, "compiled": 3,
    "slave": 4, "configure": 4, "fmu_state": 4, "fmu_exit": 4,
    "cli": 5, "report": 5, "results": 5, "design_checks": 5, "sweep": 5, "regress": 5,
    "arguments": 5, "fmu_log": 5, "fmu_variables": 5, "result_plot": 5, "fmi_enum": 5,
    "atomic": 5, "command": 5, "extras": 5, "csv_format": 5, "csv_compiled": 5,
    "figures": 5, "png": 5, "workers": 5,
}

#: top-level names the physics layers (0-3) must not import
FORBIDDEN_BELOW_TOOLS = ("fmpy", "pythonfmu", "system_models", "fmu_build")


def _modules() -> dict[str, Path]:
    """Dotted name -> file of every module of the package (packages by their __init__)."""
    mods = {}
    for path in PACKAGE_DIR.rglob("*.py"):
        rel = path.relative_to(PACKAGE_DIR.parent).with_suffix("")
        parts = list(rel.parts)
        if parts[-1] == "__init__":
            parts.pop()
        mods[".".join(parts)] = path
    return mods


def _imports(name: str, path: Path, modules: dict[str, Path]) -> tuple[set[str], set[str]]:
    """Modules of the package that ``name`` imports (graph edges) and the top-level names of
    the other modules it imports."""
    is_pkg = path.name == "__init__.py"
    package = name if is_pkg else name.rpartition(".")[0]
    targets: set[str] = set()
    external: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"), str(path))):
        found: list[str] = []
        if isinstance(node, ast.Import):
            found = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base_parts = package.split(".")
                base_parts = base_parts[:len(base_parts) - (node.level - 1)]
                base = ".".join(base_parts + ([node.module] if node.module else []))
            else:
                base = node.module or ""
            found = [base]
            # "from pkg import sub" imports the submodule pkg.sub
            found += [f"{base}.{a.name}" for a in node.names if f"{base}.{a.name}" in modules]
        for target in found:
            if target.split(".")[0] != "prsm_fmu":
                external.add(target.split(".")[0])
                continue
            parts = target.split(".")
            # the module itself and every package on the way that the importer is not inside
            for k in range(len(parts), 0, -1):
                mod = ".".join(parts[:k])
                if mod in modules and mod != name and not name.startswith(mod + "."):
                    targets.add(mod)
    return targets, external


def _graph() -> tuple[dict[str, set[str]], dict[str, set[str]]]:
    modules = _modules()
    edges, external = {}, {}
    for name, path in modules.items():
        edges[name], external[name] = _imports(name, path, modules)
    return edges, external


def _layer(name: str) -> int:
    top = name.split(".")[1] if "." in name else ""
    assert top in LAYERS, (f"module {name} has no layer: add it to LAYERS in tests/test_layers.py "
                           "(and to the layers of docs/architecture.md §2)")
    return LAYERS[top]


def _cycle(edges: dict[str, set[str]]) -> list[str] | None:
    """One cycle of the graph as a list of modules (first == last), None if it is acyclic."""
    state: dict[str, int] = {}  # 1: on the current path, 2: done
    path: list[str] = []

    def visit(v: str) -> list[str] | None:
        state[v] = 1
        path.append(v)
        for w in sorted(edges[v]):
            if state.get(w) == 1:
                return path[path.index(w):] + [w]
            if w not in state:
                found = visit(w)
                if found:
                    return found
        state[v] = 2
        path.pop()
        return None

    for v in sorted(edges):
        if v not in state:
            found = visit(v)
            if found:
                return found
    return None


def test_graph_sees_the_known_imports():
    # guards the parser itself: a graph that missed imports would pass every test below
    edges, external = _graph()
    assert "prsm_fmu.mechanics" in edges["prsm_fmu.models.base"]           # from ..mechanics import
    assert "prsm_fmu.steppers" in edges["prsm_fmu.simulate"]                # from .steppers import
    assert "prsm_fmu.steppers.base" in edges["prsm_fmu.steppers.rk4"]       # from .base import
    assert "prsm_fmu.presets" in edges["prsm_fmu.cli"]                      # from . import presets
    assert "prsm_fmu.sweep" in edges["prsm_fmu.cli"]                        # inside a function
    assert "prsm_fmu.sweep.study" in edges["prsm_fmu.cli"]                  # from .sweep.study import
    assert "system_models" in external["prsm_fmu.regress.core"]


def test_import_graph_is_acyclic():
    cycle = _cycle(_graph()[0])
    assert cycle is None, "import cycle: " + " -> ".join(cycle)


def test_no_module_imports_a_higher_layer():
    edges, _ = _graph()
    bad = [f"{a} (layer {_layer(a)}) imports {b} (layer {_layer(b)})"
           for a, targets in sorted(edges.items()) for b in sorted(targets) if _layer(b) > _layer(a)]
    assert not bad, "\n".join(bad)


def test_steppers_know_models_only_by_their_protocol():
    edges, _ = _graph()
    bad = [f"{a} imports {b}" for a, targets in sorted(edges.items()) if a.startswith("prsm_fmu.steppers")
           for b in sorted(targets) if b.startswith("prsm_fmu.models")]
    assert not bad, "\n".join(bad)


#: the one module of the physics layers that imports fmu_build: the engine's interface
ENGINE_DOOR = "prsm_fmu.engine"


def test_physics_imports_no_fmi_library_and_no_tool():
    _, external = _graph()
    bad = [f"{a} imports {b}" for a, names in sorted(external.items()) if _layer(a) <= 3
           for b in sorted(names) if b in FORBIDDEN_BELOW_TOOLS
           and not (a == ENGINE_DOOR and b == "fmu_build")]
    assert not bad, "\n".join(bad)
    assert "fmu_build" in external[ENGINE_DOOR]      # the exception is real (parser guard)


def test_the_engine_door_imports_only_the_interface_of_fmu_build():
    text = (PACKAGE_DIR / "engine.py").read_text(encoding="utf-8")
    tree = ast.parse(text)
    found = [(n.module, [a.name for a in n.names]) for n in ast.walk(tree)
             if isinstance(n, ast.ImportFrom) and (n.module or "").startswith("fmu_build")]
    assert found and all(m == "fmu_build" and names == ["native_stepper"] for m, names in found)

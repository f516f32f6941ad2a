"""What the pythonfmu FMU carries in ``resources/``: what runs inside it, nothing else.

* ``prsm_fmu/``: the modules the slave imports, directly or on demand (followed
  from :mod:`prsm_fmu.slave` and :mod:`prsm_fmu.engine`, imports made on demand included), and the presets;
  not the tools (command line, sweeps, regression runner, reports, plotting);
* ``prsm_engine_interface.py``: the engine's ctypes interface (:mod:`fmu_build.native_stepper`
  under a name of its own, which never shadows the ``fmu_build`` of a process that has one);
  not the FMU builders;
* ``binaries/<platform>/prsm_engine.{so,dll}``: the compiled engine (the native FMU's C model
  and steppers with the flat interface ``prsm_api.c``; it solves the contact of the geometry
  each instance sets, the build's being its default), for linux64
  (glibc 2.17 and later) and win64, cross-compiled here with Zig's C compiler and checked (gcc
  for this platform alone where ziglang is missing), so that no compiler is needed where the
  FMU runs, and
  ``prsm_engine.json``: the geometry parameters it was built with (read for a library of an
  older build, which baked them in: an instance whose geometry differs then runs the Python
  model, logged);
* ``prsm_start_values.json``: the parameters' start values, read by every instance;
* ``__pycache__/*.cpython-XY.pyc`` beside every packed Python file (:func:`add_bytecode`):
  its bytecode for the building interpreter's version, checked against the source's hash at
  every import (``CHECKED_HASH``: a changed source is compiled anew, never run stale); a host
  extracts the FMU into a fresh folder at every start, where Python would otherwise compile
  every module again (0.4 s of the FMU's 0.7 s start-up, ``benchmarks/command_cost.py
  --startup-only``).  Another Python version ignores them.
"""

from __future__ import annotations

import ast
import importlib.util
import json
import py_compile
import shutil
import tempfile
import zipfile
from pathlib import Path

import prsm_fmu
from prsm_fmu.engine import PACKED_INTERFACE, library_name, platform_folder
from prsm_fmu.params import MechanismParams
from prsm_fmu.slave import ENGINE_FILE, START_VALUES_FILE

__all__ = ["runtime_modules", "stage_runtime", "stage_engine", "stage_start_values",
           "add_bytecode"]

#: the modules the slave needs, besides what they import
ROOTS = ("prsm_fmu.slave", "prsm_fmu.engine")
#: packages loaded by name at run time (modulefinder cannot see them): packed whole
WHOLE_PACKAGES = ("prsm_fmu.presets",)


def _imports(path: Path, module: str, is_package: bool) -> set[str]:
    """The absolute names of every module ``path`` imports, at any depth of its code (the
    imports inside functions too: those made on demand)."""
    tree = ast.parse(path.read_text(encoding="utf-8"))
    package = module if is_package else module.rpartition(".")[0]
    names: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = package
            for _ in range(node.level - 1):
                base = base.rpartition(".")[0]
            stem = node.module or ""
            head = f"{base}.{stem}".strip(".") if node.level else stem
            names.add(head)
            names.update(f"{head}.{a.name}" for a in node.names)
    return names


def runtime_modules() -> list[Path]:
    """The files of :mod:`prsm_fmu` the FMU runs (the slave's and the engine door's imports,
    followed through the package), relative to the package's parent folder."""
    root = Path(prsm_fmu.__file__).resolve().parent.parent

    def file_of(name: str) -> tuple[Path, bool] | None:
        base = root.joinpath(*name.split("."))
        if (base / "__init__.py").is_file():
            return base / "__init__.py", True
        if base.with_suffix(".py").is_file():
            return base.with_suffix(".py"), False
        return None

    todo = list(ROOTS) + [f"{p}.{f.stem}" for p in WHOLE_PACKAGES
                          for f in root.joinpath(*p.split(".")).glob("*.py")
                          if f.stem != "__init__"]
    seen: dict[str, Path] = {}
    while todo:
        name = todo.pop()
        parts = name.split(".")
        # a module's packages are imported with it
        for i in range(1, len(parts) + 1):
            sub = ".".join(parts[:i])
            if sub in seen or parts[0] != "prsm_fmu":
                continue
            found = file_of(sub)
            if found is None:
                continue
            seen[sub] = found[0]
            todo.extend(_imports(found[0], sub, found[1]))
    return sorted(f.relative_to(root) for f in seen.values())


def stage_runtime(dest: Path) -> list[Path]:
    """Copy the runtime modules and the engine interface into ``dest``; the folders created
    (pythonfmu's project files)."""
    root = Path(prsm_fmu.__file__).resolve().parent.parent
    for rel in runtime_modules():
        (dest / rel).parent.mkdir(parents=True, exist_ok=True)
        shutil.copy2(root / rel, dest / rel)
    interface = dest / f"{PACKED_INTERFACE}.py"
    shutil.copy2(Path(__file__).resolve().parent / "native_stepper.py", interface)
    return [dest / "prsm_fmu", interface]


def stage_engine(dest: Path, params: MechanismParams,
                 platforms: tuple[str, ...] | None = None) -> list[Path]:
    """Build the engine for ``params``' geometry into ``dest/binaries/<platform>/`` for this
    platform and ``platforms`` (of :data:`fmu_build.platforms.PYTHONFMU_PLATFORMS`, the
    platforms pythonfmu ships a wrapper for: cross-compiled with Zig's C compiler and checked,
    :mod:`fmu_build.engine_library`), and describe it in ``dest/prsm_engine.json``; the project
    files created.  Without ziglang, this platform's library is compiled with gcc instead (and
    the others are left out).  Only this platform by default: a machine's first Windows build
    also compiles Zig's Windows C runtime (minutes), which ``prsm-ema run``'s automatic build
    should not wait for.

    Raises
    ------
    fmu_build.builder.BuildError
        When no library can be built for this platform (no ziglang and no gcc).
    """
    from .engine_library import build_engine_library
    from .errors import BuildError
    from .native import STRUCTURAL
    from .platforms import PYTHONFMU_PLATFORMS

    here = platform_folder()
    built = []
    wanted = dict.fromkeys((here, *(platforms or ())))
    for plat in (p for p in PYTHONFMU_PLATFORMS if p in wanted):
        try:
            built.append(build_engine_library(params, plat, dest / "binaries" / plat))
        except BuildError:
            if plat != here:
                continue
            from .native_stepper import library_file   # no ziglang: gcc, this platform only

            folder = dest / "binaries" / here
            folder.mkdir(parents=True, exist_ok=True)
            shutil.copy2(library_file(params), folder / library_name())
            built.append(folder / library_name())
    if not built:
        raise BuildError("no engine library could be built for any platform")
    geometry = {f"stage[{k}].{f}": getattr(st, f)
                for k, st in enumerate(params.stages, start=1) for f in STRUCTURAL}
    (dest / ENGINE_FILE).write_text(json.dumps({"geometry": geometry}, indent=1),
                                    encoding="utf-8")
    return [dest / "binaries", dest / ENGINE_FILE]


def stage_start_values(dest: Path, values: dict) -> Path:
    """Write the start values (parameter name -> value) as ``dest/prsm_start_values.json``."""
    path = dest / START_VALUES_FILE
    path.write_text(json.dumps(values, indent=1), encoding="utf-8")
    return path


def add_bytecode(fmu: Path) -> int:
    """Add to the FMU zip ``fmu`` the bytecode of every ``resources/**.py`` it holds (the
    slave, prsm_fmu, pythonfmu's package, the engine interface): ``__pycache__/<stem>.<tag>.pyc``
    beside each, compiled by this interpreter with hash-checked invalidation.  Returns how many
    were added.

    Raises
    ------
    py_compile.PyCompileError
        When a packed source does not compile (it could not run either).
    """
    with zipfile.ZipFile(fmu) as z:
        sources = {n: z.read(n) for n in z.namelist()
                   if n.startswith("resources/") and n.endswith(".py")}
    with tempfile.TemporaryDirectory(prefix="prsm_pyc_") as tmp:
        added = {}
        for name, data in sources.items():
            src = Path(tmp, name)
            src.parent.mkdir(parents=True, exist_ok=True)
            src.write_bytes(data)
            pyc = Path(importlib.util.cache_from_source(str(src)))
            py_compile.compile(str(src), cfile=str(pyc), dfile=name, doraise=True,
                               invalidation_mode=py_compile.PycInvalidationMode.CHECKED_HASH)
            added[pyc.relative_to(tmp).as_posix()] = pyc.read_bytes()
    with zipfile.ZipFile(fmu, "a", compression=zipfile.ZIP_DEFLATED) as z:
        for name, data in sorted(added.items()):
            z.writestr(name, data)
    return len(added)

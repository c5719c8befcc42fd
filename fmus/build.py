"""Build the toolkit's FMI 2.0 co-simulation FMUs (pythonfmu-style slaves, our native layer).

``build_fmus(out_dir)`` writes ``AbuBall.fmu``, ``SpeedController.fmu`` and ``Staircase.fmu``.
Each FMU is self-contained apart from a Python interpreter (standard library only):

* the slave script is renamed to a module name unique across the toolkit
  (``abufmu_abuball`` ...), because every Python FMU loaded in one process shares one
  interpreter and one ``sys.modules``;
* the project modules it needs (``abu_model``, ``controller``; only those its imports reach,
  :func:`module_closure`) are copied into the FMU's resources under package names unique per
  FMU (``abuball_abu_model`` ...), and pythonfmu's runtime part as ``<module>_pythonfmu``. \
Their absolute imports of
  project packages are rewritten to the vendored names here, and a build fails if a vendored
  file imports a project package that is not vendored with it, so an FMU never picks up
  another installed version of the toolkit;
* :mod:`fmus.assemble` writes the FMU with the native layer compiled for it (C compiler
  needed) and the Python runtime; the model description from pythonfmu's ``to_xml`` is fixed
  (units, output dependencies, InitialUnknowns; see :mod:`fmus.model_description`) and the
  FMU is written atomically.
"""
from __future__ import annotations

import ast
import importlib
import re
import sys
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import Mapping

from .assemble import assemble_fmu, vendor_pythonfmu
from .model_description import FmuBuildError, InterfaceSpec, rewrite_fmu_model_description

HERE = Path(__file__).resolve().parent

#: Top-level packages of this project: a vendored file may import them only when they are
#: vendored into the same FMU (the import is then rewritten to the vendored name).
PROJECT_PACKAGES = ("abu", "abu_model", "controller", "fmus", "harness", "measurement", "twin")

#: FMI options written into every FMU's <CoSimulation> element.
FMU_OPTIONS = {
    "canGetAndSetFMUstate": True,
    "canSerializeFMUstate": True,
    "canHandleVariableCommunicationStepSize": True,
}


@dataclass(frozen=True)
class FmuSpec:
    """How one FMU is built.

    Attributes:
        name: model identifier and class name of the slave (also the FMU's file stem).
        script: slave script file in the ``fmus`` package.
        module: module name of the script inside the FMU (unique across the toolkit).
        vendored: (project package, name inside the FMU) pairs.
    """

    name: str
    script: str
    module: str
    vendored: tuple[tuple[str, str], ...]


FMU_SPECS: tuple[FmuSpec, ...] = (
    FmuSpec("AbuBall", "abu_ball_slave.py", "abufmu_abuball",
            (("abu_model", "abuball_abu_model"),)),
    FmuSpec("SpeedController", "speed_controller_slave.py", "abufmu_speedcontroller",
            (("controller", "speedcontroller_controller"),
             ("abu_model", "speedcontroller_abu_model"))),
    FmuSpec("Staircase", "staircase_slave.py", "abufmu_staircase",
            (("controller", "staircase_controller"), ("abu_model", "staircase_abu_model"))),
)

FMU_NAMES: tuple[str, ...] = tuple(spec.name for spec in FMU_SPECS)


def _package_dir(package: str) -> Path:
    """Source folder of a project package (the one this interpreter imports)."""
    if package not in PROJECT_PACKAGES:
        raise FmuBuildError(f"'{package}' is not a package of this project: "
                            f"expected one of {', '.join(PROJECT_PACKAGES)}")
    module = importlib.import_module(package)
    # __path__, not __file__: an editable install made before a package had its __init__.py
    # maps it as a namespace package (no __file__) outside the source tree.
    for entry in getattr(module, "__path__", []):
        if (Path(entry) / "__init__.py").is_file():
            return Path(entry).resolve()
    raise FmuBuildError(f"package '{package}' has no folder with an __init__.py "
                        f"(found {list(getattr(module, '__path__', []))})")


def _absolute_project_imports(tree: ast.AST) -> list[tuple[ast.stmt, str]]:
    """(import node, top-level package) for every absolute import of a project package or of
    pythonfmu (whose runtime part is vendored too)."""
    found = []
    vendorable = PROJECT_PACKAGES + ("pythonfmu",)
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for alias in node.names:
                top = alias.name.split(".")[0]
                if top in vendorable:
                    found.append((node, top))
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            top = node.module.split(".")[0]
            if top in vendorable:
                found.append((node, top))
    return found


def module_closure(script: Path, packages: Mapping[str, Path]) -> dict[str, set[Path]]:
    """The files of each project package that ``script`` needs, following its imports.

    Absolute imports of a package in ``packages`` (name -> folder) and relative imports inside
    those packages are followed; every package's ``__init__.py`` is included.
    """
    needed: dict[str, set[Path]] = {name: {folder / "__init__.py"}
                                    for name, folder in packages.items()}
    todo, seen = [script, *(f for files in needed.values() for f in files)], set()

    def add(package: str, parts: list[str]) -> None:
        base = packages[package].joinpath(*parts)
        for candidate in (base.with_suffix(".py"), base / "__init__.py"):
            if candidate.is_file():
                needed[package].add(candidate)
                todo.append(candidate)

    while todo:
        file = todo.pop()
        if file in seen:
            continue
        seen.add(file)
        owner = next((name for name, folder in packages.items() if folder in file.parents), None)
        for node in ast.walk(ast.parse(file.read_text(encoding="utf-8"), filename=str(file))):
            if isinstance(node, ast.ImportFrom):
                if node.level == 0 and node.module and node.module.split(".")[0] in packages:
                    package, parts = node.module.split(".")[0], node.module.split(".")[1:]
                elif node.level == 1 and owner is not None:
                    package, parts = owner, (node.module or "").split(".") if node.module else []
                else:
                    continue
                add(package, parts)
                for alias in node.names:  # "from pkg import module"
                    add(package, [*parts, alias.name])
            elif isinstance(node, ast.Import):
                for alias in node.names:
                    top, *parts = alias.name.split(".")
                    if top in packages:
                        add(top, parts)
    return needed


def rewrite_imports(source: str, renames: Mapping[str, str], filename: str = "<source>") -> str:
    """Rewrite ``from <pkg>... import`` of project packages to their vendored names.

    Raises:
        FmuBuildError: a plain ``import <pkg>`` of a project package (its uses could not be
            renamed safely), or an import of a project package missing from ``renames``.
    """
    tree = ast.parse(source, filename=filename)
    lines = source.splitlines(keepends=True)
    for node, top in _absolute_project_imports(tree):
        where = f"{filename}:{node.lineno}"
        if top not in renames:
            raise FmuBuildError(f"{where}: imports project package '{top}', which is not "
                                "vendored into this FMU "
                                f"(vendored: {', '.join(renames) or 'none'})")
        if isinstance(node, ast.Import):
            raise FmuBuildError(f"{where}: 'import {top}...' cannot be vendored; use "
                                f"'from {top}... import name' or a relative import")
        pattern = re.compile(rf"(\bfrom\s+){re.escape(top)}(?=[.\s])")
        first, last = node.lineno - 1, node.end_lineno
        statement = "".join(lines[first:last])
        new_statement, count = pattern.subn(rf"\g<1>{renames[top]}", statement, count=1)
        if count != 1:
            raise FmuBuildError(f"{where}: could not rewrite the import of '{top}'")
        # Keep line numbers: put the rewritten statement back on the same lines.
        new_lines = new_statement.splitlines(keepends=True)
        lines[first:last] = new_lines
    result = "".join(lines)
    leftover = [top for _, top in _absolute_project_imports(ast.parse(result, filename=filename))
                if top not in renames.values()]
    if leftover:
        raise FmuBuildError(f"{filename}: project imports left after vendoring: {leftover}")
    return result


def vendor_package(src: Path, dest: Path, renames: Mapping[str, str],
                   only: set[Path] | None = None) -> None:
    """Copy the package folder ``src`` (its .py files, or those in ``only``) to ``dest``,
    rewriting project imports."""
    if not (src / "__init__.py").is_file():
        raise FmuBuildError(f"{src}: not a Python package (no __init__.py)")
    for file in sorted(src.rglob("*.py")):
        if "__pycache__" in file.parts or (only is not None and file not in only):
            continue
        target = dest / file.relative_to(src)
        target.parent.mkdir(parents=True, exist_ok=True)
        text = file.read_text(encoding="utf-8")
        target.write_text(rewrite_imports(text, renames, str(file)), encoding="utf-8")


def _forget_modules(names: list[str]) -> None:
    """Drop modules imported from a staging folder so the next build imports afresh."""
    for key in list(sys.modules):
        if any(key == name or key.startswith(name + ".") for name in names):
            del sys.modules[key]


def _real_start_values(cls, resources: Path) -> dict[str, float]:
    """Start values of the Real parameters and inputs of a fresh slave instance."""
    instance = cls(instance_name="build", resources=str(resources))
    return {v.name: float(v.getter()) for v in instance.vars.values()
            if type(v).__name__ == "Real" and v.causality.name in ("parameter", "input")}


def _slave_class(module_name: str, class_name: str | None):
    """The slave class of the staged module (the named one, else the only Fmi2Slave subclass)."""
    module = importlib.import_module(module_name)
    candidates = [obj for obj in vars(module).values()
                  if isinstance(obj, type) and obj.__module__ == module_name
                  and any(base.__name__ == "Fmi2Slave" for base in obj.__mro__[1:])]
    if class_name is not None:
        candidates = [obj for obj in candidates if obj.__name__ == class_name]
    if len(candidates) != 1:
        raise FmuBuildError(f"{module_name}: expected one slave class"
                            f"{f' named {class_name!r}' if class_name else ''}, found "
                            f"{[c.__name__ for c in candidates]}")
    return candidates[0]


def build_slave_fmu(script: Path, module: str, vendored: Mapping[Path, str], target: Path,
                    class_name: str | None = None) -> Path:
    """Build one FMU from a slave script and fix its model description.

    Args:
        script: the slave script; its class defines ``UNITS`` and ``OUTPUT_DEPENDENCIES``.
        module: module name of the script inside the FMU.
        vendored: source package folder -> package name inside the FMU; only the modules the
            script needs (:func:`module_closure`) are copied.
        target: path of the FMU to write (atomically).
        class_name: expected slave class name (= model identifier), checked if given.

    Returns:
        ``target``.
    """
    pythonfmu_name = f"{module}_pythonfmu"
    renames = {src.name: name for src, name in vendored.items()}
    renames["pythonfmu"] = pythonfmu_name
    needed = module_closure(script, {src.name: src for src in vendored})
    with tempfile.TemporaryDirectory(prefix="abufmu_stage_") as tmp:
        stage = Path(tmp) / "stage"
        stage.mkdir()
        staged_script = stage / f"{module}.py"
        staged_script.write_text(
            rewrite_imports(script.read_text(encoding="utf-8"), renames, str(script)),
            encoding="utf-8")
        for src, name in vendored.items():
            vendor_package(src, stage / name, renames, needed[src.name])
        vendor_pythonfmu(stage / pythonfmu_name)
        forget = [module, pythonfmu_name, *vendored.values()]
        _forget_modules(forget)
        importlib.invalidate_caches()
        sys.path.insert(0, str(stage))
        try:
            cls = _slave_class(module, class_name)
            try:
                units, deps = dict(cls.UNITS), dict(cls.OUTPUT_DEPENDENCIES)
            except AttributeError as exc:
                raise FmuBuildError(f"{script}: the slave class must define UNITS and "
                                    f"OUTPUT_DEPENDENCIES ({exc})") from None
            spec = InterfaceSpec(units, deps, _real_start_values(cls, stage))
            raw = assemble_fmu(stage, module, cls, FMU_OPTIONS, Path(tmp) / "raw.fmu")
            return rewrite_fmu_model_description(raw, target, spec)
        finally:
            _forget_modules(forget)
            while str(stage) in sys.path:
                sys.path.remove(str(stage))


def build_fmu(name: str, out_dir: str | Path) -> Path:
    """Build the toolkit FMU ``name`` (one of :data:`FMU_NAMES`) into ``out_dir``."""
    specs = {spec.name: spec for spec in FMU_SPECS}
    if name not in specs:
        raise FmuBuildError(f"unknown FMU '{name}': expected one of {', '.join(FMU_NAMES)}")
    spec = specs[name]
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    vendored = {_package_dir(package): vendored_name for package, vendored_name in spec.vendored}
    return build_slave_fmu(HERE / spec.script, spec.module, vendored, out_dir / f"{name}.fmu",
                           class_name=spec.name)


def build_fmus(out_dir: str | Path) -> dict[str, Path]:
    """Build AbuBall.fmu, SpeedController.fmu and Staircase.fmu into ``out_dir``.

    Returns:
        FMU name -> path of the written FMU.
    """
    return {name: build_fmu(name, out_dir) for name in FMU_NAMES}

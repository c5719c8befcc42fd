"""The toolkit's FMU files for the experiments: built once per process or taken from a
folder (:func:`ensure_fmus`; a folder of the native build, :func:`fmu_dir_kind`, must hold
all three native FMUs), and which inputs and outputs a file has (:func:`has_input`,
:func:`has_output`: FMUs of an older interface lack the newer variables)."""
from __future__ import annotations

import tempfile
from pathlib import Path
from typing import Mapping

from abu_model.errors import ParameterError

FMU_FILES = ("AbuBall", "SpeedController", "Staircase")

_FMU_CACHE: dict[str, Path] | None = None
_FMU_CACHE_DIR: tempfile.TemporaryDirectory | None = None


def ensure_fmus(fmu_dir: str | Path | Mapping[str, Path] | None = None) -> dict[str, Path]:
    """Paths of AbuBall.fmu, SpeedController.fmu and Staircase.fmu.

    Args:
        fmu_dir: a mapping name -> path (as :func:`fmus.build.build_fmus` returns), a folder
            (missing FMUs are built into it), or None (built once per process into a
            temporary folder).
    """
    global _FMU_CACHE, _FMU_CACHE_DIR
    if isinstance(fmu_dir, Mapping):
        paths = {name: Path(fmu_dir[name]) for name in FMU_FILES if name in fmu_dir}
        missing = [n for n in FMU_FILES if n not in paths or not paths[n].is_file()]
        if missing:
            raise ParameterError("fmu_dir", dict(fmu_dir), f"paths of {', '.join(FMU_FILES)}")
        return paths
    from fmus.build import build_fmu

    if fmu_dir is None:
        if _FMU_CACHE is None:
            _FMU_CACHE_DIR = tempfile.TemporaryDirectory(prefix="abu_fmus_",
                                                         ignore_cleanup_errors=True)
            _FMU_CACHE = {name: build_fmu(name, _FMU_CACHE_DIR.name) for name in FMU_FILES}
        return dict(_FMU_CACHE)
    folder = Path(fmu_dir)
    if folder.exists() and not folder.is_dir():
        raise ParameterError("fmu_dir", str(fmu_dir), "a folder")
    if fmu_dir_kind(folder) == "native":  # complete (checked): nothing to build
        return {name: folder / f"{name}.fmu" for name in FMU_FILES}
    paths = {}
    for name in FMU_FILES:
        path = folder / f"{name}.fmu"
        paths[name] = path if path.is_file() else Path(build_fmu(name, folder))
    return paths


def fmu_dir_kind(fmu_dir: str | Path, parameter: str = "fmu_dir") -> str:
    """``"native"`` if the folder holds the native build's AbuBall, SpeedController and
    Staircase (:func:`fmus.native_build.build_native_fmus`), else ``"python"`` (the default
    pythonfmu FMUs, missing ones built there by :func:`ensure_fmus`).

    Raises:
        ParameterError (named ``parameter``): the folder has a native FMU beside a Python one
            or lacks one of the three native FMUs (a Python build would fill the gap: the
            co-simulation would mix the two builds).
    """
    folder = Path(fmu_dir)
    present = {name: folder / f"{name}.fmu" for name in FMU_FILES
               if (folder / f"{name}.fmu").is_file()}
    if not present:
        return "python"
    from fmus.native_build import is_native_fmu

    native = [name for name, path in present.items() if is_native_fmu(path)]
    if not native:
        return "python"
    other = [f"{name}.fmu" for name in present if name not in native]
    if other:
        raise ParameterError(parameter, str(fmu_dir), (
            f"a folder of one build, but {', '.join(f'{n}.fmu' for n in native)} "
            f"{'is' if len(native) == 1 else 'are'} native and {', '.join(other)} "
            f"{'is' if len(other) == 1 else 'are'} not: rebuild it with 'abu build-fmus "
            f"--native --out DIR' (or without --native for the Python FMUs)"))
    missing = [f"{name}.fmu" for name in FMU_FILES if name not in present]
    if missing:
        raise ParameterError(parameter, str(fmu_dir), (
            f"all three native FMUs, but {', '.join(missing)} "
            f"{'is' if len(missing) == 1 else 'are'} missing: rebuild them with 'abu build-fmus --native --out DIR'"))
    return "native"


_CAUSALITIES: dict[tuple[str, int], dict[str, str]] = {}


def _causalities(fmu: Path) -> dict[str, str]:
    """Variable name -> causality of an FMU file (its modelDescription read once per version)."""
    import fmpy

    path = Path(fmu)
    key = (str(path.resolve()), path.stat().st_mtime_ns)
    if key not in _CAUSALITIES:
        md = fmpy.read_model_description(str(path), validate=False)
        _CAUSALITIES[key] = {v.name: v.causality for v in md.modelVariables}
    return _CAUSALITIES[key]


def has_input(fmu: Path, name: str) -> bool:
    """True if the FMU file has an input variable ``name``."""
    return _causalities(fmu).get(name) == "input"


def has_output(fmu: Path, name: str) -> bool:
    """True if the FMU file has an output variable ``name``."""
    return _causalities(fmu).get(name) == "output"

"""Assemble an FMU from a staged slave: model description, resources, the native binary.

The FMU's binary is our own C layer (``fmus/native/abufmu.c``), compiled here with the
system C compiler (``$CC``, else ``cc`` or ``gcc``) for the FMU's GUID and runtime module; the
FMU's Python code is the slave script, the project modules it needs, the runtime-only part of
pythonfmu (vendored under an FMU-specific name) and the runtime module ``<module>_rt.py``.
Everything inside imports only the standard library (checked by the tests).
"""
from __future__ import annotations

import os
import shutil
import subprocess
import sys
import sysconfig
import tempfile
import zipfile
from pathlib import Path
from typing import Mapping
from xml.dom.minidom import parseString
from xml.etree.ElementTree import tostring

from .model_description import FmuBuildError

HERE = Path(__file__).resolve().parent
NATIVE_SOURCE = HERE / "native" / "abufmu.c"
RUNTIME_SOURCE = HERE / "fmu_runtime.py"
#: pythonfmu modules the slaves need at run time (its builder, CLI and C++ library are not
#: shipped: the FMU brings its own binary).
PYTHONFMU_RUNTIME_FILES = ("_version.py", "default_experiment.py", "enums.py", "fmi2slave.py",
                           "logmsg.py", "variables.py")
PYTHONFMU_INIT = ('''"""Runtime part of pythonfmu {version} (MIT licence), '''
                  '''vendored by the abu-friction build."""
from ._version import __version__
from .default_experiment import DefaultExperiment
from .enums import Fmi2Causality, Fmi2Initial, Fmi2Status, Fmi2Variability
from .fmi2slave import Fmi2Slave
from .variables import Boolean, Integer, Real, String
''')


def vendor_pythonfmu(dest: Path) -> None:
    """Copy pythonfmu's runtime modules into the package folder ``dest``."""
    import pythonfmu

    src = Path(pythonfmu.__file__).resolve().parent
    dest.mkdir(parents=True, exist_ok=True)
    for name in PYTHONFMU_RUNTIME_FILES:
        shutil.copy2(src / name, dest / name)
    (dest / "__init__.py").write_text(PYTHONFMU_INIT.format(version=pythonfmu.__version__),
                                      encoding="utf-8")
    licence = src.parent / f"pythonfmu-{pythonfmu.__version__}.dist-info" / "LICENSE"
    if licence.is_file():
        shutil.copy2(licence, dest / "LICENSE")


def write_runtime(dest: Path, module: str, class_name: str) -> Path:
    """Write ``<module>_rt.py``, the runtime the native layer imports, into ``dest``."""
    text = RUNTIME_SOURCE.read_text(encoding="utf-8")
    text = (text.replace('"@SLAVE_MODULE@"', repr(module))
            .replace('"@SLAVE_CLASS@"', repr(class_name)))
    target = dest / f"{module}_rt.py"
    target.write_text(text, encoding="utf-8")
    return target


def python_location() -> tuple[str, str]:
    """(libpython to load in a non-Python host, the home of its standard library)."""
    libdir = sysconfig.get_config_var("LIBDIR") or ""
    soname = sysconfig.get_config_var("INSTSONAME") or sysconfig.get_config_var("LDLIBRARY") or ""
    lib = os.path.join(libdir, soname) if libdir and soname else soname
    return lib, sys.base_prefix


def compiler() -> str:
    """The C compiler to use: $CC, else cc or gcc on PATH."""
    chosen = os.environ.get("CC", "").strip()
    if chosen:
        if shutil.which(chosen.split()[0]):
            return chosen
        raise FmuBuildError(f"the C compiler in CC = {chosen!r} was not found (unset CC to use "
                            "cc or gcc from PATH)")
    for candidate in ("cc", "gcc"):
        if shutil.which(candidate):
            return candidate
    raise FmuBuildError("no C compiler found (set CC, or install gcc): the FMUs' native layer "
                        f"({NATIVE_SOURCE.name}) is compiled when the FMUs are built")


def compile_native(target: Path, runtime_module: str, guid: str) -> Path:
    """Compile the native layer for one FMU into ``target`` (a shared library)."""
    if not all(ch.isalnum() or ch in "_" for ch in runtime_module) or '"' in guid or "\\" in guid:
        raise FmuBuildError(f"cannot compile for module {runtime_module!r} / guid {guid!r}")
    cc = compiler()
    command = [*cc.split(), "-shared", "-fPIC", "-O2", "-fvisibility=hidden",
               f'-DABU_RUNTIME="{runtime_module}"', f'-DABU_GUID="{guid}"',
               "-o", str(target), str(NATIVE_SOURCE), "-ldl", "-lpthread"]
    result = subprocess.run(command, capture_output=True, text=True)
    if result.returncode != 0:
        raise FmuBuildError(f"compiling {NATIVE_SOURCE.name} failed ({' '.join(command)}):\n"
                            f"{result.stderr.strip()}")
    return target


def assemble_fmu(stage: Path, module: str, cls: type, options: Mapping[str, bool],
                 target: Path) -> Path:
    """Write the (raw) FMU ``target`` from the staged Python files in ``stage``.

    The model description comes from the slave class (pythonfmu's ``to_xml``) with the
    co-simulation ``options``; :mod:`fmus.model_description` fixes it afterwards.
    """
    if sys.platform != "linux":
        raise FmuBuildError(f"the FMUs' native layer is built for Linux only, not {sys.platform}")
    instance = cls(instance_name="build", resources=str(stage))
    xml = instance.to_xml()
    co_sim = xml.find("CoSimulation")
    for option, value in options.items():
        co_sim.set(option, str(value).lower())
    guid = xml.get("guid")
    identifier = co_sim.get("modelIdentifier")
    write_runtime(stage, module, cls.__name__)
    lib, home = python_location()
    (stage / "abufmu_python.txt").write_text(f"{lib}\n{home}\n", encoding="utf-8")
    (stage / "slavemodule.txt").write_text(module, encoding="utf-8")  # as pythonfmu names it
    with tempfile.TemporaryDirectory(prefix="abufmu_cc_") as tmp:
        binary = compile_native(Path(tmp) / f"{identifier}.so", f"{module}_rt", guid)
        with zipfile.ZipFile(target, "w", compression=zipfile.ZIP_DEFLATED) as zf:
            zf.writestr("modelDescription.xml",
                        parseString(tostring(xml, "UTF-8")).toprettyxml(encoding="UTF-8"))
            for file in sorted(stage.rglob("*")):
                if file.is_file() and "__pycache__" not in file.parts:
                    zf.write(file, arcname=str(Path("resources") / file.relative_to(stage)))
            zf.write(binary, arcname=f"binaries/linux64/{identifier}.so")
    return target

"""Build the native, Python-free variant of the toolkit's FMUs (issue 21).

    build_native_fmus(out_dir, *, win64: bool | None = None) -> dict[str, Path]

writes ``AbuBall.fmu``, ``SpeedController.fmu`` and ``Staircase.fmu`` into ``out_dir`` and
returns ``{name: path}``. ``win64``: None adds ``binaries/win64/<Model>.dll`` when the
mingw-w64 cross compiler (``x86_64-w64-mingw32-gcc``) is on PATH, True requires it, False
builds Linux only. Raises :class:`fmus.model_description.FmuBuildError` with a clear message
(no C compiler, a compiler error, ...); nothing is left half-written (atomic writes).

Each FMU holds the C99 model (``fmus/native_c``: the plant, PI law or staircase, their
numerics and ``fmu_core.c``, the FMI 2.0 layer), compiled with the system C compiler (``$CC``,
else ``cc`` or ``gcc``) into ``binaries/linux64/<Model>.so`` (libm only), and the same
sources under ``sources/`` (an FMI 2.0 source-code FMU: ``<SourceFiles>`` in the
``<CoSimulation>`` element). The model description is the Python FMU's (same variables,
value references, causalities, units and start values, from the slave classes in ``fmus``)
with its own guid, no ``needsExecutionTool`` and the memory callbacks in use.
"""
from __future__ import annotations

import hashlib
import os
import shutil
import subprocess
import sys
import tempfile
import uuid
import zipfile
from dataclasses import dataclass
from pathlib import Path
from xml.etree import ElementTree as ET

from abu_model.atomic_io import atomic_open

from .model_description import FmuBuildError, InterfaceSpec, fix_model_description

SOURCE_DIR = Path(__file__).resolve().parent / "native_c"
#: Headers and notices every native FMU's sources/ holds besides its .c files.
COMMON_FILES = ("fmu_core.h", "fmi2Functions.h", "fmi2FunctionTypes.h", "fmi2TypesPlatform.h",
                "LICENSE-FMI2-HEADERS.txt")
MINGW = "x86_64-w64-mingw32-gcc"
#: Flags of every compile: ISO C99, and no fused multiply-add (it would round differently
#: from the Python FMUs, which the native ones reproduce to the last bits).
CFLAGS = ("-std=c99", "-O2", "-ffp-contract=off", "-shared", "-Wall")
#: The ``generationTool`` of every native FMU's model description (:func:`is_native_fmu`).
GENERATION_TOOL = "abu-friction native build (fmus/native_build.py)"
FMU_OPTIONS = {"canGetAndSetFMUstate": "true", "canSerializeFMUstate": "true",
               "canHandleVariableCommunicationStepSize": "true",
               "canNotUseMemoryManagementFunctions": "false"}


@dataclass(frozen=True)
class NativeSpec:
    """One native FMU: its slave class (for the model description) and its C files."""

    name: str
    slave_module: str
    sources: tuple[str, ...]
    headers: tuple[str, ...]


NATIVE_SPECS: tuple[NativeSpec, ...] = (
    NativeSpec("AbuBall", "fmus.abu_ball_slave",
               ("fmu_core.c", "abuball_fmu.c", "abu_plant.c", "abu_numerics.c"),
               ("abu_plant.h", "abu_numerics.h")),
    NativeSpec("SpeedController", "fmus.speed_controller_slave",
               ("fmu_core.c", "speedcontroller_fmu.c", "pi.c"), ("pi.h",)),
    NativeSpec("Staircase", "fmus.staircase_slave",
               ("fmu_core.c", "staircase_fmu.c", "staircase.c", "abu_numerics.c"),
               ("staircase.h", "abu_numerics.h")),
)


def c_compiler() -> list[str]:
    """The host C compiler command: $CC, else cc or gcc on PATH."""
    chosen = os.environ.get("CC", "").strip()
    if chosen:
        if shutil.which(chosen.split()[0]):
            return chosen.split()
        raise FmuBuildError(f"the C compiler in CC = {chosen!r} was not found (unset CC to use "
                            "cc or gcc from PATH)")
    for candidate in ("cc", "gcc"):
        if shutil.which(candidate):
            return [candidate]
    raise FmuBuildError("no C compiler found (set CC, or install gcc): the native FMUs are "
                        "compiled from fmus/native_c when they are built")


def _model_description(spec: NativeSpec, stage: Path) -> ET.Element:
    """The Python FMU's model description for ``spec`` (fixed as fmus.build fixes it)."""
    import importlib

    from .build import _real_start_values

    cls = getattr(importlib.import_module(spec.slave_module), spec.name)
    root = cls(instance_name="build", resources=str(stage)).to_xml()
    co_sim = root.find("CoSimulation")
    co_sim.attrib.pop("needsExecutionTool", None)  # no Python needed
    co_sim.attrib.update(FMU_OPTIONS)
    root.set("generationTool", GENERATION_TOOL)
    raw = ET.tostring(root, encoding="UTF-8")
    fixed = fix_model_description(raw, InterfaceSpec(dict(cls.UNITS),
                                                      dict(cls.OUTPUT_DEPENDENCIES),
                                                      _real_start_values(cls, stage)))
    return ET.fromstring(fixed)


def _stage_sources(spec: NativeSpec, stage: Path) -> str:
    """Copy the FMU's C files into ``stage``; returns a digest of them (for the guid)."""
    digest = hashlib.sha256()
    for name in (*spec.sources, *spec.headers, *COMMON_FILES):
        data = (SOURCE_DIR / name).read_bytes()
        digest.update(name.encode() + b"\0" + data)
        (stage / name).write_bytes(data)
    return digest.hexdigest()


def _compile(command: list[str], what: str) -> None:
    try:
        done = subprocess.run(command, capture_output=True, text=True, timeout=300)
    except OSError as exc:
        raise FmuBuildError(f"cannot run the C compiler for {what}: {exc}") from None
    if done.returncode != 0:
        raise FmuBuildError(f"compiling {what} failed ({' '.join(command)}):\n"
                            f"{done.stderr.strip()}")


def _binaries(spec: NativeSpec, stage: Path, out: Path, win64: bool) -> dict[str, Path]:
    """Compile the staged sources: {path inside the FMU: file}."""
    sources = [str(stage / name) for name in spec.sources]
    so = out / f"{spec.name}.so"
    _compile([*c_compiler(), *CFLAGS, "-fPIC", "-fvisibility=hidden", "-pthread", "-o", str(so),
              *sources, "-lm"], f"{spec.name} for linux64")
    built = {f"binaries/linux64/{spec.name}.so": so}
    if win64:
        dll = out / f"{spec.name}.dll"
        _compile([MINGW, *CFLAGS, "-D_WIN32_WINNT=0x0600", "-static-libgcc", "-o", str(dll),
                  *sources], f"{spec.name} for win64")
        built[f"binaries/win64/{spec.name}.dll"] = dll
    return built


def build_native_fmu(spec: NativeSpec, out_dir: Path, win64: bool) -> Path:
    """Build one native FMU into ``out_dir`` (atomically)."""
    with tempfile.TemporaryDirectory(prefix="abu_native_") as tmp:
        stage, bins = Path(tmp) / "sources", Path(tmp) / "bin"
        stage.mkdir()
        bins.mkdir()
        root = _model_description(spec, Path(tmp))
        digest = _stage_sources(spec, stage)
        guid = "{%s}" % uuid.uuid5(uuid.NAMESPACE_URL, f"abu-friction/native/{spec.name}/{digest}")
        root.set("guid", guid)
        (stage / "abu_guid.h").write_text(f"/* guid of this FMU's modelDescription.xml */\n"
                                          f'#define ABU_GUID "{guid}"\n', encoding="ascii")
        files = ET.SubElement(root.find("CoSimulation"), "SourceFiles")
        for name in spec.sources:
            ET.SubElement(files, "File", name=name)
        ET.indent(root, space="  ")
        xml = ET.tostring(root, encoding="UTF-8", xml_declaration=True)
        binaries = _binaries(spec, stage, bins, win64)
        target = out_dir / f"{spec.name}.fmu"
        with atomic_open(target, "wb") as handle, \
                zipfile.ZipFile(handle, "w", compression=zipfile.ZIP_DEFLATED) as zf:
            zf.writestr("modelDescription.xml", xml)
            for arcname, path in binaries.items():
                zf.write(path, arcname)
            for path in sorted(stage.iterdir()):
                zf.write(path, f"sources/{path.name}")
            zf.write(SOURCE_DIR / "LICENSE-FMI2-HEADERS.txt",
                     "documentation/licenses/LICENSE-FMI2-HEADERS.txt")
        return target


def is_native_fmu(fmu: str | os.PathLike) -> bool:
    """True if the FMU file ``fmu`` is one of the native build's (its model description names
    :data:`GENERATION_TOOL`); False for any other FMU, also one that cannot be read."""
    try:
        with zipfile.ZipFile(fmu) as archive:
            root = ET.fromstring(archive.read("modelDescription.xml"))
    except (OSError, KeyError, ValueError, zipfile.BadZipFile, ET.ParseError):
        return False
    return root.get("generationTool") == GENERATION_TOOL


def platforms(fmu: str | os.PathLike) -> list[str]:
    """What an FMU file carries: its ``binaries/<platform>`` folders, then ``sources``."""
    with zipfile.ZipFile(fmu) as archive:
        names = archive.namelist()
    found = sorted({n.split("/")[1] for n in names
                    if n.startswith("binaries/") and n.count("/") >= 2 and n.split("/")[1]})
    return found + (["sources"] if any(n.startswith("sources/") for n in names) else [])


def build_native_fmus(out_dir: str | os.PathLike, *, win64: bool | None = None
                      ) -> dict[str, Path]:
    """Build the three native FMUs into ``out_dir``; see the module docstring."""
    if sys.platform != "linux":
        raise FmuBuildError(f"the native FMUs are built on Linux (linux64, optionally win64 "
                            f"by cross-compiling), not on {sys.platform}")
    if win64 is None:
        win64 = shutil.which(MINGW) is not None
    elif win64 and shutil.which(MINGW) is None:
        raise FmuBuildError(f"win64 binaries need the mingw-w64 cross compiler ({MINGW}, "
                            "Debian package gcc-mingw-w64-x86-64), which is not on PATH")
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    c_compiler()  # fail before any work without a compiler
    return {spec.name: build_native_fmu(spec, out, bool(win64)) for spec in NATIVE_SPECS}

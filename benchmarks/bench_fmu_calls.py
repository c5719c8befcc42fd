"""FMI call overhead of the FMUs' native layer vs pythonfmu 0.7's C++ library on the same slave.

Run: ``nice python benchmarks/bench_fmu_calls.py``.

Builds AbuBall.fmu, and a copy whose binary is pythonfmu's ``libpythonfmu-export.so`` (it runs
the same slave script: the slaves are pythonfmu ``Fmi2Slave`` classes). Both are driven through
fmpy with what a master does per communication step: set ``torque`` and ``torque_rate``,
``fmi2DoStep`` of 1 ms (stick: the plant's cheapest step), read 5 Reals and 2 Integers, get and
free an FMU state. Timed alternately (7 pairs of 2000 steps), median of the pair ratios.
"""
from __future__ import annotations

import shutil
import statistics
import sys
import tempfile
import time
import zipfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from fmpy import extract, read_model_description  # noqa: E402
from fmpy.fmi2 import FMU2Slave  # noqa: E402

from fmus.build import build_fmu  # noqa: E402


def with_pythonfmu_binary(fmu: Path, target: Path) -> Path:
    """A copy of ``fmu`` whose linux64 binary is pythonfmu's export library."""
    import pythonfmu

    lib = Path(pythonfmu.__file__).parent / "resources" / "binaries" / "linux64" / "libpythonfmu-export.so"
    with zipfile.ZipFile(fmu) as zin, zipfile.ZipFile(target, "w") as zout:
        for info in zin.infolist():
            data = lib.read_bytes() if info.filename.startswith("binaries/") else zin.read(info)
            zout.writestr(info, data)
    return target


def open_fmu(path: Path, workdir: Path):
    unzipdir = extract(str(path), unzipdir=str(workdir))
    md = read_model_description(unzipdir)
    fmu = FMU2Slave(guid=md.guid, unzipDirectory=unzipdir,
                    modelIdentifier=md.coSimulation.modelIdentifier, instanceName="bench")
    fmu.instantiate()
    fmu.setupExperiment(startTime=0.0)
    fmu.enterInitializationMode()
    fmu.exitInitializationMode()
    vr = {v.name: v.valueReference for v in md.modelVariables}
    return fmu, vr


def run(fmu, vr, t0: float, steps: int) -> float:
    inputs = [vr["torque"], vr["torque_rate"]]
    reals = [vr[n] for n in ("theta", "omega", "alpha", "beta_dot", "t_first_step_switch")]
    ints = [vr["mode"], vr["step_switches"]]
    start = time.perf_counter()
    t = t0
    for _ in range(steps):
        fmu.setReal(inputs, [1e-5, 0.0])
        state = fmu.getFMUstate()
        fmu.doStep(t, 1e-3)
        fmu.getReal(reals)
        fmu.getInteger(ints)
        fmu.freeFMUstate(state)
        t += 1e-3
    return (time.perf_counter() - start) / steps


def main() -> None:
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        ours = build_fmu("AbuBall", tmp / "ours")
        theirs = with_pythonfmu_binary(ours, tmp / "AbuBall_pythonfmu.fmu")
        a, vr_a = open_fmu(ours, tmp / "a")
        b, vr_b = open_fmu(theirs, tmp / "b")
        steps, pairs, ta, tb = 2000, [], 0.0, 0.0
        for _ in range(7):
            x = run(a, vr_a, ta, steps)
            ta += steps * 1e-3
            y = run(b, vr_b, tb, steps)
            tb += steps * 1e-3
            pairs.append((x, y))
        ours_us = statistics.median(p[0] for p in pairs) * 1e6
        theirs_us = statistics.median(p[1] for p in pairs) * 1e6
        ratio = statistics.median(p[1] / p[0] for p in pairs)
        print(f"per communication step (set 2, doStep, get 5 + 2, get/free state), AbuBall in "
              f"stick: native layer {ours_us:.1f} us, pythonfmu 0.7 {theirs_us:.1f} us; "
              f"pythonfmu / ours = {ratio:.2f}x (median of 7 alternating pairs)")
        for fmu in (a, b):
            fmu.terminate()
            fmu.freeInstance()
        shutil.rmtree(tmp, ignore_errors=True)


if __name__ == "__main__":
    main()

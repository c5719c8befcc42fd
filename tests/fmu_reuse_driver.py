"""Driver of tests/test_fmu_reuse.py, run in a child process so that a crash fails the test
instead of killing pytest.

usage: fmu_reuse_driver.py FMU_DIR ROUNDS -> one JSON line

1. Every FMU through fmpy, ROUNDS times on ONE instance: a good run, fmi2Reset, a bad
   parameter -> fmi2ExitInitializationMode is fmi2Error (twice) with a message naming it, the
   good value set in initialization mode -> it initialises after all (recoverable), fmi2Reset,
   a good run again: its outputs equal the first run's.
2. The master's pool (harness.cosim.reuse): a pooled co-simulation, then another one loaded, run
   and freed (its logger callback freed, the memory churned), then a bad parameter on the
   pooled instances: a CoSimulationError naming it, and the next good run equals the first.
   (The segfault in fmi2ExitInitializationMode: fmpy's logger proxy kept only the last
   registered logger, the freed one.)
"""
from __future__ import annotations

import ctypes
import gc
import json
import math
import sys
from dataclasses import replace
from pathlib import Path

from fmpy import calloc, extract, free, read_model_description
from fmpy.fmi1 import FMICallException
from fmpy.fmi2 import (FMU2Slave, fmi2CallbackAllocateMemoryTYPE, fmi2CallbackFreeMemoryTYPE,
                       fmi2CallbackFunctions, fmi2CallbackLoggerTYPE)

#: A parameter whose value -1 each FMU refuses at fmi2ExitInitializationMode, and a good value.
BAD = {"AbuBall": ("mu", 2e-3), "SpeedController": ("omega_n", 30.0), "Staircase": ("te", 0.5)}
#: Inputs driven during the good runs (AbuBall needs a torque to move).
INPUTS = {"AbuBall": {"torque": 2e-3, "torque_rate": 0.05}, "SpeedController": {"omega_ref": 10.0},
          "Staircase": {}}


def _status(call) -> int:
    try:
        call()
        return 0
    except FMICallException as exc:
        return exc.status


def _good_run(fmu: FMU2Slave, vr: dict, outputs: list[int], name: str, good: float) -> list:
    param = BAD[name][0]
    fmu.setReal([vr[param]], [good])
    fmu.setupExperiment(startTime=0.0)
    fmu.enterInitializationMode()
    fmu.exitInitializationMode()
    values = []
    for k in range(20):
        for var, value in INPUTS[name].items():
            fmu.setReal([vr[var]], [value])
        fmu.doStep(k * 1e-3, 1e-3)
        values.append(list(fmu.getReal(outputs)))
    return values


def fmus_directly(fmu_dir: Path, rounds: int) -> dict:
    checked = {}
    for name, (param, good) in BAD.items():
        unzipdir = extract(str(fmu_dir / f"{name}.fmu"))
        md = read_model_description(unzipdir)
        vr = {v.name: v.valueReference for v in md.modelVariables}
        outputs = [v.valueReference for v in md.modelVariables
                   if v.causality == "output" and v.type == "Real"]
        messages: list[str] = []
        fmu = FMU2Slave(guid=md.guid, unzipDirectory=unzipdir, modelIdentifier=name,
                        instanceName=name)
        callbacks = fmi2CallbackFunctions()  # a plain logger: the FMUs escape '%'
        callbacks.logger = fmi2CallbackLoggerTYPE(lambda *a: messages.append(a[-1].decode()))
        callbacks.allocateMemory = fmi2CallbackAllocateMemoryTYPE(calloc)
        callbacks.freeMemory = fmi2CallbackFreeMemoryTYPE(free)
        fmu.instantiate(callbacks=callbacks)
        first = _good_run(fmu, vr, outputs, name, good)
        for i in range(rounds):
            assert _status(fmu.reset) == 0
            fmu.setReal([vr[param]], [-1.0])
            fmu.setupExperiment(startTime=0.0)
            fmu.enterInitializationMode()
            for attempt in range(2):  # refused, and refused again: nothing half-initialised
                before = len(messages)
                status = _status(fmu.exitInitializationMode)
                assert status == 3, (name, i, status)
                assert any(f"'{param}'" in m for m in messages[before:]), (name, messages[before:])
            fmu.setReal([vr[param]], [good])  # fixed in initialization mode: recovers
            assert _status(fmu.exitInitializationMode) == 0, (name, i, messages[-3:])
            fmu.doStep(0.0, 1e-3)
            assert _status(fmu.reset) == 0
            again = _good_run(fmu, vr, outputs, name, good)
            assert again == first, (name, i)
            gc.collect()
        fmu.terminate()
        fmu.freeInstance()
        checked[name] = rounds
    return checked


def pooled_master(fmu_dir: Path) -> str:
    from abu_model.params import BallParams, PlantParams
    from harness.cosim import reuse
    from harness.experiments.staircase import StaircaseExperiment
    from harness.cosim.master import CoSimulationError

    hz = 2.0 * math.pi
    paths = {n: fmu_dir / f"{n}.fmu" for n in BAD}
    exp = StaircaseExperiment(PlantParams(BallParams(mu=2e-3)), omega0=-12 * hz,
                              omega_end=-13 * hz, t0=0.02, te=0.05, t_end=0.12)
    good = exp.system(paths)
    expected = list(reuse.run_system(good, -0.03, 0.1).values["omega"])  # pooled
    reuse.run_system(good, -0.03, 0.1, reuse=False)  # loaded, run and freed
    gc.collect()
    # Reuse the freed memory (a dangling logger would now point at something else).
    junk = [ctypes.CFUNCTYPE(None, ctypes.c_int)(lambda x: None) for _ in range(20000)]
    del junk
    gc.collect()
    junk2 = [bytearray(64) for _ in range(200000)]
    plant = good.component("plant")
    bad = replace(good, components=tuple(
        replace(c, parameters={**c.parameters, "mu": -1.0}) if c.name == "plant" else c
        for c in good.components))
    try:
        reuse.run_system(bad, -0.03, 0.1)
    except CoSimulationError as exc:
        message = str(exc)
    else:
        raise AssertionError("mu = -1 was accepted")
    assert "'mu'" in message and "-1" in message, message
    del junk2, plant
    again = list(reuse.run_system(good, -0.03, 0.1).values["omega"])
    assert again == expected
    reuse.clear()
    return message


if __name__ == "__main__":
    folder, rounds = Path(sys.argv[1]), int(sys.argv[2])
    print(json.dumps({"direct": fmus_directly(folder, rounds), "pooled": pooled_master(folder)}))

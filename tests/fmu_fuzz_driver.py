"""Driver of tests/test_fmu_fuzz.py (run as a script in a lean interpreter, so forks are cheap).

Random FMI call sequences against one FMU, each in a forked child: the host never crashes.

Family (seeded by the sequence number): 5-40 calls drawn from the whole co-simulation API
in random order (life cycle in any order, setupExperiment with non-finite or inverted times,
get/set of random value references of every type, also unknown ones, wrong types and absent
arrays' worth of values, non-finite values, doStep at the right, wrong, NaN and infinite time
with zero, negative, NaN and infinite steps, get/set/free/serialize of FMU states, garbage,
truncated, mutated and NaN-carrying serialized states, unknown state pointers, status queries,
debug logging, re-initialisations (reset, setup, enter, exit in a row) after a parameter
set to -1 (refused at fmi2ExitInitializationMode) or back to its start value, and an
injected failure of the Python runtime that makes the C layer latch fmi2Fatal). Asserted:
no child dies of a signal or exits abnormally; every status is a valid fmi2Status; every
non-OK status comes with a logged message; every call drawn invalid (NULL vr or value arrays
with nvr > 0, nvr larger than the vr array, unknown or wrongly typed value references,
non-finite or negative steps, non-finite times, an inverted or non-finite experiment, unknown
state pointers, junk serialized states) is refused: fmi2Error or worse AND a logged message
(removing the native layer's NULL-array check fails it: 10 of 100 AbuBall sequences); after fmi2Fatal every call returns fmi2Error
(with a message) and fmi2FreeFMUstate / fmi2FreeInstance still free.
"""
from __future__ import annotations

import ctypes
import json
import math
import os
import random
import signal
import sys
from collections import Counter

from fmpy import calloc, extract, free, read_model_description
from fmpy.fmi1 import FMICallException
from fmpy.fmi2 import (FMU2Slave, fmi2CallbackAllocateMemoryTYPE, fmi2CallbackFreeMemoryTYPE,
                       fmi2CallbackFunctions, fmi2CallbackLoggerTYPE, fmi2FMUstate)
from fmpy.logging import addLoggerProxy

def load(name: str, fmu_path: str, root: str):
    """(loaded FMU2Slave, model description, unzipdir), warmed up by one instance.

    The children fork from here: the binary is loaded, the Python runtime imported and the
    ctypes prototypes made, so a child only instantiates.
    """
    unzipdir = str(extract(fmu_path, unzipdir=os.path.join(root, name)))
    md = read_model_description(unzipdir)
    fmu = FMU2Slave(guid=md.guid, unzipDirectory=unzipdir, modelIdentifier=name,
                    instanceName="fuzz")
    fmu.instantiate()
    fmu.fmi2FreeInstance(fmu.component)  # keep the library loaded
    return fmu, md, unzipdir


#: Set by tests/native_fuzz_driver.py: how to make an FMU without the Python runtime fail
#: fatally, called as NATIVE_FAULT(fmu, rng) in place of the runtime fault below.
NATIVE_FAULT = None


#: Why the call being made is invalid (set by the action that draws it; None: not known
#: to be invalid). An invalid call must be refused: fmi2Error or worse and a logged message.
INVALID: dict = {"why": None}


def invalid(why: str) -> None:
    INVALID["why"] = why


class Outcome(Exception):
    """A broken promise found inside a child."""


def run_sequence(fmu: FMU2Slave, md, unzipdir: str, seed: int) -> dict:
    """One random call sequence; returns status counts, raises Outcome on a broken promise."""
    rng = random.Random(seed)
    messages: list[tuple[int, bytes]] = []

    def logger(_env, _name, status, _category, message):
        messages.append((status, message))

    callbacks = fmi2CallbackFunctions()
    callbacks.logger = fmi2CallbackLoggerTYPE(logger)
    callbacks.allocateMemory = fmi2CallbackAllocateMemoryTYPE(calloc)
    callbacks.freeMemory = fmi2CallbackFreeMemoryTYPE(free)
    addLoggerProxy(ctypes.byref(callbacks))
    fmu.instantiate(callbacks=callbacks, loggingOn=rng.random() < 0.3)
    variables = md.modelVariables
    by_type = {kind: [v.valueReference for v in variables if v.type == kind]
               for kind in ("Real", "Integer", "Boolean", "String")}
    all_vrs = [v.valueReference for v in variables]
    reals = [v for v in variables if v.type == "Real" and v.causality == "parameter"
             and v.start is not None]
    parameters = [v.valueReference for v in reals] or by_type["Real"]
    states, blobs, counts = [], [], Counter()
    fatal = False
    values = [0.0, 1e-3, -1.0, 2.5e-3, 1e300, -1e-300, math.nan, math.inf, -math.inf]

    def pick_vrs(kind: str) -> list[int]:
        pool = by_type[kind] or all_vrs
        n = rng.choice([0, 1, 1, 2, 3])
        vrs = [rng.choice(pool + all_vrs + [max(all_vrs) + 1, 9999, 2**32 - 1])
               if rng.random() < 0.3 else rng.choice(pool) for _ in range(n)]
        unknown = [vr for vr in vrs if vr not in by_type[kind]]
        if unknown:
            invalid(f"value reference {unknown[0]} is no {kind} variable")
        return vrs

    def raw_array(kind: str):
        """A get or set of ``kind`` with a NULL vr or value array and nvr > 0, or with nvr
        larger than the vr array (what lies past its end: an unknown value reference, here
        0xFFFFFFFF; the value buffer is long enough, so the FMU cannot corrupt the host)."""
        ctype = {"Real": ctypes.c_double, "Integer": ctypes.c_int, "Boolean": ctypes.c_int,
                 "String": ctypes.c_char_p}[kind]
        known = by_type[kind] or [0]
        short = rng.randrange(0, 3)
        nvr = short + rng.randrange(1, 4)
        vr = (ctypes.c_uint * nvr)(*([rng.choice(known) for _ in range(short)]
                                     + [2**32 - 1] * (nvr - short)))
        values = (ctype * nvr)()
        if kind == "String":
            values = (ctype * nvr)(*([b"x"] * nvr))
        how = rng.randrange(3)
        if how == 0:
            vr, why = None, f"vr is NULL with nvr = {nvr}"
        elif how == 1:
            values, why = None, f"the value array is NULL with nvr = {nvr}"
        else:
            why = f"nvr = {nvr} is larger than the vr array ({short} references)"
        invalid(why)
        getattr(fmu, f"fmi2{rng.choice(['Get', 'Set'])}{kind}")(fmu.component, vr, nvr, values)

    def call(what, fn):
        nonlocal fatal
        before = len(messages)
        INVALID["why"] = None
        try:
            fn()
            status = 0
        except FMICallException as exc:
            status = exc.status
        counts[status] += 1
        if status not in (0, 1, 2, 3, 4):
            raise Outcome(f"{what}: invalid status {status}")
        if status != 0 and len(messages) == before:
            raise Outcome(f"{what}: status {status} without a logged message")
        why = INVALID["why"]
        if why is not None:  # an invalid call: refused (fmi2Error or worse) with a message
            counts["invalid"] += 1
            if status < 3:
                raise Outcome(f"{what} ({why}): accepted with status {status}; expected "
                              "fmi2Error or fmi2Fatal")
        if fatal and status != 3 and what != "freeFMUstate":  # freeing still frees
            raise Outcome(f"{what}: status {status} after fmi2Fatal (expected fmi2Error)")
        if status == 4:
            fatal = True
        return status

    def do_step():
        t = rng.choice([None, None, None, math.nan, math.inf, -1.0, 7.0])
        h = rng.choice([1e-3, 1e-2, 0.1, 0.3, 0.0, -1e-3, math.nan, math.inf])
        if t is None:
            size = ctypes.c_double(0.0)
            try:
                fmu.fmi2GetRealStatus(fmu.component, 2, ctypes.byref(size))
                t = size.value
            except FMICallException:
                t = 0.0
        if not (math.isfinite(t) and math.isfinite(h)) or h < 0:
            invalid(f"doStep at t = {t} with h = {h}")
        fmu.doStep(t, h)

    def mutated_blob() -> bytes:
        if blobs and rng.random() < 0.7:
            blob = bytearray(rng.choice(blobs))
            how = rng.randrange(4)
            if how == 0 and blob:
                blob[rng.randrange(len(blob))] = rng.randrange(256)
            elif how == 1:
                blob = blob[: rng.randrange(len(blob) + 1)]
            elif how == 2:
                blob = bytearray(bytes(blob).replace(b'"time": ', b'"time": NaN, "x": ', 1))
            return bytes(blob)
        junk = rng.choice([b"", b"garbage", b"{}", b'{"format": "abufmu-state-1"}', b"[1, 2",
                           os.urandom(rng.randrange(1, 64))])
        if rng.random() < 0.7:
            invalid(f"a serialized state that is no state ({junk[:20]!r})")
            return junk
        return rng.choice([junk, b'{"format": "abufmu-state-1", '
                           b'"model": "AbuBall", "phase": "step mode", "time": 0.0, '
                           b'"last_successful_time": 0.0, "slave": {"m": -1}}'])

    def inject_fault():
        if NATIVE_FAULT is not None:  # an FMU without the Python runtime (native build)
            return NATIVE_FAULT(fmu, rng)
        # A failure of the runtime itself (a malformed answer): the C layer must latch fatal.
        import sys
        with open(os.path.join(unzipdir, "resources", "slavemodule.txt")) as f:
            runtime = sys.modules[f.read().strip() + "_rt"]
        def out_of_memory(self, vrs):
            raise MemoryError
        out_of_memory.__name__ = "get_real"
        # a malformed answer, or the runtime's own fmi2Fatal (MemoryError)
        runtime.Instance.get_real = (runtime._calls(out_of_memory) if rng.random() < 0.5
                                     else lambda self, vrs: "malformed")
        fmu.getReal([by_type["Real"][0]])

    def setup_experiment():
        tolerance = rng.choice([None, 1e-6, -1.0, math.nan])
        start = rng.choice([0.0, 0.0, 1.0, -1.0, math.nan, math.inf])
        stop = rng.choice([None, 2.0, -5.0, math.nan])
        if not math.isfinite(start) or (stop is not None and not stop >= start):
            invalid(f"setupExperiment from {start} to {stop}")
        fmu.setupExperiment(tolerance=tolerance, startTime=start, stopTime=stop)

    def unknown_state(fn, what):
        invalid(f"{what} of a pointer that is no state of this instance")
        return fn()

    actions = [
        ("setupExperiment", 3, setup_experiment),
        ("nullOrShortArray", 4, lambda: raw_array(rng.choice(
            [k for k in ("Real", "Integer", "Boolean", "String") if by_type[k]]))),
        ("enterInitializationMode", 3, fmu.enterInitializationMode),
        ("exitInitializationMode", 3, fmu.exitInitializationMode),
        ("terminate", 1, fmu.terminate),
        ("reset", 1, fmu.reset),
        ("setReal", 4, lambda: (lambda vrs: fmu.setReal(vrs, [rng.choice(values) for _ in vrs]))(
            pick_vrs("Real"))),
        ("getReal", 4, lambda: fmu.getReal(pick_vrs("Real"))),
        ("setInteger", 2, lambda: (lambda vrs: fmu.setInteger(
            vrs, [rng.choice([0, 1, 2, 5, -7, 2**31 - 1]) for _ in vrs]))(pick_vrs("Integer"))),
        ("getInteger", 2, lambda: fmu.getInteger(pick_vrs("Integer"))),
        ("setBoolean", 1, lambda: (lambda vrs: fmu.setBoolean(
            vrs, [rng.choice([True, False]) for _ in vrs]))(pick_vrs("Boolean"))),
        ("getBoolean", 1, lambda: fmu.getBoolean(pick_vrs("Boolean"))),
        ("getString", 1, lambda: fmu.getString(pick_vrs("String"))),
        ("setString", 1, lambda: (lambda vrs: fmu.setString(vrs, ["x"] * len(vrs)))(
            pick_vrs("String"))),
        ("doStep", 10, do_step),
        ("getFMUstate", 3, lambda: states.append(fmu.getFMUstate())),
        ("setFMUstate", 3, lambda: fmu.setFMUstate(rng.choice(states)) if states and
         rng.random() < 0.8 else unknown_state(lambda: fmu.setFMUstate(
             fmi2FMUstate(rng.choice([1, 0xDEADBEEF]))), "setFMUstate")),
        ("freeFMUstate", 1, lambda: fmu.freeFMUstate(states.pop(rng.randrange(len(states))))
         if states else unknown_state(lambda: fmu.freeFMUstate(fmi2FMUstate(0x1234)),
                                      "freeFMUstate")),
        ("serializeFMUstate", 2, lambda: blobs.append(fmu.serializeFMUstate(rng.choice(states)))
         if states else unknown_state(lambda: fmu.serializeFMUstate(fmi2FMUstate(0x4321)),
                                      "serializeFMUstate")),
        ("deSerializeFMUstate", 3, lambda: (lambda blob: states.append(
            fmu.deSerializeFMUstate(blob)))(rng.choice(blobs) if blobs and rng.random() < 0.3
                                            else mutated_blob())),
        ("setDebugLogging", 1, lambda: fmu.setDebugLogging(rng.random() < 0.5, [])),
        ("getStatus", 1, lambda: fmu.getStatus(rng.randrange(5))),
        ("getRealStatus", 1, lambda: fmu.getRealStatus(rng.randrange(5))),
        ("getBooleanStatus", 1, lambda: fmu.getBooleanStatus(rng.randrange(5))),
        ("injectFault", 0.3, inject_fault),
        ("badParameter", 1, lambda: fmu.setReal([rng.choice(parameters)], [-1.0])),
        ("goodParameters", 1, lambda: fmu.setReal([v.valueReference for v in reals],
                                                   [float(v.start) for v in reals])),
    ]
    # A re-initialisation: reset, setup, enter and exit initialization mode in a row (after a
    # refused bad parameter, an error or a fatal error alike), each call checked on its own.
    cycle = ["reset", "setupExperiment", "enterInitializationMode", "exitInitializationMode"]
    names = [a[0] for a in actions]
    weights = [a[1] for a in actions]
    table = {a[0]: a[2] for a in actions}
    names.append("reinitialize")
    weights.append(2)
    for _ in range(rng.randint(5, 40)):
        name = rng.choices(names, weights)[0]
        for step in (cycle if name == "reinitialize" else [name]):
            call(step, table[step])
    fmu.fmi2FreeInstance(fmu.component)  # freeing always frees (also after fmi2Fatal)
    invalid_calls = counts.pop("invalid", 0)
    return {"counts": dict(counts), "fatal": fatal, "invalid": invalid_calls}


def fuzz(fmu: FMU2Slave, md, unzipdir: str, first: int, count: int) -> dict:
    """Run sequences first..first+count-1, each in a forked child; aggregate the outcomes."""
    totals, fatal_runs, problems, invalid_calls = Counter(), 0, [], 0
    for seed in range(first, first + count):
        read_end, write_end = os.pipe()
        pid = os.fork()
        if pid == 0:  # child: run one sequence, report through the pipe, exit without cleanup
            os.close(read_end)
            signal.alarm(60)  # a hang is a failure too (reported as a signal)
            code = 0
            try:
                result = run_sequence(fmu, md, unzipdir, seed)
            except Outcome as exc:
                result, code = {"problem": str(exc)}, 3
            except BaseException as exc:  # noqa: BLE001 - report anything to the parent
                result, code = {"problem": f"host-side exception {exc!r}"}, 4
            os.write(write_end, json.dumps(result).encode())
            os._exit(code)
        os.close(write_end)
        chunks = []
        while chunk := os.read(read_end, 65536):
            chunks.append(chunk)
        os.close(read_end)
        _, wait_status = os.waitpid(pid, 0)
        if os.WIFSIGNALED(wait_status):
            problems.append(f"seed {seed}: child killed by signal {os.WTERMSIG(wait_status)}")
            continue
        result = json.loads(b"".join(chunks) or b"{}")
        if os.WEXITSTATUS(wait_status) != 0 or "problem" in result:
            problems.append(f"seed {seed}: {result.get('problem', 'no report')}")
            continue
        totals.update({int(k): v for k, v in result["counts"].items()})
        fatal_runs += result["fatal"]
        invalid_calls += result["invalid"]
    return {"sequences": count, "problems": problems, "totals": dict(totals),
            "fatal_runs": fatal_runs, "invalid_calls": invalid_calls}


if __name__ == "__main__":
    # usage: fmu_fuzz_driver.py NAME FMU_PATH WORKDIR FIRST COUNT -> one JSON line
    name, path, root, first, count = sys.argv[1:6]
    print(json.dumps(fuzz(*load(name, path, root), int(first), int(count))))

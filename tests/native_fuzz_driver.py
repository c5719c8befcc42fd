"""Driver of tests/test_native_fuzz.py: tests/fmu_fuzz_driver.py on a native FMU.

The native FMUs have no Python runtime to break, so the injected fault is the host's memory
running out: the FMU's allocateMemory callback (fmpy's calloc, wrapped here) returns NULL
for one fmi2GetFMUstate, which the FMU must answer with fmi2Fatal, latched (as the Python
runtime answers a MemoryError). Everything else is the Python FMUs' fuzzer unchanged.
"""
from __future__ import annotations

import json
import sys

import fmu_fuzz_driver as driver
from fmpy import calloc as real_calloc

FAIL = {"on": False}


def calloc(count, size):
    """fmpy's calloc, or NULL while a fault is injected."""
    return None if FAIL["on"] else real_calloc(count, size)


def out_of_memory(fmu, rng):
    FAIL["on"] = True
    try:
        fmu.getFMUstate()
    finally:
        FAIL["on"] = False


driver.calloc = calloc
driver.NATIVE_FAULT = out_of_memory

if __name__ == "__main__":
    # usage: native_fuzz_driver.py NAME FMU_PATH WORKDIR FIRST COUNT -> one JSON line
    name, path, root, first, count = sys.argv[1:6]
    print(json.dumps(driver.fuzz(*driver.load(name, path, root), int(first), int(count))))

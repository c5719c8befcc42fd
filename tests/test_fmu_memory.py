"""Flat memory: 1000 instantiate/free cycles of each FMU in one process through fmpy.

Each cycle loads the FMU's binary (fmpy's FMU2Slave), instantiates, initialises, takes one
step, gets and frees an FMU state, terminates, frees the instance and unloads the binary. After
100 warm-up cycles the resident set size may grow by less than 5 KB per cycle over the next
1000, ``sys.path`` must not change and no class may be left behind (the number of ``type``
objects the garbage collector sees stays the same). Run in a fresh interpreter so the figures
are this process's alone; ``pytest -s`` prints them.
"""
from __future__ import annotations

import json
import subprocess
import sys
import textwrap

import pytest

CYCLES = textwrap.dedent("""
    import gc, json, os, sys
    from fmpy import extract, read_model_description
    from fmpy.fmi2 import FMU2Slave

    def rss_kb():
        with open("/proc/self/statm") as f:
            return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 1024

    def n_classes():
        return sum(isinstance(o, type) for o in gc.get_objects())

    out = {}
    for name, path in json.loads(sys.argv[1]).items():
        unzipdir = extract(path)
        md = read_model_description(unzipdir)

        def cycle(i):
            fmu = FMU2Slave(guid=md.guid, unzipDirectory=unzipdir,
                            modelIdentifier=md.coSimulation.modelIdentifier, instanceName=f"i{i}")
            fmu.instantiate()
            fmu.setupExperiment(startTime=0.0)
            fmu.enterInitializationMode()
            fmu.exitInitializationMode()
            fmu.doStep(0.0, 1e-3)
            state = fmu.getFMUstate()
            fmu.freeFMUstate(state)
            fmu.terminate()
            fmu.freeInstance()

        for i in range(100):
            cycle(i)
        gc.collect()
        path0, rss0, classes0 = list(sys.path), rss_kb(), n_classes()
        for i in range(1000):
            cycle(i)
        gc.collect()
        out[name] = {"kb_per_cycle": (rss_kb() - rss0) / 1000, "path_same": sys.path == path0,
                     "class_change": n_classes() - classes0}
    print(json.dumps(out))
""")


def test_thousand_instantiate_free_cycles_keep_memory_and_sys_path_flat(fmu_dir, tmp_path):
    script = tmp_path / "cycles.py"
    script.write_text(CYCLES)
    paths = {name: str(path) for name, path in fmu_dir.items()}
    done = subprocess.run([sys.executable, str(script), json.dumps(paths)], capture_output=True,
                          text=True, timeout=600, cwd=tmp_path)
    assert done.returncode == 0, done.stderr[-3000:]
    result = json.loads(done.stdout.strip().splitlines()[-1])
    for name, r in result.items():
        print(f"\n{name}: 1000 cycles after 100 warm-up: RSS {r['kb_per_cycle']:+.2f} KB/cycle, "
              f"sys.path unchanged: {r['path_same']}, classes {r['class_change']:+d}")
    for name, r in result.items():
        assert r["path_same"], name
        assert r["class_change"] == 0, name
        assert r["kb_per_cycle"] < 5.0, (name, r)

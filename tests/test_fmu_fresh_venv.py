"""Stdlib-only FMUs: their Python imports only the standard library and they run in a venv
that holds fmpy and what fmpy installs, nothing else (no scipy, no pythonfmu, no toolkit).

The venv is built offline and fast: ``python -m venv --without-pip``, then the installed files
of fmpy's dependency closure (from its ``Requires-Dist``, read with importlib.metadata) are
linked into its site-packages - the same set ``pip install fmpy`` would install.
"""
from __future__ import annotations

import ast
import importlib.metadata as metadata
import json
import os
import re
import subprocess
import sys
import textwrap
import time
import zipfile
from pathlib import Path

import pytest


def test_every_python_file_in_the_fmus_imports_only_the_standard_library(fmu_dir):
    checked = 0
    for name, path in fmu_dir.items():
        with zipfile.ZipFile(path) as z:
            files = [n for n in z.namelist() if n.endswith(".py")]
            local = {n.split("/")[1].removesuffix(".py") for n in files}  # inside the FMU
            for file in files:
                tree = ast.parse(z.read(file).decode("utf-8"), filename=file)
                for node in ast.walk(tree):
                    if isinstance(node, ast.Import):
                        tops = [a.name.split(".")[0] for a in node.names]
                    elif isinstance(node, ast.ImportFrom) and node.level == 0:
                        tops = [node.module.split(".")[0]]
                    else:
                        continue
                    for top in tops:
                        assert top in sys.stdlib_module_names or top in local or \
                            top == "__future__", f"{name}: {file}:{node.lineno} imports {top}"
                checked += 1
    print(f"\n{checked} Python files in the three FMUs import only the standard library "
          "or modules inside their FMU")
    assert checked >= 30


def _closure(dist_name: str) -> list[metadata.Distribution]:
    """The installed distribution and its (non-extra) requirements, recursively."""
    seen: dict[str, metadata.Distribution] = {}
    todo = [dist_name]
    while todo:
        name = re.split(r"[\s<>=!~;\[(]", todo.pop(), maxsplit=1)[0]
        key = name.lower().replace("_", "-")
        if key in seen:
            continue
        dist = metadata.distribution(name)
        seen[key] = dist
        for requirement in dist.requires or []:
            if "extra ==" in requirement:
                continue
            marker = requirement.split(";", 1)[1] if ";" in requirement else ""
            if "platform_system" in marker and "Windows" in marker and "!=" not in marker:
                continue
            todo.append(requirement)
    return list(seen.values())


RUN = textwrap.dedent("""
    import importlib.util, json, sys
    from fmpy import simulate_fmu
    paths = json.loads(sys.argv[1])
    missing = [m for m in ("scipy", "pythonfmu", "abu_model", "controller", "fmus")
               if importlib.util.find_spec(m) is not None]
    ball = simulate_fmu(paths["AbuBall"], start_values={"torque": 1e-3}, stop_time=0.1,
                        output_interval=0.01)
    stairs = simulate_fmu(paths["Staircase"], stop_time=1.2, output_interval=0.01)
    ctrl = simulate_fmu(paths["SpeedController"], start_values={"omega_ref": -100.0},
                        stop_time=0.1, output_interval=0.01)
    print(json.dumps({"importable": missing, "omega": float(ball["omega"][-1]),
                      "omega_ref": float(stairs["omega_ref"][-1]),
                      "torque": float(ctrl["torque"][-1]),
                      "scipy_loaded": "scipy" in sys.modules}))
""")


def test_fmus_run_in_a_fresh_venv_with_only_fmpy(fmu_dir, tmp_path):
    start = time.perf_counter()
    venv = tmp_path / "venv"
    subprocess.run([sys.executable, "-m", "venv", "--without-pip", str(venv)], check=True)
    site = next((venv / "lib").glob("python3*/site-packages"))
    dists = _closure("fmpy")
    for dist in dists:
        for file in dist.files or []:
            source = Path(dist.locate_file(file)).resolve()
            target = site / file
            if not source.is_file() or ".." in Path(file).parts:
                continue  # console scripts etc. live outside site-packages
            target.parent.mkdir(parents=True, exist_ok=True)
            if not target.exists():
                os.symlink(source, target)
    built = time.perf_counter() - start
    names = sorted(d.metadata["Name"] for d in dists)
    assert "fmpy" in [n.lower() for n in names] and not {"scipy", "pythonfmu", "abu-friction"} & \
        {n.lower() for n in names}
    script = tmp_path / "run.py"
    script.write_text(RUN)
    paths = {name: str(path) for name, path in fmu_dir.items()}
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "PYTHONHOME")}
    done = subprocess.run([str(venv / "bin" / "python"), str(script), json.dumps(paths)],
                          capture_output=True, text=True, timeout=300, cwd=tmp_path, env=env)
    assert done.returncode == 0, done.stderr[-3000:]
    result = json.loads(done.stdout.strip().splitlines()[-1])
    print(f"\nfresh venv ({len(names)} distributions: {', '.join(names)}) made in {built:.1f} s")
    assert result["importable"] == []          # nothing but fmpy's closure is installed
    assert not result["scipy_loaded"]
    # closed forms: AbuBall sticks, omega = omega0 + T/J t; Staircase ends at -22 Hz;
    # SpeedController T = Kp (omega_ref - omega) + Ki x_I with x_I = (omega_ref - omega) t
    assert result["omega"] == pytest.approx(-2 * 3.141592653589793 * 17 + 1e-3 / 4.5e-5 * 0.1,
                                            rel=1e-12)
    assert result["omega_ref"] == pytest.approx(-2 * 3.141592653589793 * 22, rel=1e-12)
    kp, ki = 2 * 0.5 * 2.2 * 4.5e-5, 2.2**2 * 4.5e-5
    assert result["torque"] == pytest.approx(kp * -100.0 + ki * -100.0 * 0.1, rel=1e-9)

"""The README's "Python API" section runs as written, from a fresh folder, and says what is true:
the script simulates (bounds bracket the true mu = 2.75e-3, report sec. 4.2.3) and measures (an
interval containing the rendered true mu = 0.03), and writes the files it names."""
from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _api_script() -> str:
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    section = text.split("## Python API", 1)[1].split("\n## ", 1)[0]
    blocks = re.findall(r"```python\n(.*?)```", section, flags=re.S)
    assert len(blocks) == 1, "the section has one runnable script"
    return blocks[0]


def test_readme_python_api_runs_as_written(tmp_path):
    (tmp_path / "example.py").write_text(_api_script())
    env = dict(os.environ, MPLBACKEND="Agg")
    env.pop("PYTHONPATH", None)  # the installed package, as a user has it
    proc = subprocess.run([sys.executable, "example.py"], cwd=tmp_path, env=env,
                          capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr[-3000:]
    out = proc.stdout
    print(out)
    lo, hi = map(float, re.search(r"co-simulation: (\S+) <= mu < (\S+),", out).groups())
    assert lo <= 2.75e-3 < hi
    lo, hi = map(float, re.search(r"measured: (\S+) <= mu <= (\S+) \(ok\)", out).groups())
    assert lo <= 0.03 <= hi and (hi - lo) / 0.03 < 0.25
    assert "records combined: 1" in out
    for name in ("sim/result.csv", "sim/summary.json", "twin/frames.tif", "twin/truth.csv",
                 "measurement/tracks.csv", "measurement/kinematics.csv",
                 "measurement/summary.json"):
        assert (tmp_path / name).is_file(), name

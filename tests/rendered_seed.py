"""One harsh-twin recording rendered and measured end to end, for the tests of single seeds."""
from __future__ import annotations

import json
from pathlib import Path

from abu.cli.main import main


def render_and_measure(seed: int, tmp_path: Path, *measure_args: str) -> tuple[dict, float]:
    """(summary.json of ``abu measure --no-plots [MEASURE_ARGS]``, true mu) of ``abu render
    --scenario random --seed SEED``."""
    rec, out = tmp_path / "rec", tmp_path / "m"
    if not rec.exists():
        assert main(["render", "--scenario", "random", "--seed", str(seed), "--out", str(rec),
                     "--quiet"]) == 0
    assert main(["measure", str(rec), "--out", str(out), "--no-plots", "--quiet", "--overwrite",
                 *measure_args]) == 0
    summary = json.loads((out / "summary.json").read_text())
    return summary, json.loads((rec / "meta.json").read_text())["mu"]

"""Wall time of Table 4.1 (6 values of mu with their co-simulation checks), against an older
checkout of the project timed in the same run.

    git worktree add /tmp/base <old commit>
    python benchmarks/bench_table41.py --base /tmp/base [--pairs N]

Each timing is a fresh Python process (``sys.path`` set to one checkout) that builds the FMUs
untimed, then times ``harness.experiments.table41.table41`` for mu = k 2.75e-3, k = 1..6 (12
co-simulations including loading the FMUs). The two checkouts alternate for N pairs (default
5); the script prints both medians and the median of the pair ratios. Without ``--base`` only
this checkout is timed.
"""
from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

from bench_args import positive_int  # the scripts' folder is on sys.path

HERE = Path(__file__).resolve().parents[1]

CHILD = r"""
import json, sys, time
sys.path.insert(0, sys.argv[1])
from fmus.build import build_fmus
from harness.experiments.table41 import table41
fmus = build_fmus(sys.argv[2])
start = time.perf_counter()
rows = table41([k * 2.75e-3 for k in range(1, 7)], fmu_dir=sys.argv[2])
elapsed = time.perf_counter() - start
print(json.dumps({"time": elapsed, "omega0_hz": [r.omega0_hz for r in rows],
                  "consistent": [r.consistent for r in rows]}))
"""


def _time(tree: Path, fmu_dir: str) -> dict:
    out = subprocess.run([sys.executable, "-c", CHILD, str(tree), fmu_dir], check=True,
                         capture_output=True, text=True, cwd=tree).stdout
    return json.loads(out.strip().splitlines()[-1])


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--base", type=Path, default=None, help="older checkout to compare with")
    parser.add_argument("--pairs", type=positive_int, default=5, help="alternating pairs (default 5)")
    args = parser.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        new_fmus, base_fmus = str(Path(tmp) / "new"), str(Path(tmp) / "base")
        ours, theirs, ratios = [], [], []
        for _ in range(args.pairs):
            result = _time(HERE, new_fmus)
            ours.append(result["time"])
            if args.base is not None:
                base = _time(args.base, base_fmus)
                theirs.append(base["time"])
                ratios.append(base["time"] / result["time"])
                assert base["omega0_hz"] == result["omega0_hz"], (base, result)
    print(f"Table 4.1 (6 values of mu, 12 co-simulation checks), {args.pairs} runs each")
    print(f"this checkout: median {statistics.median(ours):.3f} s; rows {result['omega0_hz']} Hz, "
          f"confirmed {result['consistent']}")
    if ratios:
        print(f"base {args.base}: median {statistics.median(theirs):.3f} s")
        print(f"speed-up base / this checkout: median of pairs {statistics.median(ratios):.1f}x "
              f"(min {min(ratios):.1f}, max {max(ratios):.1f}; target >= 4)")
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""The digital controller's sample time found from the record, against it stated (or guessed
wrong), on the twin's staircase drives: ``abu measure --kinematics drive-model`` without
``--drive`` (``measurement/kinematics/sample_time_search.py``).

The records are ``tests/test_unknown_loop.py``'s (the harsh twin's digital PI drive, loop
drawn from the seed, 2-20 ms setpoint filter in two of three, lens pattern, 1.5e-4 rad
tracking noise, 2400 frames), in three families:

* ``frame rate``: the controller samples at the frame rate (4500/s), as in the rendered twin;
* ``10 kHz``: the controller at 10 kHz filmed at 5000 frames/s (every other sample);
* ``45 kHz``: the controller at 45 kHz (next to continuous) filmed at 4500 frames/s.

(The twin samples its controller on its own time grid, so a controller slower than the
camera is not available.) Each record is fitted with the sample time stated (the truth,
``continuous`` for the 45 kHz one), found (no sample time given), and, where a user could
guess wrong, with the guess (continuous; the frame interval). Printed per row: accepted,
the share of check times whose 95 % bar holds the true omega_dot, its RMS error, the sample
times found, and the CPU time per record (process time, one BLAS thread).

Run::

    nice python benchmarks/bench_sample_time_search.py --first 600 --n 12
"""
from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT), str(ROOT / "tests")]

import numpy as np  # noqa: E402

from measurement.kinematics.unknown_loop import FIND, UnknownLoopInput  # noqa: E402
from test_drive_model import SIGMA, _rms  # noqa: E402
from test_unknown_loop import CHECKS, _records  # noqa: E402

#: family: (frame rate [1/s], controller samples per frame, the true sample time, guesses)
FAMILIES = {
    "frame rate": (4500.0, 1, 1 / 4500.0, (None,)),
    "10 kHz": (5000.0, 2, 1e-4, (2e-4,)),
    "45 kHz": (4500.0, 10, None, ()),
}


def _row(records: list, sample_time) -> dict:
    accepted, inside, err, found, cpu = 0, [], [], [], 0.0
    for t, th, alpha, spec, sp in records:
        start = time.process_time()
        fit = UnknownLoopInput(setpoints=sp, sample_time_s=sample_time).fit(t, th, SIGMA)
        cpu += time.process_time() - start
        if fit.accepted:
            accepted += 1
            e = fit.omega_dot[CHECKS] - alpha[CHECKS]
            inside.extend(np.abs(e) <= 1.96 * fit.sigma_omega_dot[CHECKS])
            err.extend(e)
            found.append(fit.params.get("controller_sample_time_s"))
    return dict(accepted=accepted, inside=float(np.mean(inside)) if inside else float("nan"),
                rms=_rms(err) if err else float("nan"), found=found, cpu=cpu / len(records))


def _name(sample_time) -> str:
    if sample_time == FIND:
        return "found"
    return "continuous" if sample_time is None else f"{sample_time:.3g} s"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--first", type=int, default=600)
    ap.add_argument("--n", type=int, default=12)
    a = ap.parse_args()
    print(f"seeds {a.first}-{a.first + a.n - 1}, {a.n} records per family; CPU per record "
          "(process time, one BLAS thread, a shared machine)")
    for family, (fps, every, truth, guesses) in FAMILIES.items():
        records = list(_records(a.n, a.first, fps=fps, every=every))
        rows = {"stated " + _name(truth): _row(records, truth), "found": _row(records, FIND)}
        for guess in guesses:
            rows["guessed " + _name(guess)] = _row(records, guess)
        base = rows["stated " + _name(truth)]["cpu"]
        for name, r in rows.items():
            found = ""
            if name == "found":
                found = "; found " + ", ".join(
                    f"{_name(k or None)} x{r['found'].count(k)}" for k in sorted(set(r["found"])))
            print(f"{family:>10} | {name:<18} accepted {r['accepted']:2d}/{a.n}, inside "
                  f"{r['inside']:.0%}, RMS omega_dot {r['rms']:.3f} rad/s^2, CPU "
                  f"{r['cpu']:.2f} s/record ({r['cpu'] / base:.1f}x stated){found}",
                  flush=True)


if __name__ == "__main__":
    main()

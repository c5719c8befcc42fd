"""Measurement: high-speed camera recordings -> marker tracks -> theta, beta, omega, omega_dot ->
a confidence interval on mu. Independent of the co-simulation (``harness``).

Stages (subpackages, in data-flow order): ``imaging`` (frames -> marker tracks),
``kinematics`` (tracks -> angles and their derivatives), ``inference`` (-> the interval),
``report`` (text, JSON, figures). ``pipeline`` strings them together with typed results
(``measure_recording(path) -> MeasureResult``). Import submodules explicitly; this package file
stays light on purpose (no OpenCV or SciPy at import time).
"""
import os

# Before NumPy loads: one BLAS thread. The analysis' matrices are small (<= ~1000 rows), and a
# multi-threaded OpenBLAS on a machine with other work is far slower on them: `abu measure
# --no-plots` on 3072 frames took 2.9-4.3 s instead of 1.0 s on a 2-core machine with two
# other busy processes (the harness does the same). A user's own setting is kept.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

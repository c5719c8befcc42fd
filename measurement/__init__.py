"""Measurement: high-speed camera recordings -> marker tracks -> theta, beta, omega, omega_dot ->
a confidence interval on mu. Independent of the co-simulation (``harness``).

Stages (subpackages, in data-flow order): ``imaging`` (frames -> marker tracks),
``kinematics`` (tracks -> angles and their derivatives), ``inference`` (-> the interval),
``report`` (text, JSON, figures). ``pipeline`` strings them together with typed results
(``measure_recording(path) -> MeasureResult``). Import submodules explicitly; this package file
stays light on purpose (no OpenCV or SciPy at import time).
"""

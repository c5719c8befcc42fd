"""Measurement: high-speed camera recordings to marker tracks, angles, omega, omega_dot and mu bounds.

Imaging half: ``frames_io`` (read/write recordings), ``markers`` (find the three markers in the first
frame), ``tracking`` (sub-pixel marker tracking), ``render`` (synthetic camera) and ``twin``
(a rendered digital twin of the report's experiment). The analysis half turns tracks into
kinematics, intervals on mu and an error analysis. Import submodules explicitly; this package
file stays light on purpose (no OpenCV import at package import time).
"""

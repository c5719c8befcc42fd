"""Build of the one compiled module: the tracker's C kernels (everything else is in
pyproject.toml).

``measurement.imaging._trackc`` is a plain CPython extension (the buffer protocol, no NumPy
headers). It is optional: without a C compiler the install still succeeds and the tracker
runs its NumPy/OpenCV path (same results, ~4x slower; tests/test_tracking_kernels.py).
"""
from setuptools import Extension, setup

setup(ext_modules=[Extension("measurement.imaging._trackc",
                             sources=["measurement/imaging/_trackc.c"], optional=True)])

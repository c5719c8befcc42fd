"""Build of the compiled modules: the loop's response, the tracker's C kernels and the slip
model (everything else is in pyproject.toml).

``abu_model._loopc``, ``measurement.imaging._trackc`` and ``measurement.inference._slipc`` are plain CPython
extensions (the buffer protocol, no NumPy headers). They are optional: without a C compiler
the install still succeeds and the tracker runs its NumPy/OpenCV path (same results, ~4x
slower; tests/test_tracking_kernels.py), the slip model its NumPy path (same results to
rounding, slower; tests/test_slip_kernel.py), the loop's response its NumPy reference
(tests/test_loop_kernel.py).
"""
from setuptools import Extension, setup

setup(ext_modules=[Extension("abu_model._loopc", sources=["abu_model/_loopc.c"], optional=True),
                   Extension("measurement.imaging._trackc",
                             sources=["measurement/imaging/_trackc.c"], optional=True),
                   Extension("measurement.inference._slipc",
                             sources=["measurement/inference/_slipc.c"], optional=True)])

"""FMI 2.0 co-simulation FMUs of the toolkit (pythonfmu-style slaves, own native layer).

``fmus.build.build_fmus(out_dir)`` writes AbuBall.fmu (rotor + one ball), SpeedController.fmu
(PI speed law) and Staircase.fmu (speed setpoint). The slave scripts in this package are
not imported from here: they run inside the FMUs, where the project packages they use are
vendored under FMU-specific names (see :mod:`fmus.build` and docs/fmus.md).
"""
from .build import FMU_NAMES, build_fmu, build_fmus
from .model_description import FmuBuildError

__all__ = ["FMU_NAMES", "FmuBuildError", "build_fmu", "build_fmus"]

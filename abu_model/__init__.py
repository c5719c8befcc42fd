"""Ball-in-ABU dynamics: parameters, equations of motion, the stick/slip plant and a
monolithic reference solver.

Only relative imports are used inside this package so that it can be vendored into an
FMU under another name (see ``fmus/build.py``).
"""
from .errors import AbuError, ParameterError
from .params import BallParams, PlantParams

__all__ = ["AbuError", "ParameterError", "BallParams", "PlantParams"]

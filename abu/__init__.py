"""abu-friction: static friction of a ball in an Automatic Balancing Unit.

The public Python API is :mod:`abu.api` (``from abu import api``); the command line is
:mod:`abu.cli` (``abu --help``). SI units throughout (rad, rad/s, s, m, kg); speeds in Hz only
where a name ends in ``_hz``.
"""
from importlib.metadata import PackageNotFoundError, version as _version

try:
    __version__ = _version("abu-friction")
except PackageNotFoundError:  # pragma: no cover - run from a source tree without install
    __version__ = "0+unknown"

"""abu-friction: static friction of a ball in an Automatic Balancing Unit.

The public Python API is :mod:`abu.api` (``from abu import api``); the command line is
:mod:`abu.cli` (``abu --help``). SI units throughout (rad, rad/s, s, m, kg); speeds in Hz only
where a name ends in ``_hz``.
"""
import os

# Before NumPy loads (every command starts here): one BLAS thread, as ``harness`` and
# ``measurement`` set it for their library users; the reason is in ``measurement/__init__.py``.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")


def __getattr__(name: str):
    """``__version__``, looked up on first use: importing importlib.metadata costs ~20 ms of
    every command's start (``abu measure`` must finish within the recording's duration)."""
    if name == "__version__":
        from importlib.metadata import PackageNotFoundError, version

        try:
            return version("abu-friction")
        except PackageNotFoundError:  # pragma: no cover - a source tree without install
            return "0+unknown"
    raise AttributeError(f"module 'abu' has no attribute {name!r}")

"""The end of the ``abu`` program: exit handlers, flushed streams, then the process ends at once.

Why not a plain ``sys.exit``: CPython's finalisation frees every module and object one by one
before the process ends. With NumPy, OpenCV and matplotlib loaded that is 60 ms of work whose
result the operating system discards anyway (measured: a process that imported matplotlib and
drew one figure took 0.40 s CPU with ``sys.exit``, 0.34 s with this exit; `abu measure`'s whole
process is timed by ``benchmarks/bench_measure.py``). mypy ends its command line the same way.

What a normal exit does that matters is kept: the ``atexit`` handlers run (logging's flush,
``weakref.finalize`` of temporary folders, multiprocessing's clean-up), stdout and stderr are
flushed. While a non-daemon thread still runs, the normal exit (which waits for it) is used.
"""
from __future__ import annotations

import atexit
import os
import sys
import threading
from typing import NoReturn


def _other_threads_alive() -> bool:
    main = threading.main_thread()
    return any(t is not main and t.is_alive() and not t.daemon for t in threading.enumerate())


def exit_process(status: int) -> NoReturn:
    """End the process with ``status`` after the exit handlers ran and the streams are flushed."""
    run_exit_handlers = getattr(atexit, "_run_exitfuncs", None)   # CPython's own, since 2.x
    if run_exit_handlers is None or _other_threads_alive():
        sys.exit(status)
    run_exit_handlers()
    for stream in (sys.stdout, sys.stderr):
        try:
            if stream is not None:
                stream.flush()
        except (OSError, ValueError):   # a closed pipe: nothing more can be said on it
            status = status or 1
    os._exit(status)

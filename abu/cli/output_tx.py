"""Output folders and files as units: a reader sees a whole run or none.

Every command that writes uses :func:`output_folder` (or :func:`output_file` for a single file
such as ``abu sweep --out sweep.csv``)::

    with output_folder(args.out, overwrite=args.overwrite) as tmp:
        ...write everything into tmp...
    # on success tmp has been renamed to args.out; on an exception it is removed

* The results are written into a temporary sibling ``.NAME.<random>.tmp`` and renamed into place
  at the end (``os.rename`` of a folder is atomic on one file system). A run replacing an
  existing folder renames the old one aside first, so for a moment there is no folder: never a
  mixture of two runs.
* A lock (``fcntl.flock`` on ``.NAME.lock`` beside the target) makes a second run into a
  folder being written refuse at once with a clear message. The kernel releases the lock when
  its process dies, even by SIGKILL, so a killed run never blocks the next one.
* An existing non-empty target is replaced only with ``--overwrite``.
* Stale temporary entries of killed runs (``.NAME.*.tmp`` beside the target and ``.*.tmp``
  inside it, left by :mod:`abu_model.atomic_io`) are removed by the next run that holds the lock.
* :func:`use_run_tempdir` points :mod:`tempfile` (and ``TMPDIR`` for child processes) at a
  per-process folder ``abu-run-<pid>-*`` of the system temporary folder, held by a lock and
  removed at exit; the next run removes those whose lock is free (their process was killed),
  so extracted FMUs and co-simulation folders never pile up.
"""
from __future__ import annotations

import atexit
import errno
import fcntl
import os
import shutil
import signal
import tempfile
from contextlib import contextmanager
from pathlib import Path
from typing import Iterator

from abu_model.errors import AbuError

RUN_PREFIX = "abu-run-"
#: Temporary outputs this process is writing (removed on SIGTERM).
_ACTIVE: set[Path] = set()


class OutputError(AbuError):
    """The output folder or file cannot be used (locked, exists, is not a folder...)."""


# ---------------------------------------------------------------------------- locking
class _Lock:
    """An exclusive, non-blocking ``flock`` on ``path`` (created if missing)."""

    def __init__(self, path: Path):
        self.path = path
        self.fd: int | None = None

    def try_acquire(self, create: bool = True) -> bool:
        while True:
            fd = os.open(self.path, os.O_RDWR | (os.O_CREAT if create else 0), 0o644)
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except OSError as exc:
                os.close(fd)
                if exc.errno in (errno.EWOULDBLOCK, errno.EAGAIN, errno.EACCES):
                    return False
                raise
            # The holder before us may have unlinked the file after we opened it: then our lock
            # is on a dead inode and another run could lock a new file. Retry on a mismatch.
            try:
                same = os.fstat(fd).st_ino == os.stat(self.path).st_ino
            except FileNotFoundError:
                same = False
            if same:
                os.ftruncate(fd, 0)
                os.write(fd, f"{os.getpid()}\n".encode())
                self.fd = fd
                _ACTIVE.add(self.path)
                return True
            os.close(fd)

    def holder(self) -> str:
        try:
            pid = self.path.read_text().strip()
        except OSError:
            return "another process"
        return f"process {pid}" if pid.isdigit() else "another process"

    def release(self) -> None:
        if self.fd is None:
            return
        _ACTIVE.discard(self.path)
        try:
            os.unlink(self.path)  # while still holding it: nobody else can be using it
        except FileNotFoundError:
            pass
        os.close(self.fd)
        self.fd = None


def lock_path(target: Path) -> Path:
    """The lock file guarding ``target``."""
    return target.parent / f".{target.name}.lock"


def _remove(path: Path) -> None:
    if path.is_dir() and not path.is_symlink():
        shutil.rmtree(path, ignore_errors=True)
    else:
        try:
            path.unlink()
        except FileNotFoundError:
            pass


def clean_stale(target: Path) -> list[Path]:
    """Remove ``.NAME.*.tmp`` beside ``target`` and ``.*.tmp`` inside it (call with the lock held).

    Returns the paths removed.
    """
    removed = []
    if target.parent.is_dir():
        for entry in target.parent.glob(f".{target.name}.*.tmp"):
            _remove(entry)
            removed.append(entry)
    if target.is_dir():
        for entry in target.rglob(".*.tmp"):
            _remove(entry)
            removed.append(entry)
    return removed


def _missing_parents(path: Path) -> list[Path]:
    missing = []
    for parent in path.parents:
        if parent.exists():
            break
        missing.append(parent)
    return missing


def _check_replaceable(target: Path, option: str) -> None:
    """--overwrite replaces a run's folder, never the root, the home folder or the folder the
    user works in (or one above it)."""
    resolved = target.resolve()
    protected = {Path("/").resolve(), Path.home().resolve()}
    cwd = Path.cwd().resolve()
    if resolved in protected or resolved == cwd or resolved in cwd.parents:
        raise OutputError(f"{option} '{target}' is the root, the home or the current folder (or "
                          f"holds it); --overwrite replaces the whole folder: choose a folder of "
                          "its own")


def _describe_target(option: str, target: Path) -> str:
    return f"{option} '{target}'"


@contextmanager
def _locked_target(target: Path, option: str, overwrite: bool, want_dir: bool):
    """Lock ``target``, clean stale temporaries and check it may be (re)written; yields created
    parent folders (removed again on failure)."""
    if target.exists() and want_dir and not target.is_dir():
        raise OutputError(f"{_describe_target(option, target)} exists and is not a folder")
    if target.exists() and not want_dir and target.is_dir():
        raise OutputError(f"{_describe_target(option, target)} is a folder; expected a file name")
    created = _missing_parents(target)
    try:
        target.parent.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise OutputError(f"{_describe_target(option, target)}: cannot create its folder "
                          f"({exc.strerror})") from None
    lock = _Lock(lock_path(target))
    try:
        try:
            acquired = lock.try_acquire()
        except OSError as exc:
            raise OutputError(f"{_describe_target(option, target)}: cannot write into "
                              f"'{target.parent}' ({exc.strerror})") from None
        if not acquired:
            raise OutputError(f"{_describe_target(option, target)} is being written by another "
                              f"abu run ({lock.holder()}); wait for it to finish or choose "
                              f"another {option}")
        clean_stale(target)
        if target.exists() and overwrite and target.is_dir():
            _check_replaceable(target, option)
        if target.exists() and not overwrite:
            has_content = target.is_file() or any(target.iterdir())
            if has_content:
                raise OutputError(f"{_describe_target(option, target)} already holds results of "
                                  "another run; pass --overwrite to replace them, or choose "
                                  f"another {option}")
        yield created
    except BaseException:
        lock.release()
        for parent in created:  # innermost first
            try:
                parent.rmdir()
            except OSError:
                break
        raise
    else:
        lock.release()


@contextmanager
def output_folder(out: str | os.PathLike, *, overwrite: bool = False,
                  option: str = "--out") -> Iterator[Path]:
    """Write a run's results into a temporary sibling of ``out``, then rename it to ``out``.

    Yields the temporary folder. On an exception it is removed and ``out`` is untouched.

    Raises:
        OutputError: ``out`` is a file, is locked by another run, or holds results and
            ``overwrite`` is false.
    """
    target = Path(out).absolute()
    with _locked_target(target, option, overwrite, want_dir=True):
        tmp = Path(tempfile.mkdtemp(prefix=f".{target.name}.", suffix=".tmp", dir=target.parent))
        _ACTIVE.add(tmp)
        try:
            os.chmod(tmp, 0o777 & ~_umask())
            yield tmp
            _swap_in(tmp, target)
        except BaseException:
            _remove(tmp)
            raise
        finally:
            _ACTIVE.discard(tmp)


def _swap_in(tmp: Path, target: Path) -> None:
    if target.exists():
        old = Path(tempfile.mkdtemp(prefix=f".{target.name}.", suffix=".old.tmp",
                                    dir=target.parent))
        os.rename(target, old / "old")  # a name inside, removed with it
        os.rename(tmp, target)
        _remove(old)
    else:
        os.rename(tmp, target)


@contextmanager
def output_file(path: str | os.PathLike, *, overwrite: bool = False,
                option: str = "--out") -> Iterator[Path]:
    """Like :func:`output_folder` for one file: yields a temporary file name beside ``path``."""
    target = Path(path).absolute()
    with _locked_target(target, option, overwrite, want_dir=False):
        fd, name = tempfile.mkstemp(prefix=f".{target.name}.", suffix=".tmp", dir=target.parent)
        os.close(fd)
        tmp = Path(name)
        _ACTIVE.add(tmp)
        try:
            os.chmod(tmp, 0o666 & ~_umask())
            yield tmp
            os.replace(tmp, target)
        except BaseException:
            _remove(tmp)
            raise
        finally:
            _ACTIVE.discard(tmp)


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def check_not_inside(out: str | os.PathLike, inputs: list[str | os.PathLike],
                     option: str = "--out") -> None:
    """Refuse an output folder that is, or contains, one of the inputs (it would be replaced)."""
    target = Path(out).resolve()
    for item in inputs:
        p = Path(item).resolve()
        if p == target or target in p.parents:
            raise OutputError(f"{option} '{out}' holds the input '{item}'; the run replaces the "
                              f"whole folder: choose another {option}")


# ---------------------------------------------------------------------------- run temp dir
_RUN_DIR: tuple[int, Path, _Lock] | None = None


def _clean_stale_run_dirs(base: Path) -> None:
    for entry in base.glob(f"{RUN_PREFIX}*"):
        if not entry.is_dir():
            continue
        lock = _Lock(entry / ".lock")
        try:
            # A run writes its pid into the lock only once it holds it: a written, free lock
            # means its process is gone. A missing or empty one: a run still starting, or one
            # killed before it locked (then the pid in the name is no longer alive).
            if not (lock.path.is_file() and lock.path.stat().st_size > 0):
                if not _alive(_pid_of(entry.name)):
                    shutil.rmtree(entry, ignore_errors=True)
                continue
            if lock.try_acquire(create=False):
                shutil.rmtree(entry, ignore_errors=True)
                lock.release()
        except OSError:
            continue


def _pid_of(name: str) -> int | None:
    try:
        return int(name[len(RUN_PREFIX):].split("-", 1)[0])
    except ValueError:
        return None


def _alive(pid: int | None) -> bool:
    if pid is None:
        return True  # not ours to judge
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def use_run_tempdir() -> Path:
    """Point :mod:`tempfile` and ``TMPDIR`` at this process's own locked temporary folder.

    Called once per process by the command line (later calls return the same folder); removes the
    folders of killed runs first. Also turns SIGTERM into an orderly exit so it is cleaned up.
    """
    global _RUN_DIR
    if _RUN_DIR is not None and _RUN_DIR[0] == os.getpid():
        return _RUN_DIR[1]
    base = Path(os.environ.get("ABU_SYSTEM_TMPDIR") or tempfile.gettempdir())
    _clean_stale_run_dirs(base)
    run = Path(tempfile.mkdtemp(prefix=f"{RUN_PREFIX}{os.getpid()}-", dir=base))
    lock = _Lock(run / ".lock")
    lock.try_acquire()
    _RUN_DIR = (os.getpid(), run, lock)
    os.environ.setdefault("ABU_SYSTEM_TMPDIR", str(base))
    os.environ["TMPDIR"] = str(run)
    tempfile.tempdir = str(run)
    atexit.register(_remove_run_dir, os.getpid())
    if signal.getsignal(signal.SIGTERM) is signal.SIG_DFL:
        try:
            signal.signal(signal.SIGTERM, _terminate)
        except ValueError:  # not the main thread
            pass
    return run


def _terminate(signum, frame) -> None:  # pragma: no cover - exercised by a subprocess test
    # Not an exception: raised inside a Python FMU it would become an FMU error message. Remove
    # what this process was writing, then exit at once.
    for path in list(_ACTIVE):
        _remove(path)
    _remove_run_dir(os.getpid())
    try:
        os.write(2, b"abu: terminated\n")
    finally:
        os._exit(128 + signum)


def _remove_run_dir(pid: int) -> None:
    if _RUN_DIR is None or _RUN_DIR[0] != pid or os.getpid() != pid:
        return  # a forked child must not remove its parent's folder
    shutil.rmtree(_RUN_DIR[1], ignore_errors=True)
    if _RUN_DIR[2].fd is not None:
        os.close(_RUN_DIR[2].fd)

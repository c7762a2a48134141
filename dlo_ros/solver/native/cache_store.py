"""The compiled-code cache on disk: shared objects stored atomically and loaded only after checks.

Contract (threat model in SECURITY.md, "The compiled-code cache"):

* The cache directory (``cache_dir``) is created 0700 whatever the umask.  Before anything in it is
  loaded or written, it must be a directory owned by the effective uid and not writable by group or
  others, and each ancestor of its real path must be owned by root or that uid and not writable by
  group or others unless sticky (``/tmp``).  Otherwise nothing in it is used (``UnsafeCache``).
* A library ``<lib>`` is loaded only if ``<lib>.sha256`` (its record, written by ``store`` at
  compile time: ``sha256sum`` format, 0600, owned by this uid) names the sha256 of its content.
  The file is opened once (``O_RDONLY|O_NOFOLLOW|O_NONBLOCK``: a symlink is refused, a FIFO never
  blocks), ``fstat``-ed (a non-empty regular file of this uid, no group/other write), hashed from
  that descriptor and loaded through ``/proc/self/fd/<fd>``: what was hashed is what is loaded.
  Without ``/proc`` the bytes read from the descriptor are copied to a private 0700 directory and
  loaded from there.  Then its expected symbols must be present.
* Any refusal raises ``UnusableLibrary`` (an ``OSError``): callers rebuild the library or use the
  interpreted function.  An unsafe or unwritable cache also gives one ``CacheWarning`` per process.
* ``store`` writes a temporary file in the cache directory (``O_EXCL``, 0600), fsyncs it and
  renames it into place; the temporary file is removed on any failure.
* ``build_lock(lib)`` holds the cache directory's ``flock`` while a process looks for ``<lib>``
  and builds it: one build at a time per cache directory, so processes that miss the same library
  build it once (the others wait, at most BUILD_LOCK_WAIT_S, and load it).

A digest is computed once per process per file version (device, inode, size, mtime, ctime): hashing
a 667 kB library costs 0.36 ms, a first check 1.2 ms, a later one 49 us
(msg_docs/model_and_solver.md).
"""

from __future__ import annotations

import contextlib
import ctypes
import fcntl
import hashlib
import itertools
import os
import secrets
import shutil
import stat
import tempfile
import threading
import time
import warnings
from pathlib import Path
from typing import Iterator, Sequence

#: the record of a library ``x.so`` is ``x.so`` + RECORD_SUFFIX
RECORD_SUFFIX = ".sha256"
#: a record is one line: 64 hex digits, two spaces, the library's name
_MAX_RECORD = 512
_OPEN_FLAGS = os.O_RDONLY | os.O_NOFOLLOW | os.O_NONBLOCK | os.O_CLOEXEC


class CacheWarning(RuntimeWarning):
    """The cache is not used (unsafe, or cannot be written): interpreted derivatives instead."""


class UnusableLibrary(OSError):
    """A cached library that is missing, damaged or refused.

    A cached library that is missing, damaged or refused: rebuild it, or use the interpreted
    function.
    """


class UnsafeCache(UnusableLibrary):
    """The cache directory (or an ancestor) could be written by another user.

    The cache directory (or an ancestor) could be written by another user: nothing in it is
    used.
    """


#: the longest a build waits for another process's build in the same cache directory [s]
BUILD_LOCK_WAIT_S = 300.0

_lock = threading.RLock()
_warned = False
#: (dev, ino, size, mtime_ns, ctime_ns) -> sha256 hex digest of the file's content
_digests: dict[tuple[int, int, int, int, int], str] = {}
#: (dev, ino) -> (the descriptor it was loaded through, kept open, the handle).  Kept open so that
#: its number, which glibc remembers as the library's name, is never reused for another library.
_loaded: dict[tuple[int, int], tuple[int, ctypes.CDLL]] = {}
_copies = itertools.count()


def cache_dir() -> Path:
    """$DLO_CACHE_DIR, else $XDG_CACHE_HOME/dlo_ros, else ~/.cache/dlo_ros."""
    root = os.environ.get("DLO_CACHE_DIR")
    if root:
        return Path(root)
    return Path(os.environ.get("XDG_CACHE_HOME", Path.home() / ".cache")) / "dlo_ros"


def reset() -> None:
    """Forget this process's warning and digests (a test's fresh start).  Loaded libraries stay."""
    global _warned
    with _lock:
        _warned = False
        _digests.clear()


def warn_once(directory: Path, reason: str) -> None:
    """One ``CacheWarning`` per process: the cache is not used, and why."""
    global _warned
    with _lock:
        if _warned:
            return
        _warned = True
    warnings.warn(
        f"dlo_ros: compiled-code cache {directory} not used: {reason}; "
        "using interpreted derivatives (same answers, slower). See SECURITY.md.",
        CacheWarning,
        stacklevel=3,
    )


def _writable_by_others(st: os.stat_result) -> bool:
    return bool(st.st_mode & 0o022) and not st.st_mode & stat.S_ISVTX


def _check_ancestors(path: Path) -> None:
    """Raise UnsafeCache if another user could replace ``path`` or an ancestor.

    UnsafeCache if another user could replace ``path`` or one of its ancestors.
    """
    euid = os.geteuid()
    given = Path(os.path.abspath(path))
    for p in (given, *given.parents):  # a symlink of another user could be re-pointed
        with contextlib.suppress(FileNotFoundError):
            st = os.lstat(p)
            if stat.S_ISLNK(st.st_mode) and st.st_uid not in (0, euid):
                raise UnsafeCache(f"{p} is a symlink of uid {st.st_uid}")
    for p in Path(os.path.realpath(given)).parents:
        st = os.stat(p)
        if st.st_uid not in (0, euid):
            raise UnsafeCache(f"its ancestor {p} is owned by uid {st.st_uid}")
        if _writable_by_others(st):
            raise UnsafeCache(
                f"its ancestor {p} is writable by others (mode {st.st_mode & 0o7777:o})"
            )


def open_dir(path: Path, create: bool = False) -> int:
    """Open the checked cache directory ``path``; return its descriptor.

    A descriptor of the checked cache directory ``path`` (created 0700 when ``create``).
    UnsafeCache if it fails a check; FileNotFoundError (not created) or another OSError.
    """
    if create:
        missing = [p for p in (path, *path.parents) if not os.path.lexists(p)]
        for p in reversed(missing):  # ancestors too (e.g. ~/.cache): 0700, never the umask's 0775
            with contextlib.suppress(FileExistsError):
                os.mkdir(p, 0o700)
        if path in missing:
            os.chmod(path, 0o700)  # a umask like 0277 removes bits; none for others either way
    _check_ancestors(path)
    fd = os.open(path, os.O_RDONLY | os.O_DIRECTORY | os.O_CLOEXEC)
    try:
        st, euid = os.fstat(fd), os.geteuid()
        if st.st_uid != euid:
            raise UnsafeCache(f"it is owned by uid {st.st_uid}, not {euid}")
        if st.st_mode & 0o022:
            raise UnsafeCache(
                f"it is writable by group or others (mode {st.st_mode & 0o7777:o}; chmod 700 it)"
            )
    except BaseException:
        os.close(fd)
        raise
    return fd


def _open_entry(dfd: int, name: str) -> tuple[int, os.stat_result]:
    """Open the cache entry ``name``; return (descriptor, fstat).

    (descriptor, fstat) of the file ``name``: a non-empty regular file of this uid, no
    group/other write; UnusableLibrary otherwise.  Never blocks (a FIFO is refused after fstat).
    """
    try:
        fd = os.open(name, _OPEN_FLAGS, dir_fd=dfd)
    except FileNotFoundError as e:
        raise UnusableLibrary(f"{name} is not in the cache") from e
    except OSError as e:  # ELOOP: a symlink; ENXIO and others: not a file
        raise UnusableLibrary(f"{name} cannot be opened safely ({e.strerror})") from e
    st = os.fstat(fd)
    problem = (
        "is not a regular file"
        if not stat.S_ISREG(st.st_mode)
        else f"is owned by uid {st.st_uid}"
        if st.st_uid != os.geteuid()
        else "is writable by group or others"
        if st.st_mode & 0o022
        else "is empty"
        if st.st_size == 0
        else None
    )
    if problem:
        os.close(fd)
        raise UnusableLibrary(f"{name} {problem}")
    return fd, st


def _read_all(fd: int, size: int) -> bytes:
    chunks, offset = [], 0
    while offset < size:
        chunk = os.pread(fd, min(1 << 20, size - offset), offset)
        if not chunk:
            break
        chunks.append(chunk)
        offset += len(chunk)
    return b"".join(chunks)


def _digest(fd: int, st: os.stat_result) -> str:
    key = (st.st_dev, st.st_ino, st.st_size, st.st_mtime_ns, st.st_ctime_ns)
    with _lock:
        known = _digests.get(key)
    if known is None:
        known = hashlib.sha256(_read_all(fd, st.st_size)).hexdigest()
        with _lock:
            _digests[key] = known
    return known


def _recorded_digest(dfd: int, name: str) -> str:
    fd, st = _open_entry(dfd, name + RECORD_SUFFIX)
    try:
        if st.st_size > _MAX_RECORD:
            raise UnusableLibrary(f"{name}{RECORD_SUFFIX} is not a record")
        words = _read_all(fd, st.st_size).split()
    finally:
        os.close(fd)
    if len(words) != 2 or len(words[0]) != 64 or words[1] != name.encode():
        raise UnusableLibrary(f"{name}{RECORD_SUFFIX} is not a record of {name}")
    return words[0].decode("ascii", "replace").lower()


def _verified(dfd: int, name: str) -> tuple[int, os.stat_result]:
    """(descriptor, fstat) of the library ``name`` whose content matches its record."""
    fd, st = _open_entry(dfd, name)
    try:
        if _digest(fd, st) != _recorded_digest(dfd, name):
            raise UnusableLibrary(f"{name}: its content does not match its record")
    except BaseException:
        os.close(fd)
        raise
    return fd, st


def _checked_dir(directory: Path) -> int:
    """open_dir(directory), its refusal turned into the warning plus UnusableLibrary."""
    try:
        return open_dir(directory)
    except UnsafeCache as e:
        warn_once(directory, str(e))
        raise
    except OSError as e:
        raise UnusableLibrary(f"{directory}: {e.strerror or e}") from e


def is_verified(lib: Path) -> bool:
    """Would ``load`` accept ``lib`` (its symbols aside)?  Nothing is loaded."""
    try:
        dfd = _checked_dir(lib.parent)
    except UnusableLibrary:
        return False
    try:
        fd, _ = _verified(dfd, lib.name)
        os.close(fd)
        return True
    except UnusableLibrary:
        return False
    finally:
        os.close(dfd)


def _dlopen(fd: int, st: os.stat_result, name: str) -> ctypes.CDLL:
    """Load the file open on ``fd`` (what was hashed).

    Load the file open on ``fd`` (what was hashed): through /proc/self/fd, else a private
    copy.
    """
    proc = f"/proc/self/fd/{fd}"
    try:
        if os.path.exists(proc):
            return ctypes.CDLL(proc)
        with tempfile.TemporaryDirectory(prefix="dlo_lib_") as private:  # mkdtemp: 0700
            copy = os.path.join(private, f"{next(_copies)}_{name}")
            out = os.open(copy, os.O_WRONLY | os.O_CREAT | os.O_EXCL | os.O_CLOEXEC, 0o600)
            with os.fdopen(out, "wb") as f:
                f.write(_read_all(fd, st.st_size))
            return ctypes.CDLL(copy)
    except OSError as e:  # dlopen refused it
        raise UnusableLibrary(f"{name} cannot be loaded: {e}") from e


def load(lib: Path, symbols: Sequence[str]) -> ctypes.CDLL:
    """Load the library ``lib`` if every check passes.

    The library ``lib`` if every check passes (module docstring) and it has ``symbols``;
    UnusableLibrary (UnsafeCache, after the warning) otherwise.  Never loads anything refused.
    """
    dfd = _checked_dir(lib.parent)
    try:
        with _lock:
            fd, st = _verified(dfd, lib.name)
            known = _loaded.get((st.st_dev, st.st_ino))
            if known is not None:
                os.close(fd)
                handle = known[1]
            else:
                try:
                    handle = _dlopen(fd, st, lib.name)
                except BaseException:
                    os.close(fd)
                    raise
                _loaded[(st.st_dev, st.st_ino)] = (fd, handle)
    finally:
        os.close(dfd)
    missing = [s for s in symbols if not hasattr(handle, s)]
    if missing:
        raise UnusableLibrary(f"{lib.name} lacks {', '.join(missing)}")
    return handle


def _write_atomic(dfd: int, name: str, data: bytes) -> None:
    tmp = f".{name}.{os.getpid()}.{secrets.token_hex(4)}.tmp"
    fd = os.open(
        tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL | os.O_NOFOLLOW | os.O_CLOEXEC, 0o600, dir_fd=dfd
    )
    try:
        try:
            os.fchmod(fd, 0o600)
            view = memoryview(data)
            while view:
                view = view[os.write(fd, view) :]
            os.fsync(fd)
        finally:
            os.close(fd)
        with contextlib.suppress(FileNotFoundError):  # a damaged entry: a directory in the way
            if stat.S_ISDIR(os.stat(name, dir_fd=dfd, follow_symlinks=False).st_mode):
                shutil.rmtree(name, dir_fd=dfd)
        os.replace(tmp, name, src_dir_fd=dfd, dst_dir_fd=dfd)  # also over a FIFO or symlink
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(tmp, dir_fd=dfd)
        raise


def writable_dir(directory: Path) -> bool:
    """Create (0700) and check the cache directory before a compile; False after the warning."""
    try:
        os.close(open_dir(directory, create=True))
        return True
    except OSError as e:
        warn_once(
            directory,
            str(e)
            if isinstance(e, UnsafeCache)
            else f"it cannot be created or opened ({e.strerror or e})",
        )
        return False


def store(lib: Path, data: bytes) -> bool:
    """Store the library ``data`` at ``lib`` with its record, each atomically (0600).

    Put the library ``data`` at ``lib`` with its record, each atomically (0600); False after the
    warning if the cache cannot take it (unsafe, read-only, full): no temporary file is left.
    """
    try:
        dfd = open_dir(lib.parent, create=True)
    except OSError as e:
        warn_once(
            lib.parent,
            str(e)
            if isinstance(e, UnsafeCache)
            else f"it cannot be created or opened ({e.strerror or e})",
        )
        return False
    try:
        digest = hashlib.sha256(data).hexdigest()
        # library first: a reader in between sees the old record, refuses and rebuilds
        _write_atomic(dfd, lib.name, data)
        _write_atomic(dfd, lib.name + RECORD_SUFFIX, f"{digest}  {lib.name}\n".encode())
        with contextlib.suppress(OSError):
            os.fsync(dfd)
        return True
    except OSError as e:
        warn_once(lib.parent, f"it cannot be written ({e.strerror or e})")
        return False
    finally:
        os.close(dfd)


@contextlib.contextmanager
def build_lock(lib: Path) -> Iterator[None]:
    """Hold the cache directory's build lock across processes (``flock`` on the directory).

    Two processes that miss the same library build it once: the second waits here and then finds
    the first's in the cache.  One build at a time per cache directory (a lock per library would
    leave a file per library behind; concurrent compilers multiply the memory).  A process waits
    at most BUILD_LOCK_WAIT_S, then builds without the lock (a holder that was stopped must not
    hang every other compile).  Where the directory cannot be opened (unsafe, or it cannot be
    created: the build then reports it), nothing is held.
    """
    try:
        dfd: int | None = open_dir(lib.parent, create=True)
    except OSError:
        dfd = None
    try:
        deadline = time.monotonic() + BUILD_LOCK_WAIT_S
        while dfd is not None:
            try:
                fcntl.flock(dfd, fcntl.LOCK_EX | fcntl.LOCK_NB)
                break
            except BlockingIOError:
                if time.monotonic() > deadline:  # a holder stopped (Ctrl-Z): build without it
                    break
                time.sleep(0.05)
        yield
    finally:
        if dfd is not None:
            os.close(dfd)  # releases the lock

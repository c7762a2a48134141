"""The compiled-code cache cannot be poisoned (issue #35): nothing in an unsafe cache directory is
loaded, a library runs only if its sha256 matches the record written when it was compiled, damaged
entries are rebuilt, and a cache that cannot be written falls back to interpreted derivatives with
one warning.  SECURITY.md, "The compiled-code cache", is the contract."""
from __future__ import annotations

import errno
import hashlib
import os
import shutil
import signal
import stat
import subprocess
import sys
import warnings
from pathlib import Path

import casadi as ca
import numpy as np
import pytest

from dlo_ros.solver import ShapeSolver

from dlo_ros.solver.native import cache_store

from dlo_ros.solver.build import compiled
from dlo_ros.solver.options import SolverOptions

from support.problems import clamped_pair

PLANAR = SolverOptions(model="planar", order=6, quadrature_nodes=20, error_tolerance=1.0)
TARGET = {"right": ((0.5, 0.0, 0.1), (0.0, 0.0, 0.0, 1.0))}
PLANTED_C = r"""
#include <stdio.h>
__attribute__((constructor)) static void planted(void) {
  FILE *f = fopen(MARKER, "w");
  if (f) { fputs("planted code ran\n", f); fclose(f); }
}
int not_what_you_expect(void) { return 42; }
"""

pytestmark = pytest.mark.skipif(compiled.compiler() is None, reason="no C compiler")


def _problem():
    return clamped_pair(right=(0.6, 0.0, 0.0), weight=0.1)


@pytest.fixture(autouse=True)
def _fresh_process_state(monkeypatch):
    """Compiling on (the autouse DLO_NO_COMPILE=1 off), and this process's cache warning and
    digests forgotten, as in a fresh process."""
    monkeypatch.delenv("DLO_NO_COMPILE", raising=False)
    cache_store.reset()
    yield
    cache_store.reset()


@pytest.fixture(scope="module")
def built(tmp_path_factory):
    """A cache with every library of the small scene, compiled once; tests work on copies."""
    root = tmp_path_factory.mktemp("built") / "cache"
    with pytest.MonkeyPatch.context() as mp:
        mp.delenv("DLO_NO_COMPILE", raising=False)
        mp.setenv("DLO_CACHE_DIR", str(root))
        assert ShapeSolver(_problem(), PLANAR, compile="blocking").all_compiled
    return root


@pytest.fixture(scope="module")
def interpreted_points():
    """The independent answer: the same solve on interpreted CasADi derivatives."""
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("DLO_NO_COMPILE", "1")
        answer = ShapeSolver(_problem(), PLANAR, compile="off").solve(TARGET)
    assert answer.ok
    return answer.points


def _copy(built: Path, tmp_path: Path, monkeypatch) -> Path:
    cache = tmp_path / "cache"
    shutil.copytree(built, cache)  # modes kept: 0700 directory, 0600 files
    monkeypatch.setenv("DLO_CACHE_DIR", str(cache))
    return cache


def _kkt_free(cache: Path) -> Path:
    (lib,) = cache.glob("dlo_kkt_free_split_*.so")
    return lib


def _planted(tmp_path: Path, marker: Path) -> Path:
    """A shared object whose constructor writes ``marker`` when it is loaded."""
    source = tmp_path / "planted.c"
    source.write_text(PLANTED_C)
    out = tmp_path / "planted.so"
    subprocess.run([compiled.compiler(), "-shared", "-fPIC", f'-DMARKER="{marker}"', "-o",
                    str(out), str(source)], check=True, capture_output=True)
    return out


def _plant(planted: Path, lib: Path, with_record: bool) -> None:
    """Put ``planted`` at ``lib`` (a new file); ``with_record``: also a matching record (as if this
    user wrote it)."""
    data = planted.read_bytes()
    lib.unlink(missing_ok=True)
    lib.write_bytes(data)
    if with_record:
        Path(f"{lib}.sha256").write_text(f"{hashlib.sha256(data).hexdigest()}  {lib.name}\n")


def _record_matches(lib: Path) -> bool:
    """An independent check of an entry: a regular file whose sha256 is the one its record
    names."""
    st = os.lstat(lib)
    words = Path(f"{lib}.sha256").read_text().split()
    return stat.S_ISREG(st.st_mode) and words == [hashlib.sha256(lib.read_bytes()).hexdigest(),
                                                  lib.name]


def _cache_warnings(record) -> list:
    return [w for w in record if issubclass(w.category, cache_store.CacheWarning)]


def _assert_answers(solver, interpreted_points) -> None:
    answer = solver.solve(TARGET)
    assert answer.ok
    np.testing.assert_allclose(answer.points, interpreted_points, atol=1e-9)


def test_a_planted_library_is_never_run_and_is_rebuilt(built, tmp_path, monkeypatch,
                                                       interpreted_points):
    """Compiled into the exact path the solver loads, without a matching record: its constructor
    never runs; a cached solver goes interpreted, a compiling one rebuilds the entry."""
    cache = _copy(built, tmp_path, monkeypatch)
    marker = tmp_path / "marker"
    lib = _kkt_free(cache)
    _plant(_planted(tmp_path, marker), lib, with_record=False)
    fn = ShapeSolver(_problem(), PLANAR, compile="off").nlp.kkt_free_split_fn
    assert compiled.library_path(fn) == lib  # the path the solver would load
    assert compiled.cached_library(fn) is None
    with warnings.catch_warnings(record=True) as record:
        warnings.simplefilter("always")
        cached = ShapeSolver(_problem(), PLANAR, compile="cached")
        assert not marker.exists() and not cached.kkt_compiled
        _assert_answers(cached, interpreted_points)
        rebuilt = ShapeSolver(_problem(), PLANAR, compile="blocking")
    assert not marker.exists()
    assert not _cache_warnings(record)  # a damaged entry is not a cache problem
    assert rebuilt.kkt_compiled and _record_matches(lib)
    _assert_answers(rebuilt, interpreted_points)


@pytest.mark.parametrize("unsafe", ["world-writable", "group-writable", "another-owner"])
def test_an_unsafe_cache_directory_is_not_used(unsafe, built, tmp_path, monkeypatch,
                                               interpreted_points):
    """A planted library WITH a matching record (only the directory check stands in the way) is not
    loaded; one warning; nothing is written there; the solve answers, interpreted."""
    if unsafe == "another-owner" and os.geteuid() != 0:
        pytest.skip("chown to another uid needs root")
    cache = _copy(built, tmp_path, monkeypatch)
    marker = tmp_path / "marker"
    _plant(_planted(tmp_path, marker), _kkt_free(cache), with_record=True)
    if unsafe == "another-owner":
        os.chown(cache, 65534, 65534)
    else:
        os.chmod(cache, 0o777 if unsafe == "world-writable" else 0o770)
    before = sorted(p.name for p in cache.iterdir())
    with warnings.catch_warnings(record=True) as record:
        warnings.simplefilter("always")
        for mode in ("cached", "blocking"):
            solver = ShapeSolver(_problem(), PLANAR, compile=mode)
            assert not marker.exists() and not solver.kkt_compiled
            assert not solver.functions.outputs_compiled  # nothing at all was loaded from there
            _assert_answers(solver, interpreted_points)
    assert len(_cache_warnings(record)) == 1
    assert str(cache) in str(_cache_warnings(record)[0].message)
    assert sorted(p.name for p in cache.iterdir()) == before


def _truncate(lib: Path, tmp_path: Path) -> None:
    size = lib.stat().st_size
    with open(lib, "r+b") as f:
        f.truncate(size // 2)


def _fifo(lib: Path, tmp_path: Path) -> None:
    lib.unlink()
    os.mkfifo(lib, 0o600)


def _directory(lib: Path, tmp_path: Path) -> None:
    lib.unlink()
    lib.mkdir(0o700)
    (lib / "inside").write_text("x")


def _symlink(lib: Path, tmp_path: Path) -> None:
    real = tmp_path / "elsewhere.so"
    shutil.copyfile(lib, real)
    lib.unlink()
    lib.symlink_to(real)  # the record matches the target's bytes: a symlink is refused anyway


def _foreign(lib: Path, tmp_path: Path) -> None:
    """A library without the expected symbols, with a matching record (a bug, not an attack)."""
    source = tmp_path / "foreign.c"
    source.write_text("int dlo_something_else(void) { return 1; }\n")
    out = tmp_path / "foreign.so"
    subprocess.run([compiled.compiler(), "-shared", "-fPIC", "-o", str(out), str(source)],
                   check=True)
    _plant(out, lib, with_record=True)


class _Hang(Exception):
    pass


def _alarm(*_):
    raise _Hang("the solver blocked on a damaged cache entry")


@pytest.mark.parametrize("damage", [_truncate, _fifo, _directory, _symlink, _foreign],
                         ids=lambda f: f.__name__.strip("_"))
def test_a_damaged_entry_is_rebuilt_not_loaded(damage, built, tmp_path, monkeypatch,
                                               interpreted_points):
    cache = _copy(built, tmp_path, monkeypatch)
    lib = _kkt_free(cache)
    damage(lib, tmp_path)
    previous = signal.signal(signal.SIGALRM, _alarm)
    signal.alarm(600)  # a FIFO opened without O_NONBLOCK would block forever
    try:
        with warnings.catch_warnings(record=True) as record:
            warnings.simplefilter("always")
            solver = ShapeSolver(_problem(), PLANAR, compile="blocking")
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, previous)
    assert not _cache_warnings(record)
    assert solver.kkt_compiled and solver.functions.newton_native is not None
    assert _record_matches(lib)  # rebuilt in place: a regular file matching its record
    _assert_answers(solver, interpreted_points)


def _sine():
    x = ca.SX.sym("x", 2)
    return ca.Function("dlo_cache_probe", [x], [ca.sin(x)])


def _check_interpreted(native, ok) -> None:
    assert not ok and isinstance(native, compiled.InterpretedFunction)
    np.testing.assert_allclose(native(np.array([0.3, 1.0]))[0].ravel(), np.sin([0.3, 1.0]))


def test_a_cache_path_that_cannot_be_created_falls_back_with_one_warning(tmp_path, monkeypatch,
                                                                         interpreted_points):
    """The cache path under a regular file (mkdir fails, as root too): the solve answers."""
    blocker = tmp_path / "a-file"
    blocker.write_text("")
    monkeypatch.setenv("DLO_CACHE_DIR", str(blocker / "cache"))
    with warnings.catch_warnings(record=True) as record:
        warnings.simplefilter("always")
        solver = ShapeSolver(_problem(), PLANAR, compile="blocking")
        _assert_answers(solver, interpreted_points)
        _check_interpreted(*compiled.compiled(_sine()))
    assert not solver.kkt_compiled and len(_cache_warnings(record)) == 1
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a-file"]


@pytest.mark.parametrize("failure", ["ENOSPC on fsync", "EROFS on create"])
def test_a_full_or_read_only_cache_falls_back_and_leaves_no_temporary_file(failure, tmp_path,
                                                                           monkeypatch):
    cache = tmp_path / "cache"
    monkeypatch.setenv("DLO_CACHE_DIR", str(cache))
    real_open = os.open

    def full(fd):
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    def read_only(path, flags, *args, **kwargs):
        if flags & os.O_CREAT and str(path).endswith(".tmp"):
            raise OSError(errno.EROFS, os.strerror(errno.EROFS), path)
        return real_open(path, flags, *args, **kwargs)

    if failure.startswith("ENOSPC"):
        monkeypatch.setattr(os, "fsync", full)
    else:
        monkeypatch.setattr(os, "open", read_only)
    with warnings.catch_warnings(record=True) as record:
        warnings.simplefilter("always")
        for _ in range(2):
            _check_interpreted(*compiled.compiled(_sine()))
    assert len(_cache_warnings(record)) == 1
    assert os.listdir(cache) == []  # neither a library nor a temporary file


def test_under_umask_002_the_cache_is_private(tmp_path, monkeypatch):
    cache = tmp_path / "deeper" / "cache"
    monkeypatch.setenv("DLO_CACHE_DIR", str(cache))
    old = os.umask(0o002)
    try:
        native, ok = compiled.compiled(_sine())
    finally:
        os.umask(old)
    assert ok and isinstance(native, compiled.NativeFunction)
    np.testing.assert_allclose(native(np.array([0.3, 1.0]))[0].ravel(), np.sin([0.3, 1.0]))
    assert stat.S_IMODE(cache.stat().st_mode) == 0o700
    files = list(cache.iterdir())
    assert {p.suffix for p in files} == {".so", ".sha256"}
    for p in files:
        assert stat.S_IMODE(p.stat().st_mode) in (0o600, 0o700), p
    assert compiled.cached_library(_sine()) is not None


def test_cached_library_does_not_report_a_library_that_would_be_refused(tmp_path, monkeypatch):
    monkeypatch.setenv("DLO_CACHE_DIR", str(tmp_path / "cache"))
    fn = _sine()
    assert compiled.compiled(fn)[1]
    lib = compiled.cached_library(fn)
    assert lib == compiled.library_path(fn)
    data = bytearray(lib.read_bytes())
    data[-1] ^= 0xFF  # one byte changed: the record no longer matches
    changed = tmp_path / "changed.so"
    changed.write_bytes(bytes(data))
    os.replace(changed, lib)  # not in place: this process has the old file mapped
    assert compiled.cached_library(fn) is None
    assert compiled.compiled(fn)[1] and compiled.cached_library(fn) == lib  # rebuilt


def test_the_cli_on_an_unsafe_cache_answers_with_one_warning_and_no_traceback(tmp_path):
    """``dlo solve`` (cached mode) with a world-writable cache: exit 0, one warning line and nothing
    else on stderr."""
    cache = tmp_path / "cache"
    cache.mkdir()
    os.chmod(cache, 0o777)
    env = {k: v for k, v in os.environ.items() if k != "DLO_NO_COMPILE"}
    env["DLO_CACHE_DIR"] = str(cache)
    run = subprocess.run([sys.executable, "-m", "dlo_ros.cli", "solve", "default_cable", "--json"],
                         capture_output=True, text=True, env=env, timeout=600)
    assert run.returncode == 0, run.stderr
    assert "Traceback" not in run.stderr
    assert run.stderr.count("compiled-code cache") == 1
    assert "writable by group or others" in run.stderr
    # the warning is its message alone: no "file:line: CacheWarning:" and no line of source code
    lines = [line for line in run.stderr.splitlines() if line.strip()]
    assert len(lines) == 1 and lines[0].startswith("dlo_ros: compiled-code cache"), run.stderr
    assert os.listdir(cache) == []


def test_without_proc_the_checked_bytes_are_loaded_from_a_private_copy(tmp_path, monkeypatch):
    """Where /proc/self/fd is missing, the descriptor's bytes are copied into a private temporary
    directory, loaded from there, and the copy removed; the function answers."""
    import tempfile

    monkeypatch.setenv("DLO_CACHE_DIR", str(tmp_path / "cache"))
    private = tmp_path / "tmp"
    private.mkdir()
    monkeypatch.setattr(tempfile, "tempdir", str(private))
    real_exists = os.path.exists
    monkeypatch.setattr(os.path, "exists",
                        lambda p: False if str(p).startswith("/proc/self/fd/") else real_exists(p))
    native, ok = compiled.compiled(_sine())
    assert ok and isinstance(native, compiled.NativeFunction)
    np.testing.assert_allclose(native(np.array([0.3, 1.0]))[0].ravel(), np.sin([0.3, 1.0]))
    assert _record_matches(compiled.library_path(_sine()))
    assert list(private.iterdir()) == []  # the compile's and the load's temporary files are gone

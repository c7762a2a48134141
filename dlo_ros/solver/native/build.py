"""The compiled Newton drivers' C: read from the package, made into one source, keyed and compiled.

The drivers are C files shipped in the package (``dlo_ros/solver/native/``, read through
``importlib.resources``, so an installed package has them).  A driver's include directive for a
header ``"x.h"`` beside it is replaced by that file's text (once per source), and the result is
appended to CasADi's generated code of the functions it runs, which ``-DDLO_SYSTEM=…`` and
``-DDLO_RESIDUAL=…`` name.  Every setting the drivers share with the Python paths arrives as a
``-D`` flag from ``native.settings``.

Cache keys: a driver's library name carries a digest of its assembled source and of the compiler
flags with the settings' ``-D`` values (``driver_digest``), next to the generated function's
``compiler.fingerprint``; a change to either C or a setting gives a new name, hence a new build.
Loading stays ``cache_store``'s (owner, mode and sha256 checks), as for every compiled library.
"""

from __future__ import annotations

import hashlib
import re
from importlib import resources
from importlib.resources.abc import Traversable
from pathlib import Path

import casadi as ca

from . import settings as native_settings
from .cache_store import cache_dir
from .compiler import FLAGS, build_library, fingerprint

#: the contact-free loop (``native.newton.NativeNewton``), the active-set loop (``ActiveNewton``),
#: the saddle's escape (``native.saddle.NativeSaddle``)
FREE_DRIVER, ACTIVE_DRIVER, SADDLE_DRIVER = "newton_free.c", "newton_active.c", "saddle_escape.c"
#: the drivers appended to the full KKT function's library (both run that function)
ACTIVE_DRIVERS = (ACTIVE_DRIVER, SADDLE_DRIVER)

#: a local include: a file of the native directory, by a plain name
_INCLUDE = re.compile(r'^#[ \t]*include[ \t]+"([A-Za-z0-9_]+\.h)"[ \t]*$', re.MULTILINE)


def _native() -> Traversable:
    return resources.files("dlo_ros.solver").joinpath("native")


def c_files() -> list[str]:
    """Return the names of the shipped C files (each a driver that compiles on its own)."""
    return sorted(entry.name for entry in _native().iterdir() if entry.name.endswith(".c"))


def read(name: str) -> str:
    """Return the text of the shipped C file or header ``name``."""
    return _native().joinpath(name).read_text(encoding="utf-8")


def driver_source(*names: str) -> str:
    """Return the drivers ``names`` in turn, their local includes replaced by the headers' text.

    Each header's text comes once in the whole (its first include), so that drivers appended to
    one library share it.
    """
    seen: set[str] = set()

    def expand(text: str) -> str:
        def include(match: re.Match) -> str:
            header = match.group(1)
            if header in seen:
                return ""
            seen.add(header)
            return expand(read(header))

        return _INCLUDE.sub(include, text)

    return "\n".join(expand(read(name)) for name in names)


def settings_flags() -> tuple[str, ...]:
    """Return the compiler flags a driver's code depends on beside its functions' names.

    The compiler flags a driver's code depends on beside its functions' names:
    ``compiler.FLAGS`` and the shared settings (``native.settings.defines``).
    """
    return (*FLAGS, *native_settings.defines())


def driver_flags(system: ca.Function, residual: ca.Function) -> tuple[str, ...]:
    """Return every flag a driver is compiled with.

    Every flag a driver is compiled with, around the generated functions ``system`` and
    ``residual``.
    """
    names = (
        f"-DDLO_SYSTEM={system.name()}",
        f"-DDLO_SYSTEM_WORK={system.name()}_work",
        f"-DDLO_RESIDUAL={residual.name()}",
        f"-DDLO_RESIDUAL_WORK={residual.name()}_work",
    )
    return (*settings_flags(), *names)


def driver_digest(*names: str) -> str:
    """Return 8 hex digits of sha256 over drivers' source and ``settings_flags``.

    8 hex digits of sha256 over the drivers' assembled source and ``settings_flags``.  The
    functions' names are left out: the library's name carries the system function's name and
    fingerprint, which fixes its residual's code too.
    """
    h = hashlib.sha256(driver_source(*names).encode())
    h.update("\0".join(settings_flags()).encode())
    return h.hexdigest()[:8]


def free_library_path(fn: ca.Function, kkt_lib: Path | None = None) -> Path:
    """Return where the contact-free driver compiled with ``fn`` is (or will be) cached.

    Where the contact-free driver compiled with ``fn`` (``StringNLP.kkt_free_split_fn``) is (or
    will be) cached.  ``kkt_lib``: ``fn``'s own ``compiled.library_path``, when the caller has it
    (its name carries the fingerprint, which otherwise costs an evaluation of ``fn``).
    """
    key = kkt_lib.stem.rsplit("_", 1)[1] if kkt_lib is not None else fingerprint(fn)
    return cache_dir() / f"dlo_newton_{key}_{driver_digest(FREE_DRIVER)}.so"


def active_library_path(fn: ca.Function) -> Path:
    """Return where ``fn``'s library with the active-set driver is (or will be) cached.

    Where ``fn``'s library (``StringNLP.kkt_split_fn``) with the active-set driver and the
    saddle's escape appended (``ACTIVE_DRIVERS``) is (or will be) cached.
    """
    digest = driver_digest(*ACTIVE_DRIVERS)
    return cache_dir() / f"{fn.name()}_{fingerprint(fn)}_active_{digest}.so"


def compile_free(fn: ca.Function, residual: ca.Function, cc: str, lib: Path, nice: int) -> bool:
    """Build the contact-free driver around ``fn`` and ``residual`` into ``lib``.

    Build the contact-free driver around ``fn`` and ``residual`` into ``lib``
    (``build_library``: stored through ``cache_store``); False if the compiler fails or the cache
    is unusable.  Callers hold ``compiler.COMPILER_LOCK``.
    """
    return build_library(
        fn,
        lib,
        cc,
        flags=driver_flags(fn, residual),
        nice=nice,
        extra_source=driver_source(FREE_DRIVER),
        also=(residual,),
    )

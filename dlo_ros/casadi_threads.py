"""CasADi with thread-safe symbolics: what the solver's background work needs of it.

``model: auto`` builds new models on a worker thread while a stream evaluates the current one
(``solver/auto/background.py``), and the node solves on its own thread beside its executor.  Two
threads inside CasADi at once are safe only where CasADi guards its shared state: the sparsity
cache, the cached SX constants, reference counts, plugin loading and the Functions' work memory.
It does from 3.7 when built with ``CASADI_WITH_THREADSAFE_SYMBOLICS`` (the PyPI wheels are; casadi
issue 2955), and 3.7 still had a race in its weak references that 3.8 fixed.  Before that, CasADi
says it guarantees thread-safe evaluation, not symbolics (casadi issues 1355, 3518): a model
built beside a solve may crash the process.  So a CasADi without both is refused when the solver
is imported, with the fix in the message, instead of a crash at some later update.  (Measured on
casadi 3.8.2: 75 runs of two threads, one building symbolics and one evaluating, 30–60 s each,
no crash and no wrong value; a global lock instead stalled the evaluating thread for up to 11 s.)
"""

from __future__ import annotations

#: the oldest CasADi release whose symbolics are thread-safe with no known race
OLDEST = (3, 8)

#: the build flag that turns the guards on (``casadi.CasadiMeta.compiler_flags()``)
FLAG = "CASADI_WITH_THREADSAFE_SYMBOLICS"


class CasadiUnsupported(ImportError):
    """The imported CasADi is refused (``unsupported``); the message names the fix."""


def unsupported(version: str, compiler_flags: str) -> str | None:
    """Return why a CasADi of ``version`` built with ``compiler_flags`` is refused, or None.

    None for a release ≥ OLDEST built with FLAG; a version that does not start with two integers
    is refused too.
    """
    try:
        major, minor = (int(part) for part in version.split(".")[:2])
    except ValueError:
        return f"CasADi reports version {version!r}, which is not a release number"
    if (major, minor) < OLDEST:
        return f"CasADi {version} is older than {OLDEST[0]}.{OLDEST[1]}"
    if FLAG not in compiler_flags:
        return f"CasADi {version} was built without {FLAG}"
    return None


def require_threadsafe_casadi() -> None:
    """Raise CasadiUnsupported naming the fix when the imported CasADi is refused."""
    import casadi  # start-up: the solver imports it anyway

    version = str(getattr(casadi, "__version__", "unknown"))  # (the wheel ships no stubs)
    why = unsupported(version, casadi.CasadiMeta.compiler_flags())
    if why is not None:
        raise CasadiUnsupported(
            f"dlo_ros needs CasADi >= {OLDEST[0]}.{OLDEST[1]} with thread-safe symbolics: {why} "
            f"(imported from {casadi.__file__}).  Install the PyPI wheel: "
            f"pip install 'casadi>={OLDEST[0]}.{OLDEST[1]}'"
        )

"""A check's shadow model is compiled ahead for its derivatives only (``auto/shadows.shadow_solve``).

Beside a stream (background checks), an interpreted shadow holds the GIL through long CasADi calls,
so a shadow without compiled derivatives is compiled ahead.  A shadow whose derivatives are compiled
(a clone of a compiled mesh, ``build/mesh_clone.py``: a check on a contact moves a breakpoint onto it)
lacks at most its outputs' library, which pays only for a model that streams: each check on the main
job's post started gcc on the outputs of a moved mesh that was never used again (three during the
manoeuvre, beside the stream on two cores).  The rule, with stand-ins for the pool and the solver.
"""

from __future__ import annotations

from types import SimpleNamespace

import pytest

from dlo_ros.solver.auto import shadows


class Pool:
    """The pool's part shadow_solve uses: ``solver_for``, the worker, ``compile_ahead`` (recorded)."""

    def __init__(self, shadow, background: bool) -> None:
        self.shadow, self.worker, self.compiled_ahead = shadow, SimpleNamespace(background=background), []

    def solver_for(self, choice, problem, **kwargs):
        return self.shadow

    def compile_ahead(self, solver) -> None:
        self.compiled_ahead.append(solver)


class Shadow:
    def __init__(self, kkt_compiled: bool) -> None:
        self.kkt_compiled = kkt_compiled

    def solve(self, poses, **kwargs):
        return SimpleNamespace(ok=True, status="ok", poses=poses)

    def snapshot(self):
        return None  # (no state committed: nothing for ``snap.answers``)


SNAP = SimpleNamespace(problem=None, inner=None, state=None, poses={"right": None}, limited=True)


@pytest.mark.parametrize("background, compiled, expected", [
    (True, False, 1),   # beside a stream, interpreted derivatives: compiled ahead
    (True, True, 0),    # its derivatives compiled: no gcc for its outputs alone
    (False, False, 0),  # inline checks: nothing is compiled ahead
])
def test_a_shadow_is_compiled_ahead_only_for_its_derivatives(background, compiled, expected):
    pool = Pool(Shadow(compiled), background)
    solver, result = shadows.shadow_solve(pool, SNAP, choice=None)
    assert solver is pool.shadow and result.ok
    assert len(pool.compiled_ahead) == expected

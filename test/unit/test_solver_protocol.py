"""The Solver protocol (dlo_ros/solver/protocol.py): both solvers implement it with compatible signatures,
their model summaries are typed (ModelSummary) with the documented JSON keys, and nothing outside
dlo_ros/solver reaches into a solver's private attributes."""
from __future__ import annotations

import ast
import inspect
import re
from pathlib import Path

import pytest

import dlo_ros
from dlo_ros.solver import AutoShapeSolver, ModelSummary, ShapeSolver, Solver, SolverOptions, make_solver
from support.problems import clamped_pair

PACKAGE = Path(dlo_ros.__file__).resolve().parent
SOLVER_DIR = PACKAGE / "solver"


def protocol_members() -> dict[str, object]:
    """The protocol's methods, properties and data members by name."""
    members = {name: value for name, value in vars(Solver).items()
               if not name.startswith("_") and (callable(value) or isinstance(value, property))}
    members.update({name: None for name in Solver.__annotations__})
    return members


@pytest.fixture(scope="module")
def solvers():
    problem = clamped_pair(right=(0.6, 0.0, 0.2), weight=0.3)
    fixed = ShapeSolver(problem, SolverOptions(model="full", order=16), compile="off")
    auto = AutoShapeSolver(problem, SolverOptions(model="auto"), compile="off", checks="sync")
    yield {"ShapeSolver": fixed, "AutoShapeSolver": auto}
    auto.close()


@pytest.mark.parametrize("name", ["ShapeSolver", "AutoShapeSolver"])
def test_both_solvers_satisfy_the_protocol(solvers, name):
    solver = solvers[name]
    assert isinstance(solver, Solver)
    for member, spec in protocol_members().items():
        assert hasattr(solver, member), f"{name} has no {member}"
        if isinstance(spec, property):
            assert isinstance(inspect.getattr_static(type(solver), member), property), f"{name}.{member}: not a property"
        elif callable(spec):
            assert_compatible(inspect.signature(spec), inspect.signature(getattr(type(solver), member)), f"{name}.{member}")


def assert_compatible(wanted: inspect.Signature, have: inspect.Signature, where: str) -> None:
    """Every parameter of the protocol's method is accepted the same way (kind, default); the
    implementation's extra parameters are optional."""
    params = dict(have.parameters)
    for pname, p in wanted.parameters.items():
        assert pname in params, f"{where}: no parameter {pname!r}"
        q = params.pop(pname)
        assert q.kind == p.kind, f"{where}({pname}): {q.kind} instead of {p.kind}"
        assert q.default == p.default, f"{where}({pname}): default {q.default!r} instead of {p.default!r}"
    for pname, q in params.items():
        assert q.default is not inspect.Parameter.empty or q.kind in (q.VAR_POSITIONAL, q.VAR_KEYWORD), \
            f"{where}: extra parameter {pname!r} without a default"


def test_make_solver_returns_a_solver():
    problem = clamped_pair(right=(0.6, 0.0, 0.2))
    assert isinstance(make_solver(problem, SolverOptions(model="full", order=8), compile="off"), Solver)


FIXED_KEYS = ["planar", "twist", "stretch", "gravity", "order", "obstacles", "estimated_error_m", "variables",
              "rotation"]
AUTO_KEYS = ["planar", "twist", "stretch", "gravity", "order", "obstacles", "obstacle_samples", "estimated_error_m",
             "tolerance_m", "tolerance_met", "variables", "auto", "checked", "checked_updates_ago", "checks", "reasons", "changes", "changes_at", "rotation"]
DIRECTOR_KEYS = ["elements", "breakpoints"]


def test_model_summaries_are_typed_with_the_documented_keys(solvers):
    fixed, auto = solvers["ShapeSolver"], solvers["AutoShapeSolver"]
    r = fixed.solve()
    assert r.ok and isinstance(r.model, ModelSummary) and r.model == fixed.model_summary()
    assert list(r.model.as_dict()) == FIXED_KEYS + DIRECTOR_KEYS  # the default 3D rotation: directors
    assert r.to_dict()["model"] == r.model.as_dict()
    a = auto.solve()
    assert a.ok and isinstance(a.model, ModelSummary) and a.model.auto
    keys = AUTO_KEYS + (DIRECTOR_KEYS if a.model.elements is not None else []) + ["changed"]
    assert list(a.model.as_dict()) == keys
    with pytest.raises(AttributeError):
        r.model.order = 3  # frozen
    euler = ShapeSolver(clamped_pair(right=(0.6, 0.0, 0.2)), SolverOptions(model="full", rotation="euler", order=8),
                        compile="off")
    assert list(euler.model_summary().as_dict()) == FIXED_KEYS
    assert euler.model_summary().rotation == "euler"


# ---- nothing outside dlo_ros/solver touches a solver's private attributes ---------------------------------
def solver_private_names() -> set[str]:
    """Private attributes and methods of the classes in dlo_ros/solver (ShapeSolver, AutoShapeSolver
    and the parts they delegate to), read from their sources."""
    names = set()
    for path in SOLVER_DIR.rglob("*.py"):
        tree = ast.parse(path.read_text(encoding="utf-8"))
        for body in (n for n in ast.walk(tree) if isinstance(n, ast.ClassDef)):
            for node in ast.walk(body):
                if isinstance(node, ast.FunctionDef) and node.name.startswith("_") and not node.name.startswith("__"):
                    names.add(node.name)
                if isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name) and node.value.id == "self" \
                        and node.attr.startswith("_") and not node.attr.startswith("__"):
                    names.add(node.attr)
    return names


def outside_modules() -> list[Path]:
    return [p for p in PACKAGE.rglob("*.py") if SOLVER_DIR not in p.parents]


def private_accesses(source: str, label: str, solver_only: set[str]) -> list[str]:
    """``x._name`` (and getattr/setattr/hasattr(x, '_name')) in ``source`` where x is a solver: its text
    names a solver (``solver``, ``inner``), or ``_name`` is private to the solver classes (defined by no
    class outside dlo_ros/solver) and x is not ``self`` or ``cls``."""
    found = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Attribute):
            receiver, name = node.value, node.attr
        elif isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and \
                node.func.id in ("getattr", "setattr", "hasattr") and len(node.args) >= 2 and \
                isinstance(node.args[1], ast.Constant) and isinstance(node.args[1].value, str):
            receiver, name = node.args[0], node.args[1].value
        else:
            continue
        if not name.startswith("_") or name.startswith("__"):
            continue
        text = ast.unparse(receiver)
        if text in ("self", "cls"):
            continue
        if re.search(r"solver|\binner\b", text, re.IGNORECASE) or name in solver_only:
            found.append((node.lineno, f"{label}:{node.lineno}: {text}.{name}"))
    return [hit for _, hit in sorted(found)]


def test_no_private_solver_attribute_is_used_outside_the_solver_package():
    names = solver_private_names()
    assert {"_state", "_lock", "_pool"} <= names  # the scan sees the classes' private state
    defined_elsewhere = set()
    for path in outside_modules():
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name) and node.value.id == "self":
                defined_elsewhere.add(node.attr)
            elif isinstance(node, ast.FunctionDef):
                defined_elsewhere.add(node.name)
    found = [hit for path in outside_modules()
             for hit in private_accesses(path.read_text(encoding="utf-8"), str(path.relative_to(PACKAGE.parent)),
                                         names - defined_elsewhere)]
    assert not found, "private solver attributes used outside dlo_ros/solver:\n" + "\n".join(found)


def test_the_private_access_scan_finds_an_access():
    """The scan is not vacuous: it flags the patterns it is meant to, and not a class's own state."""
    sample = ("def f(engine, solver, s, recorder):\n    a = engine._solver._state\n    b = solver._lock\n"
              "    c = getattr(solver, '_pool')\n    d = s._min_reduced_eigenvalue\n    e = recorder._lock\n"
              "    return a, b, c, d, e\n\nclass Engine:\n    def g(self):\n        return self._solver\n")
    found = [hit.split(": ", 1)[1] for hit in private_accesses(sample, "sample", {"_min_reduced_eigenvalue"})]
    assert found == ["engine._solver._state", "solver._lock", "solver._pool", "s._min_reduced_eigenvalue"], found

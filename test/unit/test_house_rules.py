"""Check the structure rules of dlo_ros/ (CONTRIBUTING.md, "Structure").

- no module over 500 lines and no function over 80 lines, unless a ``# size: <reason>`` comment
  stands in the module's first 40 lines (module) or on the lines just above the ``def`` (function);
- no import circle between the package's modules (TYPE_CHECKING imports aside);
- no ``_private`` name imported from another module;
- a function-local import says why it is not at the top, in a comment on its line or the three
  lines above that names the reason: an ``optional`` dependency, a measured ``start-up`` cost, or
  a process that must not import something (``not at the top: ...``).

The graph is built from the source with ``ast``, as ``../shared/tools/house_check.py`` does.
"""

from __future__ import annotations

import ast
import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
PKG = ROOT / "dlo_ros"
MODULE_LINES = 500
FUNCTION_LINES = 80
SIZE_NOTE = re.compile(r"#\s*size:\s*\S")
LAZY_NOTE = re.compile(r"#.*\b(optional|start-up|not at the top)\b")


def _modules() -> dict[str, Path]:
    out = {}
    for p in sorted(PKG.rglob("*.py")):
        name = ".".join(p.relative_to(ROOT).with_suffix("").parts)
        out[name.removesuffix(".__init__")] = p
    return out


MODULES = _modules()


def _targets(module: str, node: ast.Import | ast.ImportFrom) -> tuple[str, list[str]]:
    """Return the imported module and the dlo_ros modules this import depends on."""
    if isinstance(node, ast.Import):
        return "", [a.name for a in node.names]
    if node.level:
        base = module.split(".")
        pkg = base if MODULES[module].name == "__init__.py" else base[:-1]
        pkg = pkg[: len(pkg) - (node.level - 1)]
        stem = ".".join(pkg + ([node.module] if node.module else []))
    else:
        stem = node.module or ""
    subs = [f"{stem}.{a.name}" for a in node.names if f"{stem}.{a.name}" in MODULES]
    return stem, subs if len(subs) == len(node.names) else [stem, *subs]


def _type_checking_nodes(tree: ast.AST) -> set[int]:
    out: set[int] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.If) and "TYPE_CHECKING" in ast.unparse(node.test):
            out.update(id(sub) for sub in ast.walk(node))
    return out


def _parsed() -> dict[str, tuple[list[str], ast.Module]]:
    return {m: ((t := p.read_text(encoding="utf-8")).splitlines(), ast.parse(t)) for m, p in MODULES.items()}


PARSED = _parsed()


def test_module_and_function_sizes() -> None:
    too_big = []
    for module, (lines, tree) in PARSED.items():
        rel = MODULES[module].relative_to(ROOT)
        if len(lines) > MODULE_LINES and not any(SIZE_NOTE.search(x) for x in lines[:40]):
            too_big.append(f"{rel}: {len(lines)} lines")
        for node in ast.walk(tree):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                first = min([node.lineno] + [d.lineno for d in node.decorator_list])
                n = node.end_lineno - node.lineno + 1
                above = lines[max(0, first - 4) : first - 1]
                if n > FUNCTION_LINES and not any(SIZE_NOTE.search(x) for x in above):
                    too_big.append(f"{rel}:{node.lineno} {node.name}: {n} lines")
    assert not too_big, "over the size rule without a '# size:' reason:\n" + "\n".join(too_big)


def _graph() -> dict[str, set[str]]:
    graph: dict[str, set[str]] = {m: set() for m in MODULES}
    for module, (_, tree) in PARSED.items():
        skip = _type_checking_nodes(tree)
        for node in ast.walk(tree):
            if isinstance(node, (ast.Import, ast.ImportFrom)) and id(node) not in skip:
                graph[module].update(t for t in _targets(module, node)[1] if t in MODULES and t != module)
    return graph


def _cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Return the strongly connected components with more than one module (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    out: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in sorted(graph[v]):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return out


def test_no_import_circles() -> None:
    cycles = _cycles(_graph())
    assert not cycles, "import circles:\n" + "\n".join(" <-> ".join(c) for c in cycles)


def test_no_private_names_across_modules() -> None:
    found = []
    for module, (_, tree) in PARSED.items():
        for node in ast.walk(tree):
            if not isinstance(node, ast.ImportFrom):
                continue
            stem, _ = _targets(module, node)
            if stem not in MODULES or stem == module:
                continue
            for alias in node.names:
                private = alias.name.startswith("_") and not alias.name.startswith("__")
                if private and f"{stem}.{alias.name}" not in MODULES:
                    found.append(f"{MODULES[module].relative_to(ROOT)}: {alias.name} from {stem}")
    assert not found, "private names imported across modules:\n" + "\n".join(found)


def test_function_local_imports_say_why() -> None:
    found = []
    for module, (lines, tree) in PARSED.items():
        for fn in ast.walk(tree):
            if not isinstance(fn, (ast.FunctionDef, ast.AsyncFunctionDef)):
                continue
            for node in ast.walk(fn):
                if isinstance(node, (ast.Import, ast.ImportFrom)):
                    near = lines[max(0, node.lineno - 4) : node.end_lineno]
                    if not any(LAZY_NOTE.search(x) for x in near):
                        found.append(f"{MODULES[module].relative_to(ROOT)}:{node.lineno}")
    found = sorted(set(found))
    assert not found, (
        "function-local imports that do not say why they are not at the top:\n" + "\n".join(found)
    )

"""The Python package's layout rules, read from its source (no import needed).

- No private name (``_x``) of one module is imported or used by another (the compiled
  ``_core`` excepted: it is the package's private binding).
- Module-level imports between the package's modules form no cycle.
- The modules of ``popup.diagnosis`` and ``popup.setmembership`` import only those before
  them in their package's documented order.
"""

from __future__ import annotations

import ast
import pathlib
from typing import Dict, List, Set, Tuple

import pytest

ROOT = pathlib.Path(__file__).resolve().parents[1] / "python" / "popup"
ORDERS = {
    "diagnosis": ["rules", "results", "evidence", "candidate", "conclusion", "rank", "loop", "cli"],
    "setmembership": ["structure", "data", "regression", "result", "lp", "linear", "oe_model"],
}


def _modules() -> Dict[str, pathlib.Path]:
    out = {}
    for p in ROOT.rglob("*.py"):
        parts = p.relative_to(ROOT.parent).with_suffix("").parts
        name = ".".join(parts[:-1] if parts[-1] == "__init__" else parts)
        out[name] = p
    return out


MODULES = _modules()


def _target(name: str, is_pkg: bool, level: int, module: str) -> str:
    base = name.split(".") if is_pkg else name.split(".")[:-1]
    base = base[: len(base) - (level - 1)]
    return ".".join(base + ([module] if module else []))


def _private(name: str) -> bool:
    return name.startswith("_") and not name.startswith("__") and name != "_core"


def _scan(name: str) -> Tuple[Set[str], List[str]]:
    """Module-level dependencies on the package's modules, and private names of other
    modules that ``name`` imports or uses."""
    p = MODULES[name]
    tree = ast.parse(p.read_text(encoding="utf-8"))
    is_pkg = p.name == "__init__.py"
    deps: Set[str] = set()
    aliases: Dict[str, str] = {}
    bad: List[str] = []
    top = set(map(id, tree.body))
    for n in ast.walk(tree):
        if isinstance(n, ast.ImportFrom) and n.level:
            tgt = _target(name, is_pkg, n.level, n.module or "")
            for a in n.names:
                full = f"{tgt}.{a.name}"
                if full in MODULES:
                    aliases[a.asname or a.name] = full
                    if id(n) in top:
                        deps.add(full)
                else:
                    if _private(a.name):
                        bad.append(f"{name} imports {tgt}.{a.name}")
                    if id(n) in top and a.name != "_core":
                        deps.add(tgt)
    for n in ast.walk(tree):
        if isinstance(n, ast.Attribute) and isinstance(n.value, ast.Name) and n.value.id in aliases and _private(n.attr):
            bad.append(f"{name} uses {aliases[n.value.id]}.{n.attr}")
    return {d for d in deps if d in MODULES and d != name}, bad


def test_the_scan_sees_the_package():
    assert "popup.model" in MODULES and "popup.diagnosis.loop" in MODULES
    deps, _ = _scan("popup.diagnosis.loop")
    assert {"popup.diagnosis.rank", "popup.problem"} <= deps


def test_no_module_reaches_into_another_modules_private_names():
    bad = [b for name in sorted(MODULES) for b in _scan(name)[1]]
    assert not bad, "\n".join(bad)


def test_module_level_imports_form_no_cycle():
    graph = {name: _scan(name)[0] for name in MODULES}
    state: Dict[str, int] = {}
    cycles: List[List[str]] = []

    def visit(u: str, stack: List[str]) -> None:
        state[u] = 1
        stack.append(u)
        for v in sorted(graph[u]):
            if state.get(v) == 1:
                cycles.append(stack[stack.index(v):] + [v])
            elif not state.get(v):
                visit(v, stack)
        stack.pop()
        state[u] = 2

    for u in sorted(graph):
        if not state.get(u):
            visit(u, [])
    assert not cycles, cycles


@pytest.mark.parametrize("pkg, mod", [(p, m) for p, ms in ORDERS.items() for m in ms])
def test_each_package_module_imports_only_those_before_it(pkg, mod):
    order = ORDERS[pkg]
    deps, _ = _scan(f"popup.{pkg}.{mod}")
    siblings = {d.rsplit(".", 1)[1] for d in deps if d.startswith(f"popup.{pkg}.")}
    later = [s for s in siblings if order.index(s) >= order.index(mod)]
    assert not later, f"popup.{pkg}.{mod} imports {later}, which come after it"
    assert set(order) | {"__init__"} == {p.stem for p in (ROOT / pkg).glob("*.py")}

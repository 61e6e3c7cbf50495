"""The import structure: no circles between modules, and no import up the layers.

Every ``import`` statement of ``gonio`` and ``drivers`` counts, those inside functions
too (an import deferred to keep start-up light is still a dependency). Layers, lowest
first: ``drivers`` (no gonio at all), the models (``gonio.models``), the fitting
(``gonio.fitting``), the reduction (``gonio.reduction``, which makes the fitting's
datasets), the report (``gonio.report``), the command line (``gonio.cli``); protocols and
acquisition sit below the command line. A module may import its own layer and those below.
"""
from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
#: Packages and the packages they must not import.
FORBIDDEN = {
    "drivers": ("gonio",),
    "gonio.models": ("gonio.fitting", "gonio.reduction", "gonio.acquisition", "gonio.protocols", "gonio.report",
                     "gonio.cli"),
    "gonio.fitting": ("gonio.reduction", "gonio.acquisition", "gonio.report", "gonio.cli", "gonio.adaptive"),
    "gonio.reduction": ("gonio.report", "gonio.cli", "gonio.adaptive"),
    "gonio.report": ("gonio.cli",),
    "gonio.protocols": ("gonio.cli", "gonio.acquisition", "gonio.design", "gonio.adaptive"),
    "gonio.acquisition": ("gonio.cli", "gonio.design", "gonio.adaptive"),
    "gonio.design": ("gonio.cli", "gonio.acquisition", "gonio.adaptive"),
    "gonio.adaptive": ("gonio.cli",),
    "gonio.vision": ("gonio.cli", "gonio.fitting", "gonio.report", "gonio.acquisition"),
    "gonio.export": ("gonio.cli", "gonio.report", "gonio.acquisition"),
}


def _modules() -> dict[str, Path]:
    out = {}
    for package in ("gonio", "drivers"):
        for path in (ROOT / package).rglob("*.py"):
            parts = path.relative_to(ROOT).with_suffix("").parts
            out[".".join(parts[:-1] if parts[-1] == "__init__" else parts)] = path
    return out


def _imports(name: str, path: Path, modules: dict[str, Path]) -> set[str]:
    """The modules of ``modules`` that ``name`` imports, anywhere in its source."""
    found = set()
    package = name.split(".") if path.name == "__init__.py" else name.split(".")[:-1]
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom):
            base = package[: len(package) - node.level + 1] if node.level else []
            target = ".".join(base + ([node.module] if node.module else []))
            candidates = [target] + [f"{target}.{alias.name}" for alias in node.names]
        elif isinstance(node, ast.Import):
            candidates = [alias.name for alias in node.names]
        else:
            continue
        found.update(c for c in candidates if c in modules and c != name and not name.startswith(c + "."))
    return found


def _graph() -> dict[str, set[str]]:
    modules = _modules()
    return {name: _imports(name, path, modules) for name, path in modules.items()}


def _circles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    circles: list[list[str]] = []

    def visit(node: str) -> None:
        index[node] = low[node] = len(index)
        stack.append(node)
        on_stack.add(node)
        for other in graph[node]:
            if other not in index:
                visit(other)
                low[node] = min(low[node], low[other])
            elif other in on_stack:
                low[node] = min(low[node], index[other])
        if low[node] == index[node]:
            component = []
            while True:
                member = stack.pop()
                on_stack.discard(member)
                component.append(member)
                if member == node:
                    break
            if len(component) > 1:
                circles.append(sorted(component))

    for node in graph:
        if node not in index:
            visit(node)
    return circles


def _within(name: str, package: str) -> bool:
    return name == package or name.startswith(package + ".")


def test_no_import_circles():
    assert _circles(_graph()) == []


def test_no_import_up_the_layers():
    offences = [(name, target) for name, targets in _graph().items() for target in sorted(targets)
                for package, above in FORBIDDEN.items() if _within(name, package)
                for higher in above if _within(target, higher)]
    assert offences == []


def test_the_check_finds_a_circle():
    assert _circles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]

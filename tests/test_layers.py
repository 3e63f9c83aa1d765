"""The package's layers: no module imports a later layer, and no import circles.

Every ``import``/``from ... import`` of a ``stickslip`` module counts, at any depth
(imports inside functions too). Run ``python -m pytest tests/test_layers.py -q``.
"""

from __future__ import annotations

import ast
from pathlib import Path

SRC = Path(__file__).resolve().parents[1] / "src" / "stickslip"
# the pipeline, in order: a module may import only its own layer and earlier ones
LAYERS = ("_version", "units", "robust", "compiled", "conditions", "atomic", "traces", "simulators",
          "estimators", "diagnostics", "jobs", "api", "cli")  # fmt: skip


def _module(path: Path) -> str:
    parts = path.relative_to(SRC.parent).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _imports(path: Path) -> set[str]:
    """Every stickslip module the file imports (a name imported from a package counts as
    its submodule where one exists)."""
    out: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            out |= {a.name for a in node.names if a.name.startswith("stickslip")}
        elif isinstance(node, ast.ImportFrom) and (node.module or "").startswith("stickslip"):
            for a in node.names:
                sub = f"{node.module}.{a.name}"
                has_sub = (SRC.parent / Path(*sub.split("."))).with_suffix(".py").exists() or (
                    SRC.parent / Path(*sub.split(".")) / "__init__.py").exists()
                out.add(sub if has_sub else node.module)
    return out


def _graph() -> dict[str, set[str]]:
    return {_module(p): _imports(p) for p in SRC.rglob("*.py")}


def _layer(module: str) -> int:
    parts = module.split(".")
    return LAYERS.index(parts[1]) if len(parts) > 1 else len(LAYERS)


def test_no_module_imports_a_later_layer():
    bad = [f"{m} -> {d}" for m, deps in _graph().items() if m != "stickslip"
           for d in deps if _layer(d) > _layer(m)]  # fmt: skip
    assert not bad, "imports against the pipeline:\n" + "\n".join(sorted(bad))


def test_no_import_circles():
    graph = _graph()
    # a package's __init__ re-exporting its own submodules is the package's face, not a
    # circle, as long as no submodule imports the package back
    edges = {m: {d for d in deps if d in graph and d != m} for m, deps in graph.items()}
    state: dict[str, int] = {}
    cycles: list[list[str]] = []

    def visit(m: str, stack: list[str]) -> None:
        state[m] = 1
        for d in sorted(edges[m]):
            if state.get(d) == 1:
                cycles.append(stack[stack.index(d):] + [d])
            elif d not in state:
                visit(d, stack + [d])
        state[m] = 2

    for m in sorted(edges):
        if m not in state:
            visit(m, [m])
    assert not cycles, "import circles:\n" + "\n".join(" -> ".join(c) for c in cycles)

"""The package layering of docs/ARCHITECTURE.md, enforced on every import in the tree.

Layers (each may import itself and the layers below it, never the layers above):

- foundation: hofto_hw.errors, hofto_hw.outputs, hofto_hw.jit, hofto_hw.config,
  hofto_hw.model, hofto_hw.observers, hofto_hw.control;
- drivers/ and safety/: the foundation only (and themselves; never each other);
- application: everything else under hofto_hw (runtime, commands, cli, replay, experiments,
  identify, recording): anything.

Every ``import`` and ``from ... import`` statement is checked, at module level or inside a
function or an ``if TYPE_CHECKING:`` block, relative imports resolved. A module that belongs to
no layer fails the test too, so a new package has to be placed on the map.

Why an AST walk rather than import-linter: it needs no extra dependency, reads exactly the
statements the rule is about (function-level imports included), and its failure names the
file, the line and the forbidden edge.
"""

from __future__ import annotations

import ast
import functools
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("hofto_hw", "drivers", "safety")

FOUNDATION = (
    "hofto_hw.errors",
    "hofto_hw.outputs",
    "hofto_hw.jit",
    "hofto_hw.config",
    "hofto_hw.model",
    "hofto_hw.observers",
    "hofto_hw.control",
)
APPLICATION = (
    "hofto_hw.runtime",
    "hofto_hw.commands",
    "hofto_hw.cli",
    "hofto_hw.replay",
    "hofto_hw.experiments",
    "hofto_hw.identify",
    "hofto_hw.recording",
    "hofto_hw.progress",
    "hofto_hw.control_plane",
    "hofto_hw.client",
)
#: layer -> layers it may import (besides third-party and standard-library modules)
ALLOWED: dict[str, set[str]] = {
    "foundation": {"foundation"},
    "drivers": {"drivers", "foundation"},
    "safety": {"safety", "foundation"},
    "application": {"application", "drivers", "safety", "foundation"},
}


def _within(name: str, prefix: str) -> bool:
    return name == prefix or name.startswith(prefix + ".")


def layer_of(module: str) -> str | None:
    """The layer of a module of this project; None for a module outside it (or unplaced)."""
    if _within(module, "drivers"):
        return "drivers"
    if _within(module, "safety"):
        return "safety"
    if any(_within(module, p) for p in FOUNDATION):
        return "foundation"
    if any(_within(module, p) for p in APPLICATION):
        return "application"
    return None


def _module_name(path: Path) -> str:
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


@functools.cache
def _project_modules() -> dict[str, Path]:
    """Module name -> file of every module under hofto_hw/, drivers/ and safety/."""
    out = {}
    for pkg in PACKAGES:
        for path in sorted((ROOT / pkg).rglob("*.py")):
            out[_module_name(path)] = path
    return out


def imported_modules(tree: ast.AST, module: str, is_package: bool) -> list[tuple[int, str]]:
    """(line, absolute module name) of every import statement anywhere in ``tree``.

    ``from X import y`` yields ``X`` when X is a module file (y is a name in it), else ``X.y``
    (X is a package, y may be one of its modules).
    """
    modules = _project_modules()
    package = module if is_package else module.rpartition(".")[0]
    out: list[tuple[int, str]] = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            out += [(node.lineno, a.name) for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                parts = package.split(".")
                parts = parts[: len(parts) - (node.level - 1)]
                base = ".".join([*parts, *([node.module] if node.module else [])])
            is_file = base in modules and modules[base].name != "__init__.py"
            out += [(node.lineno, base if is_file else f"{base}.{a.name}") for a in node.names]
    return sorted(out)


def forbidden_edges() -> list[str]:
    """``FILE:LINE: importer (layer) imports imported (layer)`` for every forbidden import."""
    problems = []
    for module, path in _project_modules().items():
        if module in PACKAGES:  # the top-level __init__ files
            continue
        src = layer_of(module)
        rel = path.relative_to(ROOT)
        if src is None:
            problems.append(f"{rel}: {module} is in no layer (add it to tests/test_layers.py)")
            continue
        tree = ast.parse(path.read_text(), filename=str(rel))
        for line, target in imported_modules(tree, module, path.name == "__init__.py"):
            if target.split(".")[0] not in PACKAGES or target == "hofto_hw":
                continue  # standard library, third party, or the empty top-level package
            dst = layer_of(target)
            if dst is None:
                problems.append(f"{rel}:{line}: {module} imports {target}, which is in no layer")
            elif dst not in ALLOWED[src]:
                problems.append(f"{rel}:{line}: {module} ({src}) imports {target} ({dst})")
    return problems


def test_no_import_goes_up_a_layer() -> None:
    problems = forbidden_edges()
    assert not problems, "imports against the layering of docs/ARCHITECTURE.md:\n" + "\n".join(
        problems
    )


def test_the_checker_resolves_relative_and_function_level_imports() -> None:
    tree = ast.parse(
        "from ..cia402 import pdo\n"
        "from . import plant\n"
        "from .plant import Plant\n"
        "def f():\n"
        "    import safety.collision\n"
        "    from hofto_hw.config.models import SystemConfig\n"
        "    from hofto_hw import runtime\n"
    )
    found = imported_modules(tree, "drivers.sim.simbus", is_package=False)
    assert found == [
        (1, "drivers.cia402.pdo"),
        (2, "drivers.sim.plant"),
        (3, "drivers.sim.plant"),
        (5, "safety.collision"),
        (6, "hofto_hw.config.models"),
        (7, "hofto_hw.runtime"),
    ]
    assert [layer_of(m) for _, m in found] == [
        "drivers",
        "drivers",
        "drivers",
        "safety",
        "foundation",
        "application",
    ]

"""The packages depend one way: agent → drivers / ident → virtual_cnc → gcode_gen → core.

Read from the source (every ``import``, also inside functions), so a lazy import that
points the wrong way fails here too.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

#: package -> the project packages it may import (besides itself)
ALLOWED = {
    "core": set(),
    "gcode_gen": {"core"},
    "virtual_cnc": {"core", "gcode_gen"},
    "ident": {"core", "gcode_gen"},
    "drivers": {"core", "gcode_gen", "virtual_cnc"},
    "agent": {"core", "gcode_gen", "virtual_cnc", "ident", "drivers"},
}


def _imports(path: Path) -> set[str]:
    tree = ast.parse(path.read_text(), filename=str(path))
    names = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names |= {alias.name.split(".")[0] for alias in node.names}
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            names.add(node.module.split(".")[0])
    return names & set(ALLOWED)


@pytest.mark.parametrize("package", sorted(ALLOWED))
def test_a_package_imports_only_the_layers_below_it(package):
    wrong = {}
    for path in sorted((ROOT / package).rglob("*.py")):
        bad = _imports(path) - ALLOWED[package] - {package}
        if bad:
            wrong[str(path.relative_to(ROOT))] = sorted(bad)
    assert wrong == {}

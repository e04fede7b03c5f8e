"""Each repeated piece issue 42 names lives in one place (read from the source, so that a copy that
grows back is seen): the increment's start and the lifted right-hand side
(``solvers/prediction.py``), the method, law and obstacle names (``names.py``, ``contact/obstacles.py``)."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

import dolfinx_nnqem

PACKAGE = Path(dolfinx_nnqem.__file__).resolve().parent


def _modules_calling(method: str) -> list[str]:
    """The package's modules (relative paths) with a call ``<anything>.method(...)``."""
    found = []
    for path in sorted(PACKAGE.rglob("*.py")):
        tree = ast.parse(path.read_text(encoding="utf-8"))
        if any(isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute) and node.func.attr == method
               for node in ast.walk(tree)):
            found.append(path.relative_to(PACKAGE).as_posix())
    return found


@pytest.mark.parametrize("method", ["predict_contact", "tangent_action"])
def test_the_increment_start_is_written_once(method):
    assert _modules_calling(method) == ["solvers/prediction.py"]


def _string_tuples_with(name: str) -> list[str]:
    """Modules whose source holds a literal list/tuple/set of strings containing ``name`` and
    at least one other string: a list of names written out."""
    found = []
    for path in sorted(PACKAGE.rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, (ast.List, ast.Tuple, ast.Set)) and len(node.elts) > 1 and all(
                    isinstance(e, ast.Constant) and isinstance(e.value, str) for e in node.elts) and any(
                    e.value == name for e in node.elts):  # type: ignore[attr-defined]
                found.append(path.relative_to(PACKAGE).as_posix())
                break
    return found


@pytest.mark.parametrize("name", ["nneqm2", "alart-curnier"])
def test_the_method_and_law_names_are_listed_once(name):
    assert _string_tuples_with(name) == ["names.py"]

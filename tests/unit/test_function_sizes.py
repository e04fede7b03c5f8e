"""The house's size limits (issue 42, ``CONTRIBUTING.md``): a function at most 80 lines, a class at
most 400, from its ``def``/``class`` line to its last line (docstring included).

Checked for the modules already split to them; a module joins :data:`SPLIT_MODULES` once its
largest function and class fit, so that none of them grows back.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

import dolfinx_nnqem

PACKAGE = Path(dolfinx_nnqem.__file__).resolve().parent
SPLIT_MODULES = ("numerics/newton.py", "io/run_pictures.py", "problem/meshing.py", "problem/gmsh_tools.py",
                 *(f"cases/geometries/{name}.py" for name in ("two_beams", "stacked_blocks", "block_stack",
                                                              "thick_cylinder", "graded_blocks", "sphere_on_block")),
                 *(f"material/finite_strain/{name}.py" for name in ("__init__", "hencky", "interface", "neo_hooke",
                                                                    "spectral", "gauss_state", "kernels")),
                 *(f"problem/{name}.py" for name in ("contact_problem", "assembly", "interfaces", "loads", "predictor",
                                                     "supports", "parameter_study")),
                 "contact/laws.py", "contact/model.py", "contact/constrained_directions.py", "material/state.py",
                 "material/gauss_fields.py", "problem/kinematics_choice.py", "problem/deformed_mesh.py",
                 "solvers/finite_strain_check.py",
                 "material/state_report.py", "solvers/prediction.py", "solvers/monolithic.py",
                 "solvers/surface_tangent.py", "contact/surface_stiffness.py", "solvers/nodal_flexibility.py",
                 "solvers/nneqm1.py")
MAX_FUNCTION_LINES = 80
MAX_CLASS_LINES = 400


def _oversized(path: Path) -> list[str]:
    """The functions and classes of ``path`` over their limit, as ``name: lines``."""
    found = []
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            limit = MAX_FUNCTION_LINES
        elif isinstance(node, ast.ClassDef):
            limit = MAX_CLASS_LINES
        else:
            continue
        assert node.end_lineno is not None  # (ast.parse sets it)
        lines = node.end_lineno - node.lineno + 1
        if lines > limit:
            found.append(f"{node.name} (line {node.lineno}): {lines} lines, limit {limit}")
    return found


@pytest.mark.parametrize("module", SPLIT_MODULES)
def test_functions_and_classes_keep_to_their_size_limits(module: str) -> None:
    assert _oversized(PACKAGE / module) == []

"""MPI helper of tests/integration/test_deformed_outputs.py: the output folder of a finite-strain
run with a rigid obstacle, on any number of ranks.

    mpiexec -n N python deformed_outputs.py OUT_FOLDER [small]

A rigid sphere pressed 0.05 into an elastoplastic block in 2 increments (``kinematics = "finite"``,
the contact in the current geometry; ``small``: pressed 0.02 at small strain with ``deformed_mesh=True``),
written by a :class:`~dolfinx_nnqem.io.output.ResultsWriter` into OUT_FOLDER (no pictures).
"""

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))  # this checkout's package, not an installed one
sys.path.insert(0, str(Path(__file__).resolve().parent))

import dolfinx_nnqem  # noqa: F401, E402  (first: the PyPI wheel loads MPI/PETSc before dolfinx)
from finite_strain import sphere_into_block  # noqa: E402

from dolfinx_nnqem.io.output import ResultsWriter  # noqa: E402
from dolfinx_nnqem.solvers import SolverOptions, make_solver, solve_load_steps  # noqa: E402

INCREMENTS = 2


def write_run(folder: str | Path, kinematics: str = "finite", deformed_mesh: bool | None = None,
              depth: float = 0.05):
    """Solve the sphere pressed ``depth`` into the block and write its outputs into ``folder``
    (collective); returns the problem, solved."""
    problem = sphere_into_block(kinematics=kinematics, depth=depth)
    with ResultsWriter(problem, "monolithic", folder, INCREMENTS, pictures=False, deformed_mesh=deformed_mesh) as writer:
        with make_solver("monolithic", problem, SolverOptions(rtol=1e-10)) as solver:
            solve_load_steps(problem, solver, INCREMENTS, callbacks=[writer])
    return problem


if __name__ == "__main__":
    small = len(sys.argv) > 2 and sys.argv[2] == "small"
    write_run(sys.argv[1], "small" if small else "finite", True if small else None, 0.02 if small else 0.05)

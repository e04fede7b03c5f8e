"""The Voce return map through ``dolfinx-external-operator`` against the package's quadrature part.

Both routes evaluate the same numpy return map (``material.isotropic.isotropic_return``) at the
Gauss points of the pressed blocks (Voce, both blocks) and assemble F_int and K_t from quadrature
functions; this prints the median time of one iterate (evaluation + both assemblies) of each, in
one process. Needs ``pip install dolfinx-external-operator`` (PyPI: 0.10 and 0.11 only, i.e.
DOLFINx ≥ 0.10; nothing for Debian 13's DOLFINx 0.9). Asserts nothing::

    python benchmarks/external_operator_cost.py --cells 6
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

import dolfinx_nnqem  # noqa: F401  (first: the PyPI wheel loads MPI/PETSc before dolfinx)
import dolfinx.fem.petsc
import numpy as np
import ufl

sys.path.insert(0, str(Path(__file__).resolve().parent))

from material_cost import MATERIALS, assembly_time, blocks  # noqa: E402

from dolfinx_nnqem import jit  # noqa: E402
from dolfinx_nnqem.material.isotropic import isotropic_return  # noqa: E402
from dolfinx_nnqem.material.kinematics import strain  # noqa: E402
from dolfinx_nnqem.problem.contact_problem import assemble_vector  # noqa: E402


def external_operator_route(problem, repeat: int) -> float:
    """The same F_int and K_t, σ and dσ/dΔε as a FEMExternalOperator of Δε (median seconds per iterate)."""
    from dolfinx_external_operator import (FEMExternalOperator, evaluate_external_operators, evaluate_operands,
                                           replace_external_operators)

    st = problem.state
    part = st.parts[0]
    pts = part.points
    v, du = ufl.TestFunction(problem.V), ufl.TrialFunction(problem.V)
    deps = strain(problem.u) - strain(st.u_n)
    sigma = FEMExternalOperator(deps, function_space=st.W_tensor)
    cache = {}

    def return_map(deps_values):
        key = deps_values.tobytes()
        if key not in cache:  # σ and C_alg come from one evaluation, asked for separately
            cache.clear()
            d = deps_values.reshape(-1, 3, 3)[pts]
            cache[key] = isotropic_return(st.sigma_n.x.array.reshape(-1, 3, 3)[pts], d, st.p_n.x.array[pts],
                                          part.mu[pts], part.lmbda[pts], part.hardening.subset(pts))
        return cache[key]

    def external(derivatives):
        if derivatives == (0,):
            return lambda d: return_map(d)[0].reshape(-1)
        if derivatives == (1,):
            return lambda d: return_map(d)[3].reshape(-1)
        raise NotImplementedError(derivatives)

    sigma.external_function = external
    F = ufl.inner(sigma, strain(v)) * st.dx
    J = ufl.algorithms.expand_derivatives(ufl.derivative(F, problem.u, du))
    F_replaced, F_ops = replace_external_operators(F)
    J_replaced, J_ops = replace_external_operators(J)
    F_form, J_form = jit.form(F_replaced), jit.form(J_replaced)
    rng = np.random.default_rng(0)
    u0 = problem.u.x.array.copy()
    A = dolfinx.fem.petsc.assemble_matrix(J_form)
    times = []
    for _ in range(repeat):
        problem.u.x.array[:] = u0 * (1.0 + 1e-3 * rng.standard_normal())
        t0 = time.perf_counter()
        operands = evaluate_operands(F_ops)
        evaluate_external_operators(F_ops, operands)
        evaluate_external_operators(J_ops, operands)
        b = assemble_vector(F_form, problem.V)
        A.zeroEntries()
        dolfinx.fem.petsc.assemble_matrix(A, J_form, bcs=problem.bcs)
        A.assemble()
        times.append(time.perf_counter() - t0)
        b.destroy()
    problem.u.x.array[:] = u0
    return statistics.median(times)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cells", type=int, default=6)
    parser.add_argument("--repeat", type=int, default=15)
    args = parser.parse_args(argv)
    from dolfinx_nnqem.solvers import SolverOptions, make_solver, solve_load_steps

    problem = blocks(MATERIALS["von-mises voce"], args.cells)
    with make_solver("monolithic", problem, SolverOptions(rtol=1e-10)) as solver:
        solve_load_steps(problem, solver, 5)  # a plastic converged state to evaluate near
    ours = assembly_time(problem, args.repeat)
    theirs = external_operator_route(problem, args.repeat)
    print(f"pressed blocks (Voce), {args.cells} cells per edge, {problem.state.num_gauss_points()} Gauss points")
    print(f"quadrature part (this package):  {1e3 * ours:8.2f} ms per iterate (F_int + K_t, evaluation included)")
    print(f"dolfinx-external-operator:       {1e3 * theirs:8.2f} ms per iterate ({theirs / ours:.2f} x)")
    return 0


if __name__ == "__main__":
    sys.exit(main())

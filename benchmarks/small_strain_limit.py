"""Small strain as the limit of finite strain (issue 41): the finite-strain verification cases at a
fraction (1e-4) of their loads, each solved with ``kinematics = "finite"`` and ``"small"``, and how far
the two answers are apart.

Issue 41 asks that "at loads 1e-4 of the above, finite and small strain agree to 1e-4". The cases, each
the same mesh, material, contact and solver at both kinematics (the load scaled by ``--scale``):

* ``stretch``: a unit cube (2 × 2 × 2 hexahedra) on rollers at x = 0, y = 0, z = 0, its top moved
  up by 1 at the full load (the uniaxial stretch to 100 %); von Mises, E = 200 GPa, σ_y0 = 200 MPa;
* ``shear``: the same cube clamped at the bottom, its top moved sideways by 1 (a shear of 1); a
  Neo-Hookean cube at finite strain against linear elasticity with the same E, ν at small strain;
* ``necking``: the necking bar of ``benchmarks/necking_bar.py`` (coarse mesh, P2 tetrahedra, Voce
  hardening), its end pulled 7 mm at the full load;
* ``sphere``: the deep sphere press of ``benchmarks/calculix_deep_sphere_press.py`` (h = 1/4), the
  sphere 0.2 R down at the full load, contact in the current geometry at both kinematics;
* ``ironing``: the deep ironing of ``demos/deep_ironing.py`` (nx = 8), the punch's depth scaled,
  its full slide along the strip kept (a large sliding of a tiny indentation).

The figures: the largest difference of the displacements over the largest displacement, and the
difference of the force (the reaction on the moved face, or the obstacle's force) over the force.
Both are of the order of the strains, so they shrink with the load: ``--scale 1e-5`` shows it.

The difference is first order in the strain, with a coefficient that the mechanics sets, not the
discretisation. In the uniaxial stretch λ it is in closed form: Hencky's law gives the Kirchhoff
stress τ = E ln λ, so the force per reference area is P = τ / λ against E (λ − 1) at small strain,

    1 − ln λ / (λ (λ − 1)) = (3/2)(λ − 1) + O((λ − 1)²),

that is 1.5e-4 at a stretch of 1e-4 (printed with the case as ``closed form``).

Usage::

    python benchmarks/small_strain_limit.py [--scale 1e-4] [--cases stretch shear necking sphere ironing]
        [--json OUT.json]
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import dolfinx_nnqem  # noqa: F401  (before dolfinx: the PyPI wheel needs it)
import numpy as np
from mpi4py import MPI

sys.path.insert(0, str(Path(__file__).resolve().parent))
CASES = ("stretch", "shear", "necking", "sphere", "ironing")


def cube_problem(kinematics: str, shear: bool):
    """The unit cube of the ``stretch`` or ``shear`` case (module docstring)."""
    from dolfinx_nnqem.cases.geometries import BlockStackTags as T
    from dolfinx_nnqem.cases.geometries import build_block_stack
    from dolfinx_nnqem.material import Elastic, NeoHooke, VonMises
    from dolfinx_nnqem.problem import ContactProblem, Dirichlet

    mesh, ct, ft = build_block_stack(MPI.COMM_WORLD, 1.0, 1.0, [1.0], [(2, 2, 2)])
    if shear:
        material = NeoHooke(E=200e3, nu=0.3) if kinematics == "finite" else Elastic(E=200e3, nu=0.3)
        dirichlet = [Dirichlet(T.bottom(1)), Dirichlet(T.top(1), (1.0, 0.0, 0.0))]
    else:
        material = VonMises(E=200e3, nu=0.3, sigma_y0=200.0, H=1000.0)
        dirichlet = [Dirichlet(T.bottom(1), 0.0, [1]), Dirichlet(T.xmin(1), 0.0, [0]),
                     Dirichlet(T.zmin(1), 0.0, [2]), Dirichlet(T.top(1), 1.0, [1])]
    return ContactProblem(mesh, ct, ft, materials=material, dirichlet=dirichlet, kinematics=kinematics), T.top(1)


def case_problem(case: str, kinematics: str, scale: float):
    """(problem, how to read its force, the final load factor) of ``case`` at ``kinematics``."""
    from dolfinx_nnqem.cases.large_sliding import ironing, obstacle_force
    from dolfinx_nnqem.io.results import reactions

    if case in ("stretch", "shear"):
        problem, tag = cube_problem(kinematics, shear=case == "shear")
        return problem, (lambda p: reactions(p)[tag]), scale
    if case == "necking":
        import necking_bar

        problem = necking_bar.necking_problem(*necking_bar.geometry.MESHES["coarse"], comm=MPI.COMM_WORLD,
                                              kinematics=kinematics)
        end = necking_bar.geometry.NeckingBarTags.END
        return problem, (lambda p: reactions(p)[end]), scale
    if case == "sphere":
        import calculix_deep_sphere_press as press

        problem = press.deep_press_problem(0.25, comm=MPI.COMM_WORLD, kinematics=kinematics)
        return problem, obstacle_force, scale
    problem = ironing(8, depth=0.1 * scale, kinematics=kinematics)  # the whole path: the slide is not scaled
    return problem, obstacle_force, 1.0


def solve(case: str, kinematics: str, scale: float) -> tuple[np.ndarray, np.ndarray]:
    """The displacement dofs (this rank's owned) and the force at the end of ``case``'s scaled load."""
    from dolfinx_nnqem.solvers import SolverOptions, make_solver, solve_load_steps

    problem, force_of, final = case_problem(case, kinematics, scale)
    increments = 16 if case == "ironing" else 2
    with make_solver("monolithic", problem, SolverOptions(rtol=1e-10, max_iterations=40)) as solver:
        solve_load_steps(problem, solver, increments, final_load_factor=final)
    owned = problem.V.dofmap.index_map.size_local * problem.V.dofmap.index_map_bs
    return problem.u.x.array[:owned].copy(), np.asarray(force_of(problem), dtype=float)


def difference(case: str, scale: float) -> dict:
    """The finite- against the small-strain answer of ``case`` at ``scale`` of its load."""
    comm = MPI.COMM_WORLD
    (u_s, f_s), (u_f, f_f) = (solve(case, kinematics, scale) for kinematics in ("small", "finite"))
    du = comm.allreduce(float(np.abs(u_f - u_s).max(initial=0.0)), op=MPI.MAX)
    u = comm.allreduce(float(np.abs(u_s).max(initial=0.0)), op=MPI.MAX)
    out = {"case": case, "scale": scale, "u": du / u, "force": float(np.linalg.norm(f_f - f_s) / np.linalg.norm(f_s)),
           "force small": f_s.tolist(), "force finite": f_f.tolist()}
    if case == "stretch":
        out["closed form"] = stretch_force_difference(1.0 + scale)
    return out


def stretch_force_difference(stretch: float) -> float:
    """The relative difference of the uniaxial force, small against finite strain (module docstring)."""
    return 1.0 - np.log(stretch) / (stretch * (stretch - 1.0))


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scale", type=float, nargs="+", default=[1e-4])
    parser.add_argument("--cases", nargs="+", default=list(CASES), choices=CASES)
    parser.add_argument("--json", type=Path)
    args = parser.parse_args(argv)
    rows = []
    for scale in args.scale:
        for case in args.cases:
            rows.append(difference(case, scale))
            if MPI.COMM_WORLD.rank == 0:
                r = rows[-1]
                closed = f" (closed form {r['closed form']:.4e})" if "closed form" in r else ""
                print(f"{case:8s} load × {scale:g}: |u_finite − u_small|/|u| = {r['u']:.2e}, "
                      f"|F_finite − F_small|/|F| = {r['force']:.4e}{closed}", flush=True)
    if args.json is not None and MPI.COMM_WORLD.rank == 0:
        args.json.write_text(json.dumps(rows, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())

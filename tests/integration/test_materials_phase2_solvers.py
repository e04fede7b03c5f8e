"""Kinematic hardening and Drucker–Prager through every solver and both pair laws (issue 40, phase 2):
the pressed and dragged blocks with an elastic lower block, NNEQM2's stated refusals, quadratic
Newton convergence with the (unsymmetric) consistent tangents, the options that assume symmetry
refused, problem files, and 2 ranks equal to serial."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from mpi4py import MPI
from problem_files import two_beams_minimal

from dolfinx_nnqem import compat
from dolfinx_nnqem.material import BackStress, DruckerPrager, Elastic, VoceHardening, VonMises
from dolfinx_nnqem.problem import Contact, ContactProblem, Dirichlet, Pressure, Traction
from dolfinx_nnqem.cases.geometries import BlockStackTags as B
from dolfinx_nnqem.cases.geometries import build_block_stack
from dolfinx_nnqem.solvers import NNEQM2Options, SolverOptions, make_solver, solve_load_steps

SCRIPTS = Path(__file__).resolve().parents[1] / "mpi_scripts"
UPPER = {
    "chaboche-voce": VonMises(E=2.0e10, nu=0.2, hardening=VoceHardening(2.0e7, 5.0e6, 200.0, 0.0),
                              kinematic=[BackStress(4.0e9, 400.0), BackStress(5.0e8)]),
    "dp-associated": DruckerPrager(E=2.0e10, nu=0.2, cohesion=4.0e6, friction_angle=30.0, H=1.0e8),
    "dp-non-associated": DruckerPrager(E=2.0e10, nu=0.2, cohesion=4.0e6, friction_angle=30.0, dilatancy_angle=5.0,
                                       H=1.0e8),
}


def blocks(law: str, upper, comm=MPI.COMM_WORLD) -> ContactProblem:
    """An elastic lower block under ``upper``, pressed 3e7 Pa and dragged 0.2 of it."""
    mesh, ct, ft = build_block_stack(comm, 1.0, 1.0, (0.5, 0.5), ((4, 2, 4), (4, 2, 4)))
    return ContactProblem(
        mesh, ct, ft, materials={1: Elastic(E=2.0e10, nu=0.2), 2: upper},
        dirichlet=[Dirichlet(B.bottom(1))] + [Dirichlet(f(k), 0.0, [2]) for k in (1, 2) for f in (B.zmin, B.zmax)],
        tractions=[Pressure(B.top(2), 3.0e7), Traction(B.top(2), (0.2 * 3.0e7, 0.0, 0.0))],
        contact=Contact(B.top(1), B.bottom(2), mu_f=0.3, law=law))


def _solve(method: str, law: str, upper: str, **extra):
    problem = blocks(law, UPPER[upper])
    with make_solver(method, problem, SolverOptions(rtol=1e-12, max_iterations=40), **extra) as solver:
        results = solve_load_steps(problem, solver, 5)
    return problem, results


@pytest.mark.parametrize("upper", list(UPPER))
@pytest.mark.parametrize("law", ["alart-curnier", "polar"])
def test_every_solver_takes_the_new_materials_or_refuses_before_solving(law, upper):
    runs = {m: _solve(m, law, upper) for m in ("monolithic", "nneqm1")}
    if upper.startswith("dp"):
        with pytest.raises(ValueError, match="volumetric plastic strain.*deviatoric plastic strains"):
            _solve("nneqm2", law, upper)
    else:
        runs["nneqm2"] = _solve("nneqm2", law, upper)
    with pytest.raises(ValueError, match="flow_directions='frozen'.*(von-mises-kinematic|volumetric)|volumetric"):
        _solve("nneqm2", law, upper, nneqm2=NNEQM2Options(flow_directions="frozen"))
    ref = runs["monolithic"][0].u.x.array
    plastic = runs["monolithic"][0].state.count_plastic_points()
    print(f"\n  {upper} on elastic, {law}: {plastic} Gauss points yield in the last increment; NNEQM2 "
          f"{'refuses (volumetric flow)' if upper.startswith('dp') else 'takes it (frozen variant refuses)'}")
    for name, (problem, results) in runs.items():
        diff = np.abs(problem.u.x.array - ref).max() / np.abs(ref).max()
        maxima = problem.state.maxima_by_body()
        print(f"  {name:10s} iterations {[r.iterations for r in results]}  |u − u_monolithic|/|u| {diff:.1e}  "
              f"max p {maxima['p']}  max f/σ_y {maxima['f_over_sigma_y']}"
              + (f"  max q(α) {maxima['back_stress']}" if "back_stress" in maxima else ""))
        assert maxima["p"]["1"] == 0.0 and maxima["p"]["2"] > 1e-5
        assert abs(maxima["f_over_sigma_y"]["2"]) < 1e-8  # plastic points on the yield surface
        assert diff < 1e-8, name
    assert plastic > 0


@pytest.mark.parametrize("upper", list(UPPER))
def test_newton_converges_quadratically_with_the_consistent_tangent(upper):
    """The monolithic solver's |R|/F in the last (plastic) increment: each the square of the last,
    up to a constant, until round-off, with the unsymmetric tangents too (MUMPS LU)."""
    problem, results = _solve("monolithic", "alart-curnier", upper)
    history = [h.equilibrium for h in results[-1].report.history]
    pairs = [(a, b) for a, b in zip(history[:-1], history[1:]) if b > 1e-14 and a < 1e-2][-3:]
    constants = [b / a**2 for a, b in pairs]  # bounded: quadratic; growing like 1/r_k: linear
    print(f"\n  {upper} (symmetric tangent: {problem.state.symmetric_tangent}): last increment's |R|/F "
          f"{['%.2e' % r for r in history]}; r_k+1 / r_k² {['%.1f' % c for c in constants]}")
    assert problem.state.symmetric_tangent == (upper == "dp-associated")
    assert len(pairs) >= 2 and max(constants) / min(constants) < 10 and history[-1] < 1e-12


@pytest.mark.parametrize("options", [{"pc_type": "cholesky"}, {"ksp_type": "cg", "pc_type": "gamg"},
                                     {"fieldsplit_u_pc_type": "icc"}])
def test_options_that_assume_a_symmetric_matrix_are_refused_for_an_unsymmetric_tangent(options):
    problem = blocks("alart-curnier", UPPER["dp-non-associated"])
    key = next(iter(k for k in options if k.endswith("pc_type") and options[k] != "gamg" or k == "ksp_type"))
    with pytest.raises(ValueError, match=f"{key} = .* assumes a symmetric matrix.*unsymmetric"):
        make_solver("monolithic", problem, SolverOptions(petsc_options=options))
    symmetric = blocks("alart-curnier", UPPER["dp-associated"])
    make_solver("monolithic", symmetric, SolverOptions(petsc_options=options)).destroy()  # accepted there


def test_problem_files_take_kinematic_hardening_and_drucker_prager(tmp_path):
    from dolfinx_nnqem.problem_file import ProblemFileError, load_problem_file

    def load(materials: str):
        path = tmp_path / "p.toml"
        path.write_text(two_beams_minimal(materials=materials, mu_f=0.1, clamped=(11,)))
        return load_problem_file(path)

    spec = load('[materials.1]\nE = 2.0e10\nnu = 0.2\nhardening = "voce"\nsigma_y0 = 2.0e7\nQ = 5.0e6\nb = 200.0\n'
                'kinematic = [[4.0e9, 400.0], [5.0e8, 0.0]]\n'
                '[materials.2]\nmodel = "drucker-prager"\nE = 2.0e10\nnu = 0.2\ncohesion = 4.0e6\n'
                'friction_angle = 30.0\ndilatancy_angle = 5.0\nmatch = "plane-strain"\nH = 1.0e8\n')
    print(f"\n  {spec.materials}")
    assert spec.materials[1] == VonMises(2.0e10, 0.2, hardening=VoceHardening(2.0e7, 5.0e6, 200.0),
                                         kinematic=[BackStress(4.0e9, 400.0), BackStress(5.0e8)])
    assert spec.materials[2] == DruckerPrager(2.0e10, 0.2, 4.0e6, 30.0, 5.0, "plane-strain", H=1.0e8)
    for table, match in [
        ('E = 1e9\nnu = 0.3\nsigma_y0 = 1e6\nkinematic = [[1e8]]', r"materials\.1\]\.kinematic.*pairs \[C, gamma\]"),
        ('E = 1e9\nnu = 0.3\nsigma_y0 = 1e6\nkinematic = [[1e8, -3.0]]', r"materials\.1.*kinematic\[0\].*gamma = -3"),
        ('E = 1e9\nnu = 0.3\nkinematic = [[1e8, 3.0]]', r"materials\.1.*kinematic hardening needs a yield stress"),
        ('model = "drucker-prager"\nE = 1e9\nnu = 0.3\ncohesion = 1e4\nfriction_angle = 95.0',
         r"materials\.1.*friction_angle = 95"),
        ('model = "drucker-prager"\nE = 1e9\nnu = 0.3\ncohesion = 1e4\nfriction_angle = 20.0\ndilatancy_angle = 25.0',
         r"materials\.1.*dilatancy_angle = 25.* psi <= friction_angle"),
        ('model = "drucker-prager"\nE = 1e9\nnu = 0.3\ncohesion = 1e4\nfriction_angle = 20.0\nmatch = "middle"',
         r"materials\.1.*match = 'middle'"),
        ('model = "drucker-prager"\nE = 1e9\nnu = 0.3\nfriction_angle = 20.0', r"materials\.1.*needs the key cohesion"),
        ('model = "drucker-prager"\nE = 1e9\nnu = 0.3\ncohesion = 1e4', r"materials\.1.*needs the key friction_angle"),
        ('model = "drucker-prager"\nE = 1e9\nnu = 0.3\ncohesion = -1e4\nfriction_angle = 20.0', r"materials\.1.*cohesion = -1"),
        ('model = "drucker-prager"\nE = 1e9\nnu = 0.3\ncohesion = 1e4\nfriction_angle = 20.0\nsigma_y0 = 1e6',
         r"materials\.1.*'drucker-prager' takes no key.*sigma_y0"),
    ]:
        with pytest.raises(ProblemFileError, match=match):
            load(f"[materials.1]\n{table}\n[materials.2]\nE = 1e9\nnu = 0.3\n")


@pytest.mark.mpi
@pytest.mark.parametrize("upper", ["chaboche-voce", "dp-non-associated"])
def test_two_ranks_match_serial(tmp_path, upper):
    serial_problem, _ = _solve("monolithic", "alart-curnier", upper)
    serial = serial_problem.state.maxima_by_body()
    out = tmp_path / "out.npz"
    cmd = [*compat.mpiexec(), "-n", "2", sys.executable, str(SCRIPTS / "phase2_materials.py"), upper, str(out)]
    result = subprocess.run(cmd, capture_output=True, text=True, timeout=600, env=compat.mpi_environment())
    assert result.returncode == 0, f"{' '.join(cmd)} failed:\n{result.stdout[-3000:]}\n{result.stderr[-3000:]}"
    parallel = dict(np.load(out))
    x, u_s = serial_problem.V.tabulate_dof_coordinates(), serial_problem.u.x.array.reshape(-1, 3)

    def order(x, u):  # by position; the two blocks' coincident interface nodes by their displacement
        return np.lexsort((u[:, 1].round(9), u[:, 0].round(9), *x.T.round(9)[::-1]))

    u_s = u_s[order(x, u_s)]
    du = np.abs(parallel["u"][order(parallel["x"], parallel["u"])] - u_s).max() / np.abs(u_s).max()
    dp = abs(float(parallel["max_p"]) - serial["p"]["2"]) / serial["p"]["2"]
    print(f"\n  {upper} on 2 ranks vs serial: u {du:.1e}, max p {dp:.1e} (tolerance 1e-8)")
    assert du < 1e-8 and dp < 1e-8

"""ContactProblem.update: a parameter study in one process (issue 43).

Each changeable parameter gives, after ``update`` and a new solver, the answer of a problem built
afresh with it (the figures: docs/performance.md, "Parameter studies"); the second solve compiles
nothing; what is compiled into the forms is refused with an error naming it; ``reset`` returns
the initial state.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

import dolfinx_nnqem  # noqa: F401  (before dolfinx)
from dolfinx_nnqem import jit
from dolfinx_nnqem.cases.two_beams import MATERIAL, two_beams_problem
from dolfinx_nnqem.material.elastic import Elastic
from dolfinx_nnqem.material.hardening import VoceHardening
from dolfinx_nnqem.material.von_mises import VonMises
from dolfinx_nnqem.problem import ContactProblem, Dirichlet, Gravity, Traction
from dolfinx_nnqem.cases.geometries import TwoBeamsTags as T
from dolfinx_nnqem.solvers.registry import make_solver
from dolfinx_nnqem.solvers.stepping import solve_load_steps

INCREMENTS = 4
SOLVER_TOLERANCE = 1e-8  # relative: far above the solvers' converged residuals, far below any change tested


def _solve(problem: ContactProblem, method: str) -> tuple[np.ndarray, np.ndarray]:
    with make_solver(method, problem) as solver:
        solve_load_steps(problem, solver, INCREMENTS)
    assert problem.contact is not None
    return problem.u.x.array.copy(), problem.contact.force().copy()


def _fresh(problem: ContactProblem, **changes) -> ContactProblem:
    """The problem built afresh on the same mesh with ``changes`` to its definition."""
    d = dataclasses.replace(problem.definition, **changes)
    return ContactProblem(problem.mesh, problem.cell_tags, problem.facet_tags, materials=d.materials,
                          dirichlet=d.dirichlet, tractions=d.tractions, body_forces=d.body_forces,
                          contact=list(d.contact))


def _assert_same(a: tuple[np.ndarray, np.ndarray], b: tuple[np.ndarray, np.ndarray]) -> None:
    for x, y in zip(a, b):
        assert np.abs(x - y).max() <= SOLVER_TOLERANCE * np.abs(y).max()


def _assert_differs(a: tuple[np.ndarray, np.ndarray], b: tuple[np.ndarray, np.ndarray]) -> None:
    assert np.abs(a[0] - b[0]).max() > 1e-4 * np.abs(b[0]).max()


@pytest.fixture
def compiles(monkeypatch):
    """Counts the package's form and expression compiles (every one goes through jit._compile)."""
    count = [0]
    original = jit._compile

    def counting(make, expr):
        count[0] += 1
        return original(make, expr)

    monkeypatch.setattr(jit, "_compile", counting)
    return count


@pytest.mark.parametrize("method, law", [("monolithic", "alart-curnier"), ("monolithic", "polar"),
                                         ("nneqm1", "polar"), ("nneqm1", "alart-curnier"), ("nneqm2", "polar")])
def test_friction_update_gives_the_fresh_answer(method, law, compiles):
    problem = two_beams_problem(law=law)
    first = _solve(problem, method)
    compiles[0] = 0
    problem.update(mu_f=0.1)
    second = _solve(problem, method)
    if method != "nneqm2":  # NNEQM2's Gauss-point operators compile 4 expressions per solver (from the disk cache)
        assert compiles[0] == 0
    fresh = _solve(_fresh(problem, contact=(dataclasses.replace(problem.definition.contact[0], mu_f=0.1),)), method)
    _assert_same(second, fresh)
    _assert_differs(second, first)
    assert float(problem.contact.mu_f[0]) == 0.1
    assert problem.definition.contact[0].mu_f == 0.1


@pytest.mark.parametrize("change", ["E", "nu", "sigma_y0", "H", "density"])
def test_material_update_gives_the_fresh_answer(change, compiles):
    problem = two_beams_problem()
    first = _solve(problem, "monolithic")
    material = dataclasses.replace(MATERIAL, **{change: 1.5 * getattr(MATERIAL, change)})
    compiles[0] = 0
    problem.update(materials={T.BODY2: material})
    second = _solve(problem, "monolithic")
    assert compiles[0] == 0
    fresh = _solve(_fresh(problem, materials={T.BODY1: MATERIAL, T.BODY2: material}), "monolithic")
    _assert_same(second, fresh)
    _assert_differs(second, first)


def test_load_and_support_update_gives_the_fresh_answer(compiles):
    """(The lifting of prescribed displacements compiles its form at its first use: the first run
    lifts them, so that the count measures the second.)"""
    problem = two_beams_problem()
    problem.update(dirichlet=[Dirichlet(T.CLAMP1, value=(0.0, -2e-4, 0.0)), Dirichlet(T.CLAMP2)])
    first = _solve(problem, "nneqm1")
    tractions = [Traction(T.LOAD, (0.6e5, -0.6e5, 0.3e5), amplitude=lambda ell: ell ** 2)]
    body_forces = [Gravity((0.0, -2 * 9.81, 0.0))]
    dirichlet = [Dirichlet(T.CLAMP1, value=(0.0, -1e-4, 0.0)), Dirichlet(T.CLAMP2)]
    compiles[0] = 0
    problem.update(tractions=tractions, body_forces=body_forces, dirichlet=dirichlet)
    second = _solve(problem, "nneqm1")
    assert compiles[0] == 0
    fresh = _solve(_fresh(problem, tractions=tuple(tractions), body_forces=tuple(body_forces),
                          dirichlet=tuple(dirichlet)), "nneqm1")
    _assert_same(second, fresh)
    _assert_differs(second, first)


def test_reset_returns_the_initial_state():
    problem = two_beams_problem()
    first = _solve(problem, "monolithic")
    assert problem.load_factor_n == 1.0 and problem.predictor_history is not None
    problem.reset()
    assert problem.load_factor == problem.load_factor_n == 0.0
    assert problem.predictor_history is None
    assert not np.any(problem.u.x.array) and not np.any(problem.state.u_n.x.array)
    for f in (problem.state.sigma_n, problem.state.p_n, problem.state.dp_n):
        assert not np.any(f.x.array)
    assert problem.contact is not None
    assert np.array_equal(problem.contact.z, problem.contact.laws.initial_unknowns())
    assert not np.any(problem.contact.w_n) and not np.any(problem.contact.state_n)
    again = _solve(problem, "monolithic")
    assert all(np.array_equal(a, b) for a, b in zip(again, first))  # bit for bit: the same run


@pytest.mark.parametrize("changes, message", [
    ({"tractions": [Traction(T.LOAD, (1.0e5, 0.0, 0.0))]}, "not a multiple"),
    ({"tractions": [Traction(T.CLAMP1, (1.0e5, -1.0e5, 0.5e5))]}, "kind and tag are fixed"),
    ({"tractions": []}, "only their magnitudes"),
    ({"dirichlet": [Dirichlet(T.CLAMP1, components=(0,)), Dirichlet(T.CLAMP2)]}, "constrained dofs"),
    ({"materials": {T.BODY1: Elastic(E=2e10, nu=0.17)}}, "material kind"),
    ({"materials": {T.BODY1: VonMises(E=2e10, nu=0.17, hardening=VoceHardening(5e5, 1e6, 10.0))}}, "material kind"),
    ({"materials": {99: MATERIAL}}, "no body with this cell tag"),
    ({"materials": MATERIAL}, "one per cell tag"),
    ({"mu_f": -0.1}, "mu_f"),
    ({"mu_f": {"no-such-interface": 0.1}}, "no interface named"),
])
def test_what_is_compiled_or_fixed_is_refused(changes, message):
    problem = two_beams_problem()
    before = problem.definition
    with pytest.raises(ValueError, match=message):
        problem.update(**changes)
    assert problem.definition == before and float(problem.contact.mu_f[0]) == before.contact[0].mu_f


def test_parameters_of_a_return_map_on_arrays_are_refused():
    """A Voce law's parameters live in arrays its part builds with the problem: refused, named."""
    voce = VonMises(E=2e10, nu=0.17, hardening=VoceHardening(5e5, 1e6, 10.0), density=2400.0)
    problem = _fresh(two_beams_problem(), materials={T.BODY1: voce, T.BODY2: voce})
    with pytest.raises(ValueError, match=r"materials\[1\]\.E: .*arrays built with the problem"):
        problem.update(materials={T.BODY1: dataclasses.replace(voce, E=3e10)})


def test_an_nneqm2_solver_built_before_a_material_update_is_refused():
    """NNEQM2 builds its Gauss-point operators and factorises K_e with the materials of its time: after
    a material update it says so instead of failing to converge (measured: 5 cutbacks, then a
    ConvergenceError). The monolithic solver and NNEQM1 read the materials anew at every iteration:
    one built before an update gives the fresh answer bit for bit (docs/user-guide.md)."""
    problem = two_beams_problem(law="polar")
    with make_solver("nneqm2", problem) as solver:
        solve_load_steps(problem, solver, INCREMENTS)
        problem.update(materials={T.BODY2: dataclasses.replace(MATERIAL, E=3e10)})
        with pytest.raises(ValueError, match="material parameters changed .* build the solver again"):
            solve_load_steps(problem, solver, INCREMENTS)


def test_friction_that_alone_holds_a_body_cannot_go_to_zero():
    """The three stacked blocks of demos/contact_interfaces.py: block 2 slides along x against
    nothing but friction. μ_f = 0 on both of its interfaces is refused, naming the body, and the
    problem keeps its friction; μ_f = 0 on one interface is a parameter like any other."""
    from mpi4py import MPI

    from dolfinx_nnqem.problem import Contact, Pressure
    from dolfinx_nnqem.cases.geometries import BlockStackTags as B
    from dolfinx_nnqem.cases.geometries import build_block_stack

    mesh, cell_tags, facet_tags = build_block_stack(MPI.COMM_WORLD, 1.0, 1.0, [0.5] * 3, [(2, 1, 2)] * 3)
    elastic = VonMises(E=1.0e9, nu=0.3)
    problem = ContactProblem(
        mesh, cell_tags, facet_tags, materials={k: elastic for k in (1, 2, 3)},
        dirichlet=[Dirichlet(B.bottom(1)), Dirichlet(B.top(3), 1e-2, [0])]
        + [Dirichlet(face(k), 0.0, [2]) for k in (1, 2, 3) for face in (B.zmin, B.zmax)],
        tractions=[Pressure(B.top(3), 1.0e6)],
        contact=[Contact(B.top(1), B.bottom(2), mu_f=0.2, name="lower"),
                 Contact(B.top(2), B.bottom(3), mu_f=0.4, name="upper")])
    held_by_friction = r"(?s)move rigidly without resistance.*body 2 \(cells tagged 2\): translation along \(1, 0, 0\)"
    with pytest.raises(ValueError, match=held_by_friction):
        problem.update(mu_f=0.0)
    assert sorted(set(problem.contact.mu_f.tolist())) == [0.2, 0.4]
    assert [c.mu_f for c in problem.definition.contact] == [0.2, 0.4]
    problem.update(mu_f={"lower": 0.0})
    assert [c.mu_f for c in problem.definition.contact] == [0.0, 0.4]


@pytest.mark.mpi
def test_update_on_two_ranks_gives_the_fresh_answer(tmp_path):
    """``update`` is collective (the moduli, r and the rigid-mode checks reduce over the ranks): on
    2 ranks a μ_f and E update gives the answer of the problem built afresh (measured: 2.9e-16 and
    5.7e-16 in two runs of the monolithic solver, MUMPS's parallel rounding; 0 for NNEQM1; relative to
    the largest displacement)."""
    import json
    import subprocess
    import sys
    from pathlib import Path

    from dolfinx_nnqem import compat

    script = Path(__file__).parents[1] / "mpi_scripts" / "parameter_update.py"
    out = tmp_path / "out.json"
    cmd = [*compat.mpiexec(), "-n", "2", sys.executable, str(script), str(out)]
    result = subprocess.run(cmd, capture_output=True, text=True, timeout=600, env=compat.mpi_environment())
    assert result.returncode == 0, f"{' '.join(cmd)} failed:\n{result.stdout[-3000:]}\n{result.stderr[-3000:]}"
    found = json.loads(out.read_text())
    print(f"\n  2 ranks, updated against fresh: {found}")
    assert found["ranks"] == 2 and max(found["monolithic"], found["nneqm1"]) <= SOLVER_TOLERANCE

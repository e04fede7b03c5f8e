"""Large sliding: contact geometry in the current configuration (issue 27, first part).

* symmetric press: a frictionless rigid sphere pressed into an elastic block at x = 0.3 and slid to
  x = 0.7 ends with the force of a press made in place at 0.7 (and, by the mesh's mirror symmetry,
  with the mirror image of the force at 0.3), monolithic and NNEQM1, both laws;
* the issue's set-up (R = 0.6, 0.01 into a unit cube, x from 0.3 to 0.7) on 8³ hexahedra instead of
  16³ (test time): reference geometry stops and now names the stale geometry as the likely cause;
  current geometry runs through;
* a block slid 1.6 master facets over another (node-to-surface, pairs change their master facet
  and a third of them go): the force of a press made in place there;
* a cylinder slid like the sphere; a plane pressed and slid with friction gives the reference
  geometry's results (its geometry is exact in both);
* μ_f = 0.3: the slid block's pairs on the Coulomb cone; the same run from a problem file;
* what is refused, before solving, with the reason: node-to-node with ``geometry = "current"``
  (mortar: tests/integration/test_large_sliding_mortar.py; NNEQM2, which follows the geometry since
  issue 41: tests/integration/test_large_sliding_nneqm2.py).
"""

import logging

import numpy as np
import pytest

from dolfinx_nnqem.cases.large_sliding import ironing, obstacle_force, slave_force, sliding_blocks, sliding_sphere
from dolfinx_nnqem.problem import Contact
from dolfinx_nnqem.solvers import ConvergenceError, SolverOptions, make_solver, solve_load_steps

CASES = [("monolithic", "alart-curnier"), ("monolithic", "polar"), ("nneqm1", "alart-curnier"),
         ("nneqm1", "polar")]
OPTIONS = SolverOptions(rtol=1e-10, max_iterations=40)


def _run(problem, method, increments):
    with make_solver(method, problem, OPTIONS) as solver:
        results = solve_load_steps(problem, solver, increments)
    return results


@pytest.mark.parametrize("method, law", CASES)
def test_symmetric_press(method, law):
    slid = sliding_sphere(6, start=0.3, end=0.7, law=law)
    results = _run(slid, method, 16)
    in_place = sliding_sphere(6, start=0.7, end=0.7, law=law)
    _run(in_place, method, 4)
    f_slid, f_place = obstacle_force(slid), obstacle_force(in_place)
    error = np.linalg.norm(f_slid - f_place) / np.linalg.norm(f_place)
    iterations = [r.iterations for r in results]
    passes = [r.report.geometry_passes for r in results]
    print(f"\n  {method}/{law}: slid 0.3 -> 0.7: F = {f_slid}, pressed in place at 0.7: F = {f_place}; "
          f"|ΔF|/|F| = {error:.2e} (tolerance 1e-6); Newton iterations per increment {iterations} "
          f"(total {sum(iterations)}), solves per increment {passes}")
    assert error < 1e-6
    assert slid.num_pairs == 49  # every node of the top face (a rigid obstacle pairs them all)


@pytest.mark.parametrize("method", ["monolithic", "nneqm1"])
def test_symmetric_press_cylinder(method):
    """A cylinder (axis along z) slid over the block: the same as a press in place, 1e-6."""
    slid = sliding_sphere(6, shape="cylinder")
    _run(slid, method, 16)
    in_place = sliding_sphere(6, start=0.7, end=0.7, shape="cylinder")
    _run(in_place, method, 4)
    f_slid, f_place = obstacle_force(slid), obstacle_force(in_place)
    error = np.linalg.norm(f_slid - f_place) / np.linalg.norm(f_place)
    print(f"\n  {method}: cylinder slid 0.3 -> 0.7: F = {f_slid}, in place: F = {f_place}; |ΔF|/|F| = {error:.2e}")
    assert error < 1e-6 and f_place[1] < 0


@pytest.mark.parametrize("method, law", CASES)
def test_plane_current_geometry_equals_reference(method, law):
    """A plane pressed, then slid with friction: its normals and gaps are exact in either geometry, so
    the current geometry (w_n measured again at every evaluation) gives the reference's results."""
    from mpi4py import MPI

    from dolfinx_nnqem.contact.obstacles import Plane
    from dolfinx_nnqem.material import VonMises
    from dolfinx_nnqem.problem import ContactProblem, Dirichlet, PiecewiseLinearPath
    from dolfinx_nnqem.cases.geometries import BlockStackTags as T
    from dolfinx_nnqem.cases.geometries import build_block_stack

    def solve(geometry):
        mesh, ct, ft = build_block_stack(MPI.COMM_WORLD, 1.0, 1.0, [0.5], [(3, 2, 3)])
        path = PiecewiseLinearPath([[0.0, 0.0, 0.0, 0.0], [0.5, 0.0, -1e-3, 0.0], [1.0, 5e-3, -1e-3, 0.0]])
        plane = Plane(point=(0.0, 0.5, 0.0), normal=(0.0, -1.0, 0.0), motion=path)
        problem = ContactProblem(mesh, ct, ft, materials=VonMises(E=1.0e9, nu=0.3), dirichlet=[Dirichlet(T.bottom(1))],
                                 contact=Contact(plane, T.top(1), mu_f=0.3, law=law, geometry=geometry))
        results = _run(problem, method, 8)
        return obstacle_force(problem), [r.iterations for r in results]

    (f_ref, it_ref), (f_cur, it_cur) = solve("reference"), solve("current")
    error = np.linalg.norm(f_cur - f_ref) / np.linalg.norm(f_ref)
    print(f"\n  {method}/{law}: plane press then slide: reference F = {f_ref} ({it_ref} iterations), current "
          f"F = {f_cur} ({it_cur}); |ΔF|/|F| = {error:.1e} (tolerance 1e-8)")
    assert error < 1e-8


def test_issue_sliding_sphere_reference_geometry_stops_before_a_stale_state():
    """geometry = "reference" chosen: the first converged state slid past 0.25 facet sizes is not
    committed; the run stops there (no cutback), naming the interface, the slip and what to use."""
    problem = sliding_sphere(8, geometry="reference")
    committed = []
    with make_solver("monolithic", problem, OPTIONS) as solver:
        with pytest.raises(ConvergenceError) as error:
            solve_load_steps(problem, solver, 20, callbacks=[lambda r: committed.append(r.load_factor)])
    message, failure = str(error.value), error.value.failure
    slips = problem.contact.geometry.slipped(problem.relative_displacement())
    print(f"\n  reference geometry: committed {committed}; {message}")
    assert "converged, but is not committed: the contact geometry is stale" in message
    assert "contact sphere-201 (rigid obstacle, reference geometry): the surfaces slid" in message
    assert "geometry = 'reference' was chosen for it (use 'auto' or 'current' for large sliding)" in message
    assert failure["stale_geometry"] == ["sphere-201"] and failure["cutbacks"] == 0
    assert failure["load_factor"] == pytest.approx(committed[-1] + 0.05)
    assert not slips  # the last committed state, restored, is within the limit


@pytest.mark.parametrize("method, law, nx, increments, switch", [("monolithic", "alart-curnier", 32, 40, 0.225),
                                                              ("monolithic", "polar", 32, 40, 0.225),
                                                              ("nneqm1", "alart-curnier", 16, 20, 0.25),
                                                              ("nneqm2", "alart-curnier", 16, 20, 0.25)])
def test_default_geometry_follows_a_dragged_punch(method, law, nx, increments, switch):
    """Issue 39, item 1: a cylinder pressed into a plastic strip and dragged 16 facets along it (8 for
    NNEQM1 and NNEQM2: time), with the default geometry. The press leaves the surfaces where they were; the
    drag slides them past 0.25 facet sizes at ℓ = 0.225 (0.25 with 8 facets), and from that increment on the pairs are
    re-evaluated where the bodies are: every committed force is the current geometry's, to round-off.
    (The reference geometry, the default before, committed forces 1.8 to 2.4 times too large
    there, then stopped on the strain check.)"""
    forces = {}
    for geometry in (None, "current"):
        problem = ironing(nx, law=law, geometry=geometry)
        history = []
        with make_solver(method, problem, OPTIONS) as solver:
            results = solve_load_steps(problem, solver, increments,
                                       callbacks=[lambda r: history.append(obstacle_force(problem))])
        forces[geometry] = np.array(history)
        if geometry is None:
            switches = problem.slip_warnings
            following = problem.contact.geometry.following
    a, b = forces[None], forces["current"]
    error = (np.abs(a - b).max(axis=1) / np.abs(b).max(axis=1)).max()
    print(f"\n  {method}/{law}, {nx} × {nx // 4} × 2: {len(results)} increments; {switches}; largest difference "
          f"from geometry = 'current' over the path {error:.1e} (tolerance 1e-8); F at the end {a[-1]}")
    assert len(a) == len(b) == increments and following == [True]
    assert len(switches) == 1 and f"at load factor {switch:g}:" in switches[0] and "geometry = 'auto'" in switches[0]
    assert error < 1e-8


def test_issue_sliding_sphere_current_geometry():
    problem = sliding_sphere(8)
    forces = []
    with make_solver("monolithic", problem, OPTIONS) as solver:
        results = solve_load_steps(problem, solver, 20, callbacks=[lambda r: forces.append(obstacle_force(problem))])
    f = np.array(forces)
    print(f"\n  current geometry, 8³: {len(results)} increments, {sum(r.iterations for r in results)} Newton "
          f"iterations, {sum(r.report.geometry_passes for r in results)} solves; normal force after the press "
          f"{f[4, 1]:.6g}, over the slide {f[4:, 1].min():.6g} .. {f[4:, 1].max():.6g}")
    assert results[-1].load_factor == 1.0
    assert np.all(f[4:, 1] < 0.8 * f[4, 1])  # still pressed all the way (y points up: the force is < 0)


@pytest.mark.parametrize("method, law", CASES)
def test_block_slid_over_several_facets(method, law):
    slid = sliding_blocks(slide=0.4, law=law)
    assert slid.contact is not None
    facets_before = slid.contact.geometry.state()[0].copy()  # every slave node's master facet
    pairs_before = slid.num_pairs
    results = _run(slid, method, 12)
    facets = slid.contact.geometry.state()[0]
    moved = np.count_nonzero((facets != facets_before) & (facets >= 0))
    in_place = sliding_blocks(slide=0.0, offset=0.4, law=law)
    _run(in_place, method, 4)
    f_slid, f_place = slave_force(slid), slave_force(in_place)
    error = abs(f_slid[1] - f_place[1]) / abs(f_place[1])
    error_total = np.linalg.norm(f_slid - f_place) / np.linalg.norm(f_place)
    iterations = [r.iterations for r in results]
    print(f"\n  {method}/{law}: slid 0.4 (1.6 master facets): pairs {pairs_before} -> {slid.num_pairs}, "
          f"{moved} slave nodes on another master facet; normal force {f_slid[1]:.9g}, in place {f_place[1]:.9g}: "
          f"{error:.1e} (tolerance 1e-6); |ΔF|/|F| = {error_total:.1e}; iterations {iterations}")
    assert pairs_before == 49 and slid.num_pairs == in_place.num_pairs == 28
    assert moved > 10
    assert error < 1e-6
    assert error_total < 1e-3  # the lateral part: which facet a node on a shared edge keeps (theory.md)


@pytest.mark.parametrize("discretisation, why", [("node-to-node", "does not apply to node-to-node")])
def test_current_geometry_refused_where_not_implemented(discretisation, why):
    with pytest.raises(ValueError, match=why):
        Contact(21, 22, mu_f=0.0, discretisation=discretisation, geometry="current")
    with pytest.raises(ValueError, match="geometry = 'deformed'; expected one of auto, reference, current"):
        Contact(21, 22, mu_f=0.0, geometry="deformed")


@pytest.mark.parametrize("method, law", CASES)
def test_frictional_block_slides_on_the_cone(method, law):
    """μ_f = 0.3: once the block slides, every closed pair is on the Coulomb cone (the slip measured
    as the relative displacement increment in the current frame, theory.md) and friction opposes the slide."""
    from dolfinx_nnqem.io import pair_table

    mu_f = 0.3
    problem = sliding_blocks(slide=0.4, law=law, mu_f=mu_f)
    results = _run(problem, method, 12)
    t = pair_table(problem)
    local = -t["force_local_body1"]  # on the slave block: (p_n, q1, q2)
    closed = local[:, 0] > 0
    cone = np.abs(np.hypot(local[closed, 1], local[closed, 2]) - mu_f * local[closed, 0]).max() / (mu_f * local[:, 0].max())
    f = slave_force(problem)
    print(f"\n  {method}/{law}: {np.count_nonzero(closed)} closed pairs, states "
          f"{dict(zip(*np.unique(t['state_name'], return_counts=True)))}; max ||q| − μ_f p_n| / (μ_f max p_n) = "
          f"{cone:.1e} (tolerance 1e-8); F = {f}, |F_x| / F_y = {abs(f[0]) / f[1]:.6f}; iterations "
          f"{[r.iterations for r in results]}")
    assert np.all(t["state_name"][closed] == "slip") and cone < 1e-8
    assert f[0] < 0 and 0.28 < abs(f[0]) / f[1] <= mu_f  # < μ_f: the Poisson effect adds a transverse slip


def _blocks_file(*, E1: float, press: float, pressed_at: float, slide: float, z_tags: list[int], increments: int,
                 degree: int = 1, discretisation: str = "node-to-surface", rtol: float | None = None) -> str:
    """A problem file for two blocks (surfaces 201 | 102, body 1 clamped at 101): body 2's top (202)
    pressed down by ``press`` over ℓ ≤ ``pressed_at``, then slid ``slide`` along x; u_z = 0 on
    ``z_tags``; MESH, METHOD and LAW to be replaced. ``degree``, ``rtol``: written only if given (not 1, None)."""
    fixed_z = "".join(f"[[dirichlet]]\ntag = {tag}\ncomponents = [2]\n" for tag in z_tags)
    mesh_degree = "" if degree == 1 else f"degree = {degree}\n"
    solver_rtol = "" if rtol is None else f"rtol = {rtol!r}\n"
    return f"""
[mesh]
file = "MESH"
{mesh_degree}[materials.1]
E = {E1!r}
nu = 0.3
[materials.2]
E = 1.0e3
nu = 0.3
[contact]
surface1 = 201
surface2 = 102
mu_f = 0.3
law = "LAW"
discretisation = "{discretisation}"
geometry = "current"
[[dirichlet]]
tag = 101
[[dirichlet]]
tag = 202
components = [1]
value = {press!r}
amplitude = [[0.0, 0.0], [{pressed_at!r}, 1.0], [1.0, 1.0]]
[[dirichlet]]
tag = 202
components = [0]
value = {slide!r}
amplitude = [[0.0, 0.0], [{pressed_at!r}, 0.0], [1.0, 1.0]]
{fixed_z}[solver]
method = "METHOD"
increments = {increments}
{solver_rtol}"""


BLOCKS_FILE = _blocks_file(E1=1.0e3, press=-0.01, pressed_at=0.25, slide=0.4, z_tags=[202], increments=12)


@pytest.mark.parametrize("method, law", [("monolithic", "alart-curnier"), ("nneqm1", "polar"), ("nneqm2", "alart-curnier")])
def test_problem_file_block_slid_in_current_geometry(tmp_path, method, law):
    """The frictional block slide from a problem file (``geometry = "current"``), through the CLI and its
    writers, while a third of the pairs go: the Python run's force."""
    import json

    from mpi4py import MPI

    from dolfinx_nnqem.cli import EXIT_OK, main
    from dolfinx_nnqem.cases.geometries import build_block_stack

    if MPI.COMM_WORLD.size > 1:
        pytest.skip("the CLI test runs serially")
    build_block_stack(MPI.COMM_SELF, 1.0, 1.0, [0.5, 0.5], [(4, 2, 4), (6, 2, 6)], msh_file=tmp_path / "blocks.msh")
    path = tmp_path / "slide.toml"
    path.write_text(BLOCKS_FILE.replace("MESH", (tmp_path / "blocks.msh").as_posix()).replace("METHOD", method)
                    .replace("LAW", law))
    assert main(["-q", "run", str(path), "--out", str(tmp_path / "out")]) == EXIT_OK
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    python = [r.iterations for r in _run(sliding_blocks(slide=0.4, law=law, mu_f=0.3), method, 12)]
    print(f"\n  {method}/{law}: converged {summary['converged']}, iterations {summary['iterations']} (the Python "
          f"run's: {python}), global equilibrium {summary['equilibrium_residual']:.1e}")
    assert summary["converged"] and summary["iterations"] == python
    assert summary["equilibrium_residual"] < 1e-8


@pytest.mark.parametrize("method", ["monolithic", "nneqm1"])
def test_restart_in_current_geometry(tmp_path, method):
    """The frictional block slide interrupted after increment 5 (pairs 49 -> 42 by then) and resumed
    in a fresh problem equals the uninterrupted run to 1e-12: the checkpoint's pairs are evaluated
    again from its displacement, with its master facets."""
    from dolfinx_nnqem.io import checkpoint

    def build():
        return sliding_blocks(slide=0.4, mu_f=0.3)

    n = 12
    reference = build()
    _run(reference, method, n)
    out = tmp_path / "run"
    first = build()
    checkpointer = checkpoint.Checkpointer(out)

    def checkpoint_then_stop_after_5(problem, stepper_state, result):
        checkpointer(problem, stepper_state, result)
        if result.index == 5:
            raise KeyboardInterrupt  # as Ctrl-C would, after increment 5's checkpoint

    with pytest.raises(KeyboardInterrupt):
        with make_solver(method, first, OPTIONS) as solver:
            solve_load_steps(first, solver, n, checkpoint=checkpoint_then_stop_after_5)
    pairs_at_stop = first.num_pairs
    second = build()
    state, _ = checkpoint.restore(second, out)
    with make_solver(method, second, OPTIONS) as solver:
        results = solve_load_steps(second, solver, n, resume=state)
    du = np.abs(second.u.x.array - reference.u.x.array).max() / np.abs(reference.u.x.array).max()
    df = np.linalg.norm(slave_force(second) - slave_force(reference)) / np.linalg.norm(slave_force(reference))
    print(f"\n  {method}: stopped after increment 5 with {pairs_at_stop} pairs, resumed for {len(results)} increments: "
          f"u {du:.1e}, force {df:.1e} (tolerance 1e-12)")
    assert pairs_at_stop == 42 and [r.index for r in results] == list(range(6, n + 1))
    assert du < 1e-12 and df < 1e-12


@pytest.mark.parametrize("stop", [3, 6])
def test_restart_of_a_default_geometry_run(tmp_path, stop):
    """The frictional block slide with geometry = "auto" (node-to-surface: the reference pairs until the
    slide passes 0.25 facet sizes, at increment 5), interrupted after increment ``stop`` (before and
    after that switch) and resumed in a fresh problem: the uninterrupted run to 1e-12, with the
    interface in the geometry the checkpoint had."""
    from dolfinx_nnqem.io import checkpoint

    def build():
        return sliding_blocks(slide=0.4, mu_f=0.3, geometry="auto")

    n = 12
    reference = build()
    _run(reference, "monolithic", n)
    out = tmp_path / "run"
    first = build()
    checkpointer = checkpoint.Checkpointer(out)

    def checkpoint_then_stop(problem, stepper_state, result):
        checkpointer(problem, stepper_state, result)
        if result.index == stop:
            raise KeyboardInterrupt  # as Ctrl-C would, after the checkpoint

    with pytest.raises(KeyboardInterrupt):
        with make_solver("monolithic", first, OPTIONS) as solver:
            solve_load_steps(first, solver, n, checkpoint=checkpoint_then_stop)
    following_at_stop = first.contact.geometry.following
    second = build()
    state, _ = checkpoint.restore(second, out)
    following_restored = second.contact.geometry.following
    with make_solver("monolithic", second, OPTIONS) as solver:
        results = solve_load_steps(second, solver, n, resume=state)
    du = np.abs(second.u.x.array - reference.u.x.array).max() / np.abs(reference.u.x.array).max()
    df = np.linalg.norm(slave_force(second) - slave_force(reference)) / np.linalg.norm(slave_force(reference))
    print(f"\n  stopped after increment {stop} (current geometry: {following_at_stop}), resumed for {len(results)} "
          f"increments: u {du:.1e}, force {df:.1e} (tolerance 1e-12); switched: {reference.slip_warnings}")
    assert following_at_stop == following_restored == [stop == 6]
    assert reference.contact.geometry.following == second.contact.geometry.following == [True]
    assert [r.index for r in results] == list(range(stop + 1, n + 1))
    assert du < 1e-12 and df < 1e-12


@pytest.mark.parametrize("law", ["alart-curnier", "polar"])
def test_ironing_monolithic_and_nneqm1_agree(law):
    """A cylinder pressed into an elastoplastic strip and dragged 8 facets with μ_f = 0.1: NNEQM1 on the
    monolithic run's load path ends in the same state (path-dependent: plasticity and friction)."""
    from dolfinx_nnqem.cases.large_sliding import ironing
    from dolfinx_nnqem.solvers import solve_load_path

    mono = ironing(16, law=law)
    # 40 increments (a fifth of a facet each): with 20, NNEQM1's full outer steps alternate between 3 and
    # 6 closed pairs when the punch enters new facets, and it cuts back (docs/theory.md)
    results = _run(mono, "monolithic", 40)
    path = [r.load_factor for r in results]
    nested = ironing(16, law=law)
    with make_solver("nneqm1", nested, OPTIONS) as solver:
        nested_results = solve_load_path(nested, solver, path)
    f_m, f_n = obstacle_force(mono), obstacle_force(nested)
    df = np.linalg.norm(f_m - f_n) / np.linalg.norm(f_m)
    du = np.abs(mono.u.x.array - nested.u.x.array).max() / np.abs(mono.u.x.array).max()
    plastic = int(np.count_nonzero(mono.state.p_n.x.array > 0))
    print(f"\n  {law}: {len(path)} increments; monolithic F = {f_m} ({sum(r.iterations for r in results)} iterations), "
          f"NNEQM1 F = {f_n} ({sum(r.iterations for r in nested_results)}); |ΔF|/|F| = {df:.1e}, max |Δu|/max |u| = "
          f"{du:.1e} (tolerance 1e-6); {plastic} Gauss points plastic; |F_x|/|F_y| = {abs(f_m[0] / f_m[1]):.4f}")
    assert df < 1e-6 and du < 1e-6
    assert plastic > 50 and f_m[0] > 0 and 0.05 < abs(f_m[0] / f_m[1]) < 0.3  # dragged along +x, ploughing


def _long_slide_history(problem, method):
    """The long slide solved in 20 increments: per increment of steady sliding, the cone's largest
    miss |Σ|q|/Σp_n − μ_f| over the closed pairs' sums, F_x / F_y on the slider and its normal force."""
    from dolfinx_nnqem.cases.large_sliding import LONG_SLIDE_PRESSED_AT
    from dolfinx_nnqem.io import pair_table

    rows = []

    def record(result):
        local = -pair_table(problem)["force_local_body1"]
        rows.append([result.load_factor, *slave_force(problem),
                     np.hypot(local[:, 1], local[:, 2]).sum() / local[:, 0].sum()])

    with make_solver(method, problem, OPTIONS) as solver:
        results = solve_load_steps(problem, solver, 20, callbacks=[record])
    h = np.array(rows)
    steady = h[:, 0] > LONG_SLIDE_PRESSED_AT + 1e-12
    return h[steady, 4], -h[steady, 1] / h[steady, 2], h[steady, 2], results


STEADY_CASES = [("monolithic", "alart-curnier", "node-to-surface"), ("monolithic", "polar", "node-to-surface"),
                ("nneqm1", "alart-curnier", "node-to-surface"), ("nneqm1", "polar", "node-to-surface"),
                ("monolithic", "alart-curnier", "mortar"), ("nneqm1", "polar", "mortar")]


@pytest.mark.parametrize("method, law, discretisation", STEADY_CASES)
def test_steady_sliding_resultant_is_mu_f(method, law, discretisation):
    """A short block slid four times its own length (eight master facets) over a long one 10⁵ times
    stiffer, μ_f = 0.3: in steady sliding F_x / F_y = μ_f to 1e-6 and the normal force is constant
    to 1e-6. Mortar's resultant is μ_f to 2e-5: its nodal normal at the contact zone's leading edge
    averages a closed and a lifting slave facet (6e-4 tilt, 9e-6 of the resultant ratio)."""
    from dolfinx_nnqem.cases.large_sliding import LONG_SLIDE_STIFF_MASTER, long_slide

    mu_f = 0.3
    problem = long_slide(law=law, mu_f=mu_f, discretisation=discretisation, master=LONG_SLIDE_STIFF_MASTER)
    cone, ratio, normal, results = _long_slide_history(problem, method)
    miss = np.abs(ratio - mu_f).max() / mu_f
    spread = (normal.max() - normal.min()) / normal.mean() / 2
    print(f"\n  {method}/{law}/{discretisation}: {problem.num_pairs} pairs, {len(ratio)} increments of steady "
          f"sliding: max |Σ|q|/Σp_n − μ_f| = {np.abs(cone - mu_f).max():.1e}; max |F_x/F_y − μ_f|/μ_f = {miss:.1e}; "
          f"normal force {normal.mean():.6g} ± {spread:.1e}; iterations {[r.iterations for r in results]}")
    assert np.abs(cone - mu_f).max() < 1e-10
    assert spread < 1e-6
    assert miss < (1e-6 if discretisation == "node-to-surface" else 2e-5)


def test_block_slid_over_its_own_material():
    """The same slide over a long block of the slider's own material: every pair on the cone, but the
    deformed master's normals tilt and its stiffness under the slider varies along it: the resultant's
    F_x / F_y and the normal force vary with the master facets the block crosses (measured)."""
    from dolfinx_nnqem.cases.large_sliding import long_slide

    mu_f = 0.3
    problem = long_slide(mu_f=mu_f)
    cone, ratio, normal, results = _long_slide_history(problem, "monolithic")
    spread = (normal.max() - normal.min()) / normal.mean()
    print(f"\n  {problem.num_pairs} pairs: max |Σ|q|/Σp_n − μ_f| = {np.abs(cone - mu_f).max():.1e}; F_x/F_y from "
          f"{ratio.min():.5f} to {ratio.max():.5f}; normal force {normal.mean():.6g} ± {100 * spread / 2:.2f} %; "
          f"iterations {[r.iterations for r in results]}")
    assert np.abs(cone - mu_f).max() < 1e-10
    assert 1e-4 < np.abs(ratio - mu_f).max() / mu_f < 0.01 and 1e-3 < spread < 0.03


LONG_SLIDE_FILE = _blocks_file(E1=1.0e8, press=-0.002, pressed_at=0.1, slide=1.0, z_tags=[501, 601, 502, 602],
                               increments=20) + "rtol = 1e-10\n"


@pytest.mark.parametrize("method, law", [("monolithic", "alart-curnier"), ("nneqm1", "polar")])
def test_problem_file_steady_sliding(tmp_path, method, law):
    """The long slide over the stiff block from a problem file (XDMF mesh), through the CLI: in the pair
    tables of steady sliding Σ F_x / Σ F_y = μ_f to 1e-6 and the normal force is constant to 1e-6."""
    import csv

    from dolfinx.io import XDMFFile
    from mpi4py import MPI

    from dolfinx_nnqem.cases.large_sliding import LONG_SLIDE_PRESSED_AT, long_slide
    from dolfinx_nnqem.cli import EXIT_OK, main

    if MPI.COMM_WORLD.size > 1:
        pytest.skip("the CLI test runs serially")
    mesh_of = long_slide()  # its mesh and tags: the short block squeezed to x in [0.25, 0.5]
    ct, ft = mesh_of.cell_tags, mesh_of.facet_tags
    ct.name, ft.name = "cell_tags", "facet_tags"
    with XDMFFile(MPI.COMM_SELF, tmp_path / "long.xdmf", "w") as xdmf:
        xdmf.write_mesh(mesh_of.mesh)
        xdmf.write_meshtags(ct, mesh_of.mesh.geometry)
        xdmf.write_meshtags(ft, mesh_of.mesh.geometry)
    text = (LONG_SLIDE_FILE.replace("MESH", (tmp_path / "long.xdmf").as_posix()).replace("METHOD", method)
            .replace("LAW", law))
    (tmp_path / "slide.toml").write_text(text)
    assert main(["-q", "run", str(tmp_path / "slide.toml"), "--out", str(tmp_path / "out"), "--no-pictures"]) == EXIT_OK
    ratio, normal = [], []
    for table in sorted((tmp_path / "out" / "pairs").glob("pairs_*.csv")):
        with open(table) as fh:
            rows = list(csv.DictReader(fh))
        if float(rows[0]["load_factor"]) > LONG_SLIDE_PRESSED_AT + 1e-12:
            f = np.array([[float(r["Fx_on_body1"]), float(r["Fy_on_body1"])] for r in rows]).sum(axis=0)
            ratio.append(-f[0] / f[1])
            normal.append(-f[1])
    ratio, normal = np.array(ratio), np.array(normal)
    miss = np.abs(ratio - 0.3).max() / 0.3
    spread = (normal.max() - normal.min()) / normal.mean() / 2
    print(f"\n  {method}/{law}: {len(ratio)} pair tables of steady sliding: max |F_x/F_y − μ_f|/μ_f = {miss:.1e}, "
          f"normal force {normal.mean():.6g} ± {spread:.1e}")
    assert len(ratio) == 18 and miss < 1e-6 and spread < 1e-6


def test_iterative_linear_solver_in_current_geometry():
    """The monolithic solver's Krylov path (made again, like the direct one, when the pairs change):
    the frictional block slide ends with the direct solver's force."""
    from dolfinx_nnqem.solvers.options import MonolithicOptions

    forces = []
    for linear_solver in ("direct", "iterative"):
        problem = sliding_blocks(slide=0.4, mu_f=0.3)
        with make_solver("monolithic", problem, OPTIONS, monolithic=MonolithicOptions(linear_solver=linear_solver)) as s:
            solve_load_steps(problem, s, 12)
        forces.append(slave_force(problem))
    error = np.linalg.norm(forces[1] - forces[0]) / np.linalg.norm(forces[0])
    print(f"\n  direct F = {forces[0]}, iterative F = {forces[1]}: {error:.1e} (tolerance 1e-8)")
    assert error < 1e-8


def test_node_to_node_past_the_slip_limit_stops_naming_the_interface():
    """Matching blocks (node-to-node pairs, geometry = "auto") dragged 0.4 facet sizes: node-to-node pairs
    cannot follow the bodies, so the first state slid past 0.25 facet sizes is not committed; the run
    stops there, naming the interface and suggesting node-to-surface."""
    from mpi4py import MPI

    from dolfinx_nnqem.problem import ContactProblem, Dirichlet
    from dolfinx_nnqem.cases.geometries import BlockStackTags as T
    from dolfinx_nnqem.cases.geometries import build_block_stack
    from dolfinx_nnqem.cases.large_sliding import MATERIAL

    mesh, ct, ft = build_block_stack(MPI.COMM_WORLD, 1.0, 1.0, [0.5, 0.5], [(4, 2, 4), (4, 2, 4)])
    drag = 0.1  # 0.4 × the facet size 0.25
    problem = ContactProblem(
        mesh, ct, ft, materials=MATERIAL,
        dirichlet=[Dirichlet(T.bottom(1)), Dirichlet(T.top(2), -0.01, [1], amplitude=lambda l: min(1.0, 2 * l)),
                   Dirichlet(T.top(2), drag, [0], amplitude=lambda l: max(0.0, 2 * l - 1.0)),
                   Dirichlet(T.top(2), 0.0, [2])],
        contact=Contact(T.top(1), T.bottom(2), mu_f=0.0))
    committed = []
    with make_solver("monolithic", problem, OPTIONS) as solver:
        with pytest.raises(ConvergenceError) as error:
            solve_load_steps(problem, solver, 8, callbacks=[lambda r: committed.append(r.load_factor)])
    message = str(error.value)
    print(f"\n  {problem.contact.interfaces[0].pairs.kind}: committed {committed}; {message}")
    assert committed == [0.125, 0.25, 0.375, 0.5, 0.625, 0.75]  # 0.75: slid 0.05, 0.2 facet sizes
    assert error.value.failure["load_factor"] == 0.875 and error.value.failure["stale_geometry"] == ["201-102"]
    assert "contact 201-102 (node-to-node, reference geometry): the surfaces slid 0.075" in message
    assert "0.3 × the facet size 0.25 (more than 0.25) at load factor 0.875" in message
    assert "(use discretisation = 'node-to-surface' or 'mortar' for large sliding)" in message


def test_problem_file_refuses_an_unknown_geometry(tmp_path):
    from dolfinx_nnqem.problem_file import ProblemFileError, load_problem_file

    (tmp_path / "m.msh").write_text("")
    text = BLOCKS_FILE.replace("MESH", (tmp_path / "m.msh").as_posix()).replace("METHOD", "monolithic").replace(
        "LAW", "polar").replace('geometry = "current"', 'geometry = "deformed"')
    (tmp_path / "p.toml").write_text(text)
    with pytest.raises(ProblemFileError, match=r"\[contact\]\.geometry = 'deformed': expected one of auto, reference, current"):
        load_problem_file(tmp_path / "p.toml")


@pytest.mark.parametrize("cell_type", ["tetrahedron", "hexahedron"])
@pytest.mark.parametrize("discretisation", ["node-to-surface", "mortar"])
def test_current_geometry_takes_every_kind_of_pairs_with_degree_2(cell_type, discretisation):
    """Issue 41 lifted the degree-2 refusals of the current geometry (rigid obstacles:
    tests/integration/test_large_sliding_degree2.py; node-to-surface and mortar:
    test_large_sliding_nts_degree2.py, test_large_sliding_mortar_degree2.py): both kinds of surface
    pairs build on Q2 hexahedra and P2 tetrahedra and follow the bodies from the start."""
    from mpi4py import MPI

    from dolfinx_nnqem.cases.large_sliding import MATERIAL, T
    from dolfinx_nnqem.problem import ContactProblem, Dirichlet
    from dolfinx_nnqem.cases.geometries import build_block_stack

    mesh, ct, ft = build_block_stack(MPI.COMM_WORLD, 1.0, 1.0, [0.5, 0.5], [(2, 1, 2), (2, 1, 2)], cell_type=cell_type)
    contact = Contact(T.top(1), T.bottom(2), mu_f=0.0, discretisation=discretisation, geometry="current")
    problem = ContactProblem(mesh, ct, ft, materials=MATERIAL, dirichlet=[Dirichlet(T.bottom(1)), Dirichlet(T.top(2))],
                             degree=2, contact=contact)
    assert problem.contact is not None and problem.contact.geometry.following == [True]
    assert problem.contact.interfaces[0].pairs.kind == discretisation


def test_default_r_is_the_softer_sides(monkeypatch):
    """r = E h with E the softer body's modulus at the interface: the slider's (10³) beside a long block
    of 10⁸, the strip's beside a rigid punch; an r given is checked against the same E h (10⁻⁵ E h is
    accepted, though 10⁻¹⁰ of the stiffer side's; 10⁻⁷ E h is refused, naming the range)."""
    from dolfinx_nnqem.cases import large_sliding
    from dolfinx_nnqem.cases.large_sliding import LONG_SLIDE_STIFF_MASTER, ironing, long_slide

    for problem in (long_slide(master=LONG_SLIDE_STIFF_MASTER), ironing(8)):
        (interface,) = problem.contact.interfaces
        assert interface.r == pytest.approx(1.0e3 * problem.characteristic_length(), rel=1e-14)
    Eh = 1.0e3 * long_slide().characteristic_length()
    original = large_sliding.Contact
    monkeypatch.setattr(large_sliding, "Contact", lambda *a, **k: original(*a, r=1e-5 * Eh, **k))
    assert long_slide(master=LONG_SLIDE_STIFF_MASTER).contact.interfaces[0].r == 1e-5 * Eh
    monkeypatch.setattr(large_sliding, "Contact", lambda *a, **k: original(*a, r=1e-7 * Eh, **k))
    with pytest.raises(ValueError, match=r"is 1e-07 × E h .*softer body's Young's modulus at the interface"):
        long_slide(master=LONG_SLIDE_STIFF_MASTER)

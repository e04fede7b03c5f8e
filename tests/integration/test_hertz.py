"""V6 Hertz-like contact and V7 Cattaneo–Mindlin partial slip (``verification.md``).

Two identical elastic blocks meet on the plane y = 0 through node-to-node pairs on matching
meshes; the initial gap g0 = (x² + z²)/(2R) makes the pair set a sphere of radius R on a flat
(relative curvature 1/R). Body 1's bottom is clamped; body 2's top is displacement-controlled
(u_y = −δ, u_x = u_z = 0; for V7 u_x follows a growing drag), so that K is never singular
although body 2 touches body 1 in one point at the start. The configuration is symmetric under
y → −y with the bodies swapped, so identical materials transmit no friction under the normal
load (Dundurs' β = 0, as Hertz and Mindlin assume).

Units: mm, N, MPa. The meshes are structured hexahedra, uniform (size h) over the contact zone
(|x|, |z| ≤ 1.25 a and 0.5 a deep on both sides) and graded geometrically (ratio 1.3) out to
the block faces 6 a away, so that the blocks are half-spaces to a few tenths of a per cent.

Measurements (``docs/verification-hertz.md`` gives the reasoning):

- F: the total normal force, Σ p_n over the pairs (× 4 for the quarter model, × 2 for the half
  model); equilibrium: it equals the reaction of body 2's top and of body 1's bottom.
- p0: the pressure of the centre pair, p_n / A (A the pair's tributary area ∫ N_a dA).
- a: the radius of the Hertz distribution (with the measured F, so p0 = 3F/(2πa²)) whose
  consistent nodal forces ∫ p_Hertz N_a dA best fit the pair forces (least squares). Node-to-
  node forces are tributary integrals of the pressure: an edge pair's force divided by its
  area is not the local pressure, and the outermost closed pair lies up to about half an
  element outside a, so neither serves as a 5 % measure of a on a mesh of a few elements
  across the contact. Both are printed.
- c (V7): the stick–slip boundary, half way between the outermost sticking pair and the
  innermost slipping pair.
"""

import time

import numpy as np
import pytest
from mpi4py import MPI

from dolfinx_nnqem.cases.hertz import NodalLoads, hertz_contact
from dolfinx_nnqem.cases.hertz import measure_hertz as _measure
from dolfinx_nnqem.material import VonMises
from dolfinx_nnqem.cases.geometries import StackedBlocksTags as T
from dolfinx_nnqem.cases.geometries import build_graded_contact_blocks
from dolfinx_nnqem.solvers.monolithic import MonolithicSolver
from dolfinx_nnqem.problem import Contact, ContactProblem, Dirichlet
from dolfinx_nnqem.solvers import SolverOptions
from dolfinx_nnqem.io import pair_table, reactions
from dolfinx_nnqem.solvers import solve_load_steps

E, NU = 210e3, 0.3  # MPa
MATERIAL = VonMises(E=E, nu=NU)  # σ_y0 = inf: elastic
E_STAR = E / (2.0 * (1.0 - NU**2))  # 1/E* = (1 − ν1²)/E1 + (1 − ν2²)/E2
R_SPHERE = 50.0  # mm
A_NOMINAL = 1.0  # mm: the contact radius the approach DELTA gives (about)
DELTA = 0.0185  # mm: prescribed approach of body 2's top
BLOCK = 6.0  # mm: half width, depth and height of each block (≥ 6 a)
MU_F = 0.3


# -- the model ---------------------------------------------------------------------------------
def hertz_mesh(h: float, half: bool):
    """Two blocks meeting at y = 0, graded towards x = z = 0 (quarter model, or half with ``half``)."""
    return build_graded_contact_blocks(MPI.COMM_WORLD, h, fine_width=1.25 * A_NOMINAL,
                                       fine_depth=0.5 * A_NOMINAL, block=BLOCK, half=half)


def hertz_problem(h: float, *, half: bool = False, mu_f: float = 0.0, drag: float = 0.0,
                  normal=None, tangential=None, law: str = "alart-curnier"):
    """The V6/V7 problem; ``normal``/``tangential`` are the amplitudes of δ and of the drag."""
    mesh, cell_tags, facet_tags = hertz_mesh(h, half)
    dirichlet = [
        Dirichlet(T.BOTTOM),  # body 1's bottom clamped
        Dirichlet(T.TOP, -DELTA, [1], amplitude=normal),  # body 2's top: the approach ...
        Dirichlet(T.TOP, drag, [0], amplitude=tangential or (lambda ell: 0.0)),  # ... the drag
        Dirichlet(T.TOP, 0.0, [2]),
        Dirichlet(T.BODY1_ZMIN, 0.0, [2]), Dirichlet(T.BODY2_ZMIN, 0.0, [2]),  # symmetry z = 0
    ]
    if not half:  # symmetry x = 0
        dirichlet += [Dirichlet(T.BODY1_XMIN, 0.0, [0]), Dirichlet(T.BODY2_XMIN, 0.0, [0])]
    return ContactProblem(
        mesh, cell_tags, facet_tags, materials={T.BODY1: MATERIAL, T.BODY2: MATERIAL},
        dirichlet=dirichlet,
        contact=Contact(T.CONTACT1, T.CONTACT2, mu_f=mu_f, law=law,
                        initial_gap=lambda x: (x[0] ** 2 + x[2] ** 2) / (2.0 * R_SPHERE)),
    )


# -- measuring ----------------------------------------------------------------------------------
def pair_loads(problem) -> NodalLoads:
    """Tributary areas and Hertz forces at the pairs' body-1 nodes (global pair order)."""
    pairs = problem.contact.interfaces[0].pairs  # node-to-node: the body-1 nodes a_i
    return NodalLoads(problem, T.CONTACT1, pairs.gather(pairs.dofs_a.astype(np.int64)))


def hertz_reference(F: float) -> tuple[float, float]:
    """Hertz, sphere (radius R) on a flat, identical elastic materials: (a, p0) for the force F."""
    return hertz_contact(F, R_SPHERE, E_STAR)


def measure_hertz(problem, loads: NodalLoads, table: dict, symmetry: int) -> dict:
    """F, a and p0 from the pair forces (``symmetry``: 4 quarter model, 2 half model)."""
    return _measure(loads, -table["force_local_body1"][:, 0], table["position"], table["state"] != 0,
                    symmetry, R_SPHERE, E_STAR)


def equilibrium_errors(problem, table: dict) -> tuple[float, float]:
    """(|Σ p_n + R_top,y|, |Σ p_n − R_bottom,y|) / Σ p_n."""
    react = reactions(problem)
    P = -table["force_local_body1"][:, 0].sum()
    return abs(P + react[T.TOP][1]) / P, abs(P - react[T.BOTTOM][1]) / P


# -- V6 -------------------------------------------------------------------------------------------
def run_v6(h: float) -> dict:
    """Quarter model, frictionless, the approach δ in one increment."""
    t0 = time.perf_counter()
    problem = hertz_problem(h)
    loads = pair_loads(problem)
    solver = MonolithicSolver(problem, SolverOptions(rtol=1e-12, max_iterations=30))
    results = solve_load_steps(problem, solver, 1)
    table = pair_table(problem)
    m = measure_hertz(problem, loads, table, symmetry=4)
    m["equilibrium"] = max(equilibrium_errors(problem, table))
    m["friction"] = np.abs(table["force_local_body1"][:, 1:]).max() / np.abs(table["force_local_body1"][:, 0]).max()
    m.update(h=h, iterations=sum(r.iterations for r in results), pairs=problem.num_pairs,
             dofs=3 * problem.V.dofmap.index_map.size_global, time=time.perf_counter() - t0)
    return m


def print_v6(m: dict) -> None:
    print(f"  h = a/{A_NOMINAL / m['h']:.0f}: {m['dofs']} dofs, {m['pairs']} pairs ({m['closed']} closed), "
          f"{m['iterations']} iterations, {m['time']:.1f} s")
    print(f"    F = {m['F']:.3f} N; equilibrium |Σp_n − reaction| / Σp_n = {m['equilibrium']:.1e} (tolerance 1e-10)")
    print(f"    p0 = {m['p0']:.2f} MPa (Hertz {m['p0_hertz']:.2f}): {100 * m['err_p0']:+.2f} %;  centre pair "
          f"force / Hertz consistent force − 1 = {100 * m['err_f_centre']:+.2f} %")
    print(f"    a = {m['a']:.4f} mm (Hertz {m['a_hertz']:.4f}): {100 * m['err_a']:+.2f} %;  outermost closed "
          f"pair r = {m['r_closed']:.4f}, innermost open r = {m['r_open']:.4f}")


def check_v6_mesh(m: dict, five_per_cent: bool = True) -> None:
    assert m["equilibrium"] < 1e-10
    assert m["friction"] < 1e-10  # frictionless: the tangential pair forces vanish
    if five_per_cent:  # not on the coarsest mesh (2 elements across a)
        assert abs(m["err_p0"]) < 0.05 and abs(m["err_a"]) < 0.05
    # the FE contact zone ends between the last closed and the first open pair, within an element of a
    assert m["r_closed"] - m["h"] < m["a"] < m["r_open"] + m["h"]


def test_v6_hertz_contact_two_meshes():
    """Quarter model, h = a/2 and a/3: equilibrium exact, a and p0 errors fall under refinement,
    within 5 % from h = a/3 on (the demo mesh is h = a/4)."""
    runs = [run_v6(A_NOMINAL / n) for n in (2, 3)]
    print()
    for m in runs:
        print_v6(m)
    coarse, fine = runs
    check_v6_mesh(coarse, five_per_cent=False)
    check_v6_mesh(fine)
    assert abs(fine["err_a"]) < abs(coarse["err_a"])
    assert abs(fine["err_p0"]) < abs(coarse["err_p0"])
    assert abs(fine["err_f_centre"]) < abs(coarse["err_f_centre"])


@pytest.mark.slow
def test_v6_hertz_contact_demo_mesh_and_finer():
    """Quarter model, h = a/4 (the demo mesh) and a/6: within 5 %, errors still falling."""
    runs = [run_v6(A_NOMINAL / n) for n in (4, 6)]
    print()
    for m in runs:
        print_v6(m)
        check_v6_mesh(m)
    assert abs(runs[1]["err_a"]) < abs(runs[0]["err_a"])
    assert abs(runs[1]["err_f_centre"]) < abs(runs[0]["err_f_centre"])


# -- V7 -------------------------------------------------------------------------------------------
def run_v7(h: float, drag: float, tangential_increments: int) -> list[dict]:
    """Half model, μ_f = 0.3: the approach δ in one increment, then the drag of body 2's top in
    ``tangential_increments`` equal increments with δ held."""
    n = 1 + tangential_increments
    problem = hertz_problem(
        h, half=True, mu_f=MU_F, drag=drag,
        normal=lambda ell: min(n * ell, 1.0),
        tangential=lambda ell: max(n * ell - 1.0, 0.0) / tangential_increments)
    loads = pair_loads(problem)
    solver = MonolithicSolver(problem, SolverOptions(rtol=1e-12, max_iterations=30))
    out = []

    def record(result):
        table = pair_table(problem)
        f = -table["force_local_body1"]  # on body 2: (p_n, q along +x, q along −z)
        P, Q = f[:, 0].sum(), -f[:, 1].sum()  # the drag pulls +x: friction on body 2 points −x
        react = reactions(problem)
        r = np.hypot(table["position"][:, 0], table["position"][:, 2])
        stick, slip = table["state"] == 1, table["state"] == 2
        ratio = Q / (MU_F * P)
        a_hertz, _ = hertz_reference(2.0 * P)
        step = {
            "ell": result.load_factor, "iterations": result.iterations, "time": result.wall_time_s,
            "P": P, "Q": Q, "ratio": ratio, "a_hertz": a_hertz,
            "c": a_hertz * max(1.0 - ratio, 0.0) ** (1.0 / 3.0),
            "r_stick": r[stick].max() if stick.any() else 0.0,
            "r_slip": r[slip].min() if slip.any() else np.inf,
            "stick": int(stick.sum()), "slip": int(slip.sum()), "closed": int((stick | slip).sum()),
            "equilibrium": max(*equilibrium_errors(problem, table), abs(Q - react[T.TOP][0]) / P),
            "coulomb": np.max(np.hypot(f[:, 1], f[:, 2]) - MU_F * f[:, 0]) / f[:, 0].max(),
        }
        step["c_measured"] = 0.5 * (step["r_stick"] + step["r_slip"])
        if len(out) == 0:
            step["v6"] = measure_hertz(problem, loads, table, symmetry=2)
            step["friction"] = np.abs(f[:, 1:]).max() / f[:, 0].max()
        out.append(step)

    solve_load_steps(problem, solver, n, callbacks=[record])
    return out


def check_v7(steps: list[dict], h: float) -> None:
    normal, tangential = steps[0], steps[1:]
    print(f"\n  h = a/{A_NOMINAL / h:.0f}, normal stage: {normal['iterations']} iterations, F = 2P = "
          f"{2 * normal['P']:.3f} N, a_Hertz = {normal['a_hertz']:.4f} mm, a = {normal['v6']['a']:.4f} mm "
          f"({100 * normal['v6']['err_a']:+.2f} %), p0 {100 * normal['v6']['err_p0']:+.2f} %, "
          f"max |q|/max p_n = {normal['friction']:.1e}")
    assert normal["friction"] < 1e-8  # identical materials: no friction under the normal load
    assert normal["stick"] == normal["closed"]
    print(f"  {'Q/(μP)':>7s} {'c Mindlin':>9s} {'c FE':>7s} {'|Δc|/h':>7s}  outer stick / inner slip r  "
          f"stick/slip  its   time   equilibrium")
    for s in tangential:
        err = abs(s["c_measured"] - s["c"]) / h
        print(f"  {s['ratio']:7.4f} {s['c']:9.4f} {s['c_measured']:7.4f} {err:7.3f}  {s['r_stick']:.4f} / "
              f"{s['r_slip']:.4f}           {s['stick']:3d}/{s['slip']:3d}  {s['iterations']:3d} {s['time']:5.1f}s"
              f"  {s['equilibrium']:.1e}")
    for s in tangential:
        assert s["equilibrium"] < 1e-10
        assert abs(s["P"] - normal["P"]) < 1e-10 * normal["P"]  # P held
        assert s["coulomb"] < 1e-10  # |q| ≤ μ_f p_n at every pair
        assert 0.0 < s["ratio"] < 1.0
        assert abs(s["c_measured"] - s["c"]) <= h
    ratios = [s["ratio"] for s in tangential]
    assert np.all(np.diff(ratios) > 0) and ratios[-1] > 0.6  # a partial-slip path up to high Q


def test_v7_cattaneo_mindlin_stick_radius():
    """Half model, h = a/3: the stick radius follows c = a (1 − Q/(μ_f P))^(1/3) within h."""
    h = A_NOMINAL / 3
    check_v7(run_v7(h, drag=0.004, tangential_increments=4), h)


@pytest.mark.slow
def test_v7_cattaneo_mindlin_demo_mesh():
    """Half model, h = a/4 (the demo mesh), Q/(μ_f P) up to about 0.85 in 6 increments."""
    h = A_NOMINAL / 4
    check_v7(run_v7(h, drag=0.0055, tangential_increments=6), h)


def test_v10_polar_law_on_v6_v7_where_it_converges():
    """V10 on V6/V7 (half model, h = a/3): the polar law along its own load path (with cutbacks)
    and the Cartesian law along the same path give the same pair forces where the polar law
    converges; the printout says where it needs Levenberg–Marquardt steps or stops."""
    from dolfinx_nnqem.solvers import ConvergenceError
    from dolfinx_nnqem.solvers import solve_load_path

    h, increments = A_NOMINAL / 3, 3
    n = 1 + increments
    paths = dict(half=True, mu_f=MU_F, drag=0.004,
                 normal=lambda ell: min(n * ell, 1.0),
                 tangential=lambda ell: max(n * ell - 1.0, 0.0) / increments)
    polar = hertz_problem(h, law="polar", **paths)
    done = []

    def record(result):
        done.append((result.load_factor, pair_table(polar)["force_local_body1"].copy(), result.report))

    try:
        # no cutbacks, 25 iterations: enough to show where the polar form stops, cheap to run
        solve_load_steps(polar, MonolithicSolver(polar, SolverOptions(rtol=1e-12, max_iterations=25)), n,
                         callbacks=[record], max_cutbacks=0)
        stopped = None
    except ConvergenceError as error:
        stopped = str(error).splitlines()[0]
    assert done, "the polar law did not converge on the normal load"
    cartesian = hertz_problem(h, law="alart-curnier", **paths)
    forces = []
    solve_load_path(cartesian, MonolithicSolver(cartesian, SolverOptions(rtol=1e-12, max_iterations=40)),
                    [ell for ell, _, _ in done],
                    callbacks=[lambda r: forces.append(pair_table(cartesian)["force_local_body1"].copy())])
    worst = 0.0
    for (ell, f_p, report), f_c in zip(done, forces):
        diff = np.abs(f_p - f_c).max() / np.abs(f_c[:, 0]).max()
        worst = max(worst, diff)
        lm = sum(1 for rec in report.history if rec.kind == "lm")
        print(f"  ℓ = {ell:.3f}: max |Δ pair force| / max p_n = {diff:.2e}; polar iterations {report.iterations} "
              f"({lm} LM)")
    print(f"  polar law converged on {len(done)} increments (of {n} asked for); worst {worst:.2e} "
          f"(tolerance 1e-8)" + (f"; stopped: {stopped}" if stopped else ""))
    assert worst < 1e-8

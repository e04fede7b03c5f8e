"""Cost of setting up a dual mortar interface, against one Newton solve and against node-to-node.

    python benchmarks/mortar_setup.py                      # ~1.2e5 dofs, 10 201 slave nodes
    python benchmarks/mortar_setup.py --n 40 --n1 39       # quick check

Two thin elastoplastic plates pressed together (the loads and material of
``dolfinx_nnqem.cases.pressed_blocks``: clamped bottom, pressure on top, u_z = 0 on the z faces; the
pressure phase only by default): body 1 with n1 × 1 × n1 hexahedra, body 2 (the finer, the mortar
slave) with n × 1 × n, so that no interface node but the corners coincides and every slave facet
overlaps several master facets. The matching version of the same problem has n × 1 × n in both
bodies (node-to-node).

Per interface set-up (the pair-set construction, ``contact.discretisation.discretise``, run once
more after the problem is built, JIT warm) it prints the time of each phase: gathering the
surfaces on every rank, the facet search (KD-tree candidates), the clipping and integration
(one numba kernel), the rest (dual coefficients, assembly of D and M, frames, B's rows), and the
memory: the peak increase of the resident set (VmHWM after resetting it, Linux) and of the
Python/NumPy heap (tracemalloc, in a repetition: it slows NumPy-heavy code down), and the bytes
per slave node the gathered surfaces hold on each rank. The same for one Newton solve of the
monolithic solver (Newton matrix, factorisation or preconditioner, solve), and the whole run's
time for mortar and for node-to-node on the matching mesh. A Newton solve reuses the memory of the previous factorisation, so its peak RSS increase is
small; the whole run's (the first factorisation included) shows what the linear solver holds.
Asserts nothing.
"""

import argparse
import contextlib
import sys
import time
import tracemalloc
from pathlib import Path

import dolfinx_nnqem  # noqa: F401  (before dolfinx)
import numpy as np
from mpi4py import MPI

from dolfinx_nnqem.contact import discretisation as discretisation_module
from dolfinx_nnqem.contact import mortar_geometry
from dolfinx_nnqem.contact.discretisation import discretise
from dolfinx_nnqem.cases.geometries import StackedBlocksTags as T
from dolfinx_nnqem.cases.geometries import build_stacked_blocks
from dolfinx_nnqem.solvers.monolithic import MonolithicSolver
from dolfinx_nnqem.cases.pressed_blocks import DRAG, MATERIAL, PRESSURE, drag_amplitude, pressure_amplitude
from dolfinx_nnqem.problem import Contact, ContactProblem, Dirichlet, Pressure
from dolfinx_nnqem.solvers import MonolithicOptions, SolverOptions
from dolfinx_nnqem.solvers import solve_load_steps

sys.path.insert(0, str(Path(__file__).parent))
from scaling import one_newton_solve  # noqa: E402

THICKNESS = 0.04
"""Each plate's height (m): one layer of hexahedra about 4 × as tall as wide at n = 100."""


def pressed_plates(comm, n1: int, n: int, discretisation: str) -> ContactProblem:
    """Body 1 (n1 × 1 × n1 hexahedra) under body 2 (n × 1 × n); see the module docstring."""
    mesh, cell_tags, facet_tags = build_stacked_blocks(comm, 1.0, THICKNESS, THICKNESS, 1.0, n1, 1, 1, n1,
                                                       nx2=n, nz2=n)
    return ContactProblem(
        mesh, cell_tags, facet_tags, materials={T.BODY1: MATERIAL, T.BODY2: MATERIAL},
        dirichlet=[Dirichlet(T.BOTTOM), Dirichlet(T.TOP, DRAG, [0], amplitude=drag_amplitude),
                   Dirichlet(T.BODY1_ZMIN, 0.0, [2]), Dirichlet(T.BODY1_ZMAX, 0.0, [2]),
                   Dirichlet(T.BODY2_ZMIN, 0.0, [2]), Dirichlet(T.BODY2_ZMAX, 0.0, [2])],
        tractions=[Pressure(T.TOP, PRESSURE, amplitude=pressure_amplitude)],
        contact=Contact(T.CONTACT1, T.CONTACT2, mu_f=0.1, discretisation=discretisation))


# -- memory ------------------------------------------------------------------------------------------------------
def _status_kb(field: str) -> int:
    """A field of /proc/self/status in kB (VmRSS, VmHWM); 0 where there is none."""
    with contextlib.suppress(OSError):
        for line in Path("/proc/self/status").read_text().splitlines():
            if line.startswith(field + ":"):
                return int(line.split()[1])
    return 0


def _reset_peak_rss() -> bool:
    """Reset VmHWM to the current resident set (Linux ≥ 4.0); whether it worked."""
    try:
        Path("/proc/self/clear_refs").write_text("5")
    except OSError:
        return False
    return True


@contextlib.contextmanager
def measured(out: dict, comm, heap: bool = False):
    """Wall time (s, slowest rank) and peak RSS increase (MB, largest rank) of the block; with ``heap``
    the tracemalloc peak (MB) instead of the time (tracemalloc slows NumPy-heavy code down)."""
    reset = _reset_peak_rss()
    rss0 = _status_kb("VmRSS")
    if heap:
        tracemalloc.start()
    comm.Barrier()
    t0 = time.perf_counter()
    try:
        yield out
    finally:
        comm.Barrier()
        if heap:
            _, peak = tracemalloc.get_traced_memory()
            tracemalloc.stop()
            out["heap_peak_mb"] = comm.allreduce(peak / 2**20, op=MPI.MAX)
        else:
            out["time_s"] = comm.allreduce(time.perf_counter() - t0, op=MPI.MAX)
            out["rss_peak_increase_mb"] = (comm.allreduce((_status_kb("VmHWM") - rss0) / 1024, op=MPI.MAX)
                                           if reset else float("nan"))


@contextlib.contextmanager
def phase_timers(timings: dict):
    """Time the set-up's phases by wrapping the functions the pair-set construction calls."""
    wrapped = [(discretisation_module, "gather_surfaces", "gather"),
               (mortar_geometry, "candidate_couples", "search"),
               (mortar_geometry, "_integrate_couples", "clip + integrate")]
    originals = []
    for module, name, label in wrapped:
        original = getattr(module, name)
        originals.append((module, name, original))

        def timed(*args, _original=original, _label=label, **kwargs):
            t0 = time.perf_counter()
            try:
                return _original(*args, **kwargs)
            finally:
                timings[_label] = timings.get(_label, 0.0) + time.perf_counter() - t0

        setattr(module, name, timed)
    try:
        yield timings
    finally:
        for module, name, original in originals:
            setattr(module, name, original)


def gathered_bytes(problem) -> int:
    """Bytes of the gathered contact surfaces (both sides) that every rank holds."""
    c = problem.contact.interfaces[0].contact
    surfaces = discretisation_module.gather_surfaces(problem.V, problem.facet_tags, (c.surface1, c.surface2))
    facets = surfaces.facets
    total = sum(getattr(facets, f).nbytes for f in facets.__dataclass_fields__)
    for nodes in surfaces.nodes:
        total += sum(getattr(nodes, f).nbytes for f in nodes.__dataclass_fields__
                     if isinstance(getattr(nodes, f), np.ndarray))
    return total


# -- one case ------------------------------------------------------------------------------------------------------
def run_case(comm, n1: int, n: int, discretisation: str, increments: int, final_load_factor: float,
             linear_solver: str) -> dict:
    r = {"discretisation": discretisation, "n1": n1, "n": n}
    t0 = time.perf_counter()
    problem = pressed_plates(comm, n1, n, discretisation)
    r["problem_build_s"] = comm.allreduce(time.perf_counter() - t0, op=MPI.MAX)
    r["dofs"] = problem.V.dofmap.index_map.size_global * 3
    r["pairs"] = problem.num_pairs
    r["describe"] = problem.contact.describe()[0]
    c = problem.contact.interfaces[0].contact

    # the pair set once more, JIT warm, phases timed; then again under tracemalloc
    phases: dict[str, float] = {}
    setup: dict = {}
    with phase_timers(phases), measured(setup, comm):
        pairs = discretise(problem.V, problem.facet_tags, c.surface1, c.surface2, discretisation)
    del pairs
    with measured(setup, comm, heap=True):
        pairs = discretise(problem.V, problem.facet_tags, c.surface1, c.surface2, discretisation)
    r["setup"] = setup
    r["phases_s"] = {k: comm.allreduce(v, op=MPI.MAX) for k, v in phases.items()}
    r["slave_nodes"] = int(getattr(pairs, "num_slave_nodes", pairs.num_global))
    if discretisation != "node-to-node":  # node-to-node gathers only node positions (contact/pairs.py)
        r["gathered_bytes"] = comm.allreduce(gathered_bytes(problem), op=MPI.MAX)
    del pairs

    solver = MonolithicSolver(problem, SolverOptions(max_iterations=40), MonolithicOptions(linear_solver=linear_solver))
    run: dict = {}
    with measured(run, comm):
        results = solve_load_steps(problem, solver, increments, final_load_factor=final_load_factor)
    r["run"] = run
    r["run_s"] = run["time_s"]
    r["iterations"] = [res.iterations for res in results]
    newton: dict = {}
    with measured(newton, comm):
        one_newton_solve(problem, solver)
    with measured(newton, comm, heap=True):
        one_newton_solve(problem, solver)
    r["newton"] = newton
    r["plastic_points"] = problem.state.count_plastic_points()
    return r


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--n", type=int, default=100, help="body 2's (slave) hexahedra per side")
    parser.add_argument("--n1", type=int, default=99, help="body 1's hexahedra per side (non-matching run)")
    parser.add_argument("--increments", type=int, default=2)
    parser.add_argument("--final-load-factor", type=float, default=0.5, help="0.5: the pressure phase only")
    parser.add_argument("--linear-solver", default="direct", choices=["direct", "iterative"])
    args = parser.parse_args()
    comm = MPI.COMM_WORLD
    rank0 = comm.rank == 0

    t0 = time.perf_counter()  # JIT warm-up: FFCx forms, numba kernels (mortar geometry, laws)
    warm = pressed_plates(comm, 3, 4, "mortar")
    solve_load_steps(warm, MonolithicSolver(warm), 1, final_load_factor=0.25)
    if rank0:
        print(f"{comm.size} rank(s); JIT warm-up {time.perf_counter() - t0:.1f} s; {args.increments} increments to "
              f"load factor {args.final_load_factor}, monolithic solver, {args.linear_solver} linear solver", flush=True)

    cases = [run_case(comm, args.n1, args.n, "mortar", args.increments, args.final_load_factor, args.linear_solver),
             run_case(comm, args.n, args.n, "node-to-node", args.increments, args.final_load_factor,
                      args.linear_solver)]
    if not rank0:
        return
    for r in cases:
        print(f"\n{r['discretisation']}: body 1 {r['n1']}², body 2 {r['n']}² facets; {r['dofs']} dofs, "
              f"{r['pairs']} pairs of {r['slave_nodes']} slave nodes; {r['describe']}")
        print(f"  problem build {r['problem_build_s']:.2f} s; Newton iterations {r['iterations']}; "
              f"plastic Gauss points at the end {r['plastic_points']}")
    header = f"{'':<34}{'time (s)':>10}{'RSS peak +MB':>14}{'heap peak MB':>14}"
    print("\n" + header)
    for r in cases:
        s, nw = r["setup"], r["newton"]
        print(f"{r['discretisation'] + ' pair set':<34}{s['time_s']:>10.3f}{s['rss_peak_increase_mb']:>14.1f}"
              f"{s['heap_peak_mb']:>14.1f}")
        for k, v in r["phases_s"].items():
            print(f"{'  ' + k:<34}{v:>10.3f}")
        if r["phases_s"]:
            print(f"{'  the rest':<34}{s['time_s'] - sum(r['phases_s'].values()):>10.3f}")
        print(f"{'  one Newton solve':<34}{nw['time_s']:>10.3f}{nw['rss_peak_increase_mb']:>14.1f}"
              f"{nw['heap_peak_mb']:>14.1f}")
        print(f"{'  whole run':<34}{r['run_s']:>10.2f}{r['run']['rss_peak_increase_mb']:>14.1f}")
        print(f"{'  pair set / one Newton solve':<34}{s['time_s'] / nw['time_s']:>10.3f}")
        if "gathered_bytes" in r:
            print(f"{'  gathered surfaces, B/slave node':<34}{r['gathered_bytes'] / r['slave_nodes']:>10.0f}"
                  f"   ({r['gathered_bytes'] / 2**20:.2f} MB on every rank)")
    m, nn = cases
    print(f"\nwhole run, mortar / node-to-node on the matching mesh: {m['run_s'] / nn['run_s']:.2f} "
          f"({m['run_s']:.1f} s / {nn['run_s']:.1f} s)")


if __name__ == "__main__":
    main()

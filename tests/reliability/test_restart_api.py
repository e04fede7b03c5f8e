"""Checkpoint and restart from Python (the calls docs/reliability.md shows): a run interrupted
after increment 3 and resumed in a fresh problem equals an uninterrupted run to 1e-12 (degree 2
too: its ``fields_p2.pvd`` then lists every increment once, the last one equal to u)."""

import numpy as np
import pytest

from dolfinx_nnqem.io import checkpoint
from dolfinx_nnqem.io import ResultsWriter
from dolfinx_nnqem.solvers import make_solver
from dolfinx_nnqem.solvers import solve_load_steps
from dolfinx_nnqem.cases.two_beams import two_beams_problem


def _state(problem):
    st, c = problem.state, problem.contact
    return {"u": problem.u.x.array.copy(), "sigma": st.sigma_n.x.array.copy(), "p": st.p_n.x.array.copy(),
            "z": c.z_n.copy(), "w": c.w_n.copy()}


@pytest.mark.parametrize("method, degree", [("monolithic", 1), ("nneqm2", 1), ("monolithic", 2)])
def test_python_restart_equals_an_uninterrupted_run(tmp_path, method, degree):
    n = 6
    ref = two_beams_problem(law="alart-curnier", degree=degree)
    solve_load_steps(ref, make_solver(method, ref), n)
    expected = _state(ref)

    out = tmp_path / "run"
    first = two_beams_problem(law="alart-curnier", degree=degree)
    writer = ResultsWriter(first, method, out, n)

    checkpointer = checkpoint.Checkpointer(out, writers=[writer])

    def checkpoint_then_stop_after_3(problem, stepper_state, result):
        checkpointer(problem, stepper_state, result)
        if result.index == 3:
            raise KeyboardInterrupt  # as Ctrl-C would, after increment 3's checkpoint

    with pytest.raises(KeyboardInterrupt):
        solve_load_steps(first, make_solver(method, first), n, callbacks=[writer],
                         checkpoint=checkpoint_then_stop_after_3)
    writer.close()

    second = two_beams_problem(law="alart-curnier", degree=degree)
    writer = ResultsWriter(second, method, out, n, resume=True)
    state, meta = checkpoint.restore(second, out)
    writer.resume(meta["writers"][0])
    results = solve_load_steps(second, make_solver(method, second), n, callbacks=[writer], resume=state,
                               checkpoint=checkpoint.Checkpointer(out, writers=[writer]))
    writer.close()
    got = _state(second)
    diffs = {k: float(np.max(np.abs(got[k] - expected[k])) / max(np.max(np.abs(expected[k])), 1e-300))
             for k in expected}
    print(f"\n  {method}: resumed at increment {state.index}, ran {[r.index for r in results]}; "
          f"relative differences {', '.join(f'{k} {v:.1e}' for k, v in diffs.items())}; "
          f"summary increments {len(writer.summary.data['load_factors'])}")
    assert state.index == 3 and [r.index for r in results] == [4, 5, 6]
    assert all(v <= 1e-12 for v in diffs.values())
    assert len(writer.summary.data["load_factors"]) == n and writer.summary.data["status"] == "completed"

    if degree == 2:
        import pyvista
        from mpi4py import MPI

        reader = pyvista.get_reader(str(out / "fields_p2.pvd"))
        print(f"  fields_p2.pvd after the restart: steps {reader.time_values}")
        assert reader.time_values == pytest.approx(writer.summary.data["load_factors"])
        if MPI.COMM_WORLD.size == 1:
            reader.set_active_time_value(reader.time_values[-1])
            u = reader.read()[0].point_data["u"]
            assert np.abs(np.abs(u).max() - np.abs(got["u"]).max()) <= 1e-12 * np.abs(got["u"]).max()

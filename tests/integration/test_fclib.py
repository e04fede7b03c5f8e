"""FCLIB export of NNEQM1's condensed contact problem (``dolfinx_nnqem.io.fclib``).

Round trip (the file reads back to the same C, w_free and q), the HDF5 layout against the one
of FrictionalContactLibrary/fclib ``src/fclib.h`` (b8845f7), the equivalence of FCLIB's
Coulomb problem and our pair law under the q/W mapping, and a real NNEQM1 inner problem of the
two-beam benchmark whose converged forces solve the exported problem.
"""

import subprocess
import sys
import textwrap

import numpy as np
import pytest

from dolfinx_nnqem import compat
from dolfinx_nnqem.io import fclib
from dolfinx_nnqem.contact.laws import get_law

h5py = fclib.h5py  # imported by fclib so that it survives DOLFINx's HDF5 (see fclib._import_h5py)


def _random_condensed(nc=7, seed=1, zero_direction=True):
    """A condensed problem with the shapes and signs of NNEQM1's ``last_condensed``."""
    rng = np.random.default_rng(seed)
    A = rng.standard_normal((3 * nc, 3 * nc))
    C = (A @ A.T / (3 * nc) + np.eye(3 * nc)) * 1e-9  # m/N, SPD
    if zero_direction:  # a direction fixed by the supports: zero row and column
        C[4, :] = 0.0
        C[:, 4] = 0.0
    return {"C": C, "w_free": rng.standard_normal(3 * nc) * 1e-5, "w_m": rng.standard_normal(3 * nc) * 1e-4,
            "lam_m": rng.standard_normal(3 * nc) * 1e3, "mu_f": rng.uniform(0.1, 0.8, nc),
            "g0": rng.uniform(0, 1e-4, nc), "w_prev": rng.standard_normal((nc, 3)) * 1e-4, "r": 4e9}


def _q_by_hand(c):
    """q written out pair by pair from the formulation (independent of fclib's vector code)."""
    nc = c["g0"].size
    q = np.empty(3 * nc)
    for i in range(nc):
        for k in range(3):
            row = 3 * i + k
            w_lin = c["w_m"][row] + c["w_free"][row] - sum(c["C"][row, j] * c["lam_m"][j] for j in range(3 * nc))
            if k == 0:
                q[row] = c["g0"][i] + w_lin  # gap g = g0 + w_n
            else:
                q[row] = w_lin - c["w_prev"][i, k]  # slip s = w_t - w^n_t
    return q


def test_round_trip(tmp_path):
    c = _random_condensed()
    path = fclib.write_condensed_problem(tmp_path / "p.hdf5", c, solution=c["lam_m"] * 0.5,
                                         description="round trip", number_of_dofs=123)
    d = fclib.read_fclib_local(path)
    q_ref = _q_by_hand(c)
    err_W = np.abs(d["W"] - c["C"]).max() / np.abs(c["C"]).max()
    err_q = np.abs(d["q"] - q_ref).max() / np.abs(q_ref).max()
    back = d["condensed"]
    print(f"\n  W vs C: max rel diff {err_W:.1e} (nzmax {d['W_storage']['nzmax']} of {c['C'].size}); "
          f"q vs hand-written q: {err_q:.1e}; stored C, w_free bitwise equal: "
          f"{np.array_equal(back['C'], c['C'])}, {np.array_equal(back['w_free'], c['w_free'])}")
    assert err_W == 0.0  # the values are stored, not recomputed
    assert err_q <= 1e-15
    assert d["W_storage"]["nzmax"] == np.count_nonzero(c["C"])  # exact zeros are not stored
    for key in ("C", "w_free", "w_m", "lam_m", "g0", "w_prev", "mu_f"):
        assert np.array_equal(back[key], c[key]), key
    assert back["r"] == c["r"] and back["fclib_reference"] == fclib.FCLIB_REFERENCE
    assert np.array_equal(d["mu"], c["mu_f"]) and d["spacedim"] == 3 and d["number_of_contacts"] == 7
    assert d["info"]["description"] == "round trip" and d["info"]["title"] == fclib.DEFAULT_TITLE
    assert int(d["info"]["attributes"]["numberOfDegreeOfFreedom"][0]) == 123
    r = c["lam_m"] * 0.5
    assert np.array_equal(d["solution"]["r"], r)
    assert np.allclose(d["solution"]["u"], c["C"] @ r + q_ref, rtol=0, atol=1e-15 * np.abs(q_ref).max())
    assert len(d["guesses"]) == 1 and np.array_equal(d["guesses"][0]["r"], c["lam_m"])
    assert d["W_info"]["rank"] == 3 * 7 - 1  # the zero direction
    # the solution's u is NNEQM1's w(λ) shifted by (g0, -w_prev_t): check one pair by hand
    w = c["w_m"] + c["w_free"] + c["C"] @ (r - c["lam_m"])
    assert np.isclose(d["solution"]["u"][3], c["g0"][1] + w[3], rtol=1e-13)
    assert np.isclose(d["solution"]["u"][5], w[5] - c["w_prev"][1, 2], rtol=1e-13)


def _dtype_of(ds):
    return ds.id.get_type()


def test_layout_matches_fclib_source(tmp_path):
    """Names, dtypes, shapes, dataset-vs-attribute and string types as fclib.h writes them.

    fclib.h (b8845f7): fclib_write_local -> /fclib_local/{spacedim, W, vectors, info};
    write_matrix -> nzmax, m, n, nz, p, i, x (+ comment, conditioning, determinant, rank) with
    H5LTmake_dataset_int (rank-1 H5T_NATIVE_INT) and _double (H5T_NATIVE_DOUBLE);
    write_local_vectors -> q, mu; write_problem_info -> title, description, math_info with
    H5LTmake_dataset_string (scalar H5T_C_S1, size strlen+1, NULLTERM); fclib_write_solution ->
    /solution/{u, r}; fclib_write_guesses -> /guesses/number_of_guesses, /guesses/1/{u, r}.
    """
    c = _random_condensed(nc=4, seed=3)
    path = fclib.write_condensed_problem(tmp_path / "p.hdf5", c, solution=c["lam_m"], title="t",
                                         description="", math_info="m")  # "" is written as ""
    m = 12
    with h5py.File(path, "r") as f:
        assert set(f) == {"fclib_local", "solution", "guesses", "dolfinx_nnqem"}
        assert "fclib_global" not in f  # fclib's read_nvnunrnl looks for a global problem first
        assert set(f["fclib_local"]) == {"spacedim", "W", "vectors", "info"}
        W = f["fclib_local/W"]
        assert set(W) == {"nzmax", "m", "n", "nz", "p", "i", "x", "comment", "conditioning", "determinant",
                          "rank"}
        nzmax = int(W["nzmax"][0])
        expected = {  # name: (numpy dtype, shape)
            "fclib_local/spacedim": ("<i4", (1,)),
            "fclib_local/W/nzmax": ("<i4", (1,)), "fclib_local/W/m": ("<i4", (1,)),
            "fclib_local/W/n": ("<i4", (1,)), "fclib_local/W/nz": ("<i4", (1,)),
            "fclib_local/W/p": ("<i4", (m + 1,)), "fclib_local/W/i": ("<i4", (nzmax,)),
            "fclib_local/W/x": ("<f8", (nzmax,)),
            "fclib_local/W/conditioning": ("<f8", (1,)), "fclib_local/W/determinant": ("<f8", (1,)),
            "fclib_local/W/rank": ("<i4", (1,)),
            "fclib_local/vectors/q": ("<f8", (m,)), "fclib_local/vectors/mu": ("<f8", (m // 3,)),
            "solution/u": ("<f8", (m,)), "solution/r": ("<f8", (m,)),
            "guesses/number_of_guesses": ("<i4", (1,)), "guesses/1/u": ("<f8", (m,)),
            "guesses/1/r": ("<f8", (m,)),
        }
        for name, (dtype, shape) in expected.items():
            ds = f[name]
            assert isinstance(ds, h5py.Dataset), name
            assert ds.dtype == np.dtype(dtype) and ds.shape == shape, (name, ds.dtype, ds.shape)
            assert ds.dtype == np.dtype(np.intc if dtype == "<i4" else np.float64)  # NATIVE_INT/DOUBLE
            assert len(ds.attrs) == 0, name  # everything is a dataset, nothing an attribute
        assert set(f["solution"]) == {"u", "r"}  # local problem: no v, no l
        assert set(f["guesses"]) == {"number_of_guesses", "1"}
        assert int(W["m"][0]) == int(W["n"][0]) == m and int(W["nz"][0]) == -1
        assert int(f["fclib_local/spacedim"][0]) == 3
        # CSC as CSparse stores it: column pointers p (n+1), row indices i, values x
        p, i, x = W["p"][()], W["i"][()], W["x"][()]
        assert p[0] == 0 and p[-1] == nzmax and np.all(np.diff(p) >= 0)
        dense = np.zeros((m, m))
        for col in range(m):
            rows = i[p[col]:p[col + 1]]
            assert np.all(np.diff(rows) > 0)  # sorted, no duplicates
            dense[rows, col] = x[p[col]:p[col + 1]]
        assert np.array_equal(dense, c["C"])
        # strings exactly as H5LTmake_dataset_string makes them
        strings = {"fclib_local/info/title": "t", "fclib_local/info/description": "",
                   "fclib_local/info/math_info": "m", "fclib_local/W/comment": None}
        for name, text in strings.items():
            ds = f[name]
            tid = _dtype_of(ds)
            assert ds.shape == () and tid.get_class() == h5py.h5t.STRING, name
            assert not tid.is_variable_str() and tid.get_strpad() == h5py.h5t.STR_NULLTERM, name
            assert tid.get_cset() == h5py.h5t.CSET_ASCII, name
            raw = ds.id.get_storage_size()
            if text is not None:
                assert tid.get_size() == len(text) + 1 == raw, (name, tid.get_size())
                assert fclib._read_string(ds) == text
        info = fclib.read_fclib_local(path)["W_info"]
        print(f"\n  layout: {len(expected)} numeric datasets and 4 strings as in fclib.h; W CSC nzmax "
              f"{nzmax}; W info: rank {info['rank']}, cond {info['conditioning']:.3g}")


def _coulomb_pair_states(nc, rng):
    """(u, r) per contact satisfying Coulomb's law: open, stick and slip in turn."""
    u, r = np.zeros((nc, 3)), np.zeros((nc, 3))
    mu = rng.uniform(0.2, 0.6, nc)
    states = []
    for i in range(nc):
        kind = ("open", "stick", "slip")[i % 3]
        states.append(kind)
        if kind == "open":
            u[i] = (rng.uniform(1e-6, 1e-4), *rng.standard_normal(2) * 1e-5)
        elif kind == "stick":
            r[i, 0] = rng.uniform(1e3, 1e4)
            t = rng.standard_normal(2)
            r[i, 1:] = 0.7 * mu[i] * r[i, 0] * t / np.linalg.norm(t)
        else:
            r[i, 0] = rng.uniform(1e3, 1e4)
            s = rng.standard_normal(2) * 1e-5
            u[i, 1:] = s
            r[i, 1:] = -mu[i] * r[i, 0] * s / np.linalg.norm(s)  # q = -mu p_n s/|s|
    return u, r, mu, states


def test_fclib_solutions_are_pair_law_solutions(tmp_path):
    """Under W = C and q of the mapping, FCLIB's Coulomb problem and our Alart–Curnier pair law
    (``contact.laws``, used by NNEQM1) have the same solution: a λ built to satisfy Coulomb's law
    in every state (open, stick, slip) has zero FCLIB error and zero law residual H."""
    rng = np.random.default_rng(7)
    nc = 9
    c = _random_condensed(nc=nc, seed=11, zero_direction=False)
    u_star, r_star, mu, states = _coulomb_pair_states(nc, rng)
    c["mu_f"] = mu
    # choose w_free so that the NNEQM1 relation gives (gap, slip) = u_star at λ = r_star
    lam = r_star.reshape(-1)
    d_shift = np.column_stack((c["g0"], -c["w_prev"][:, 1], -c["w_prev"][:, 2])).reshape(-1)
    c["w_free"] = u_star.reshape(-1) - d_shift - c["w_m"] - c["C"] @ (lam - c["lam_m"])
    path = fclib.write_condensed_problem(tmp_path / "s.hdf5", c, solution=lam)
    d = fclib.read_fclib_local(path)
    err_fclib = fclib.complementarity_error(d["W"], d["q"], d["mu"], d["solution"]["r"])
    merit = fclib.fclib_merit(d["W"], d["q"], d["mu"], d["solution"]["r"])
    err_u = np.abs(d["solution"]["u"] - u_star.reshape(-1)).max() / np.abs(u_star).max()
    # our pair law at w(λ) = w_m + w_free + C (λ - λ_m)
    law = get_law("alart-curnier")
    w = (c["w_m"] + c["w_free"] + c["C"] @ (lam - c["lam_m"])).reshape(nc, 3)
    ev = law.evaluate(w, c["w_prev"], r_star, c["g0"], mu, c["r"])
    err_law = np.abs(ev.H).max() / np.abs(r_star).max()
    # negative controls: a wrong force, and the slip measured with the wrong sign of w_prev
    bad = lam.copy()
    bad[3 * states.index("slip") + 1] *= 0.5
    err_bad = fclib.complementarity_error(d["W"], d["q"], d["mu"], bad)
    wrong = fclib.fclib_local_from_condensed(c["C"], c["w_free"], mu, w_m=c["w_m"], lam_m=c["lam_m"],
                                             g0=c["g0"], w_prev=-c["w_prev"])
    err_wrong_q = fclib.complementarity_error(wrong["W"], wrong["q"], mu, lam)
    viol = fclib.coulomb_violations(d["W"], d["q"], d["mu"], lam)
    print(f"\n  states {viol['contacts']}; FCLIB error at λ*: {err_fclib:.1e} (fclib merit {merit:.1e}); "
          f"pair-law |H|/|λ| {err_law:.1e}; u = (g, s): {err_u:.1e}; controls: wrong force {err_bad:.1e}, "
          f"+w_prev in q {err_wrong_q:.1e}")
    assert viol["contacts"] == {"open": 3, "stick": 3, "slip": 3}
    assert err_fclib < 1e-12 and merit < 1e-9 and err_law < 1e-12 and err_u < 1e-10
    assert err_bad > 1e-3 and err_wrong_q > 1e-3


# -- a real NNEQM1 inner problem ------------------------------------------------------------------
def _two_beams_nneqm1(law):
    from dolfinx_nnqem.solvers import solve_load_steps
    from dolfinx_nnqem.solvers import make_solver
    from dolfinx_nnqem.cases.two_beams import two_beams_problem

    p = two_beams_problem(law=law)
    s = make_solver("nneqm1", p)
    # 12 increments: the polar law's inner solve with 3 large ones is sensitive to rounding (it
    # fails on Debian's reference BLAS, converges with OpenBLAS)
    solve_load_steps(p, s, 12)
    return p, s


def _check_two_beams(p, s, path):
    c = s.last_condensed.as_dict()
    d = fclib.read_fclib_local(path)
    r, u = d["solution"]["r"], d["solution"]["u"]
    # the converged contact forces are the inner solution of the last condensed problem
    lam = p.contact.gather(p.contact.force())
    assert np.array_equal(r, lam.reshape(-1))
    err_W = np.abs(d["W"] - c["C"]).max()
    q_ref = _q_by_hand(c)
    err_q = np.abs(d["q"] - q_ref).max() / np.abs(q_ref).max()
    # FCLIB's u is the physical (gap, incremental slip) of the converged displacement field
    w = p.contact.gather(p.contact.w_n)  # committed at the end of the increment
    phys = np.column_stack((c["g0"] + w[:, 0], w[:, 1:] - c["w_prev"][:, 1:])).reshape(-1)
    err_u = np.abs(u - phys).max() / np.abs(phys).max()
    err = fclib.complementarity_error(d["W"], d["q"], d["mu"], r)
    merit = fclib.fclib_merit(d["W"], d["q"], d["mu"], r)
    viol = fclib.coulomb_violations(d["W"], d["q"], d["mu"], r)
    start = fclib.complementarity_error(d["W"], d["q"], d["mu"], d["guesses"][0]["r"])
    wrong = fclib.fclib_local_from_condensed(c["C"], c["w_free"], c["mu_f"], w_m=c["w_m"], lam_m=c["lam_m"],
                                             g0=c["g0"], w_prev=-np.asarray(c["w_prev"]))
    err_wrong = fclib.complementarity_error(wrong["W"], wrong["q"], wrong["mu"], r)
    print(f"\n  law {p.contact.interfaces[0].law.name}: {d['number_of_contacts']} contacts {viol['contacts']}; W vs C {err_W:.1e}; "
          f"q {err_q:.1e}; u vs physical (gap, slip) {err_u:.1e}; FCLIB complementarity error "
          f"{err:.1e} (fclib_merit_local {merit:.1e}; at NNEQM1's start λ_m {start:.1e}); "
          f"control with +w_prev in q {err_wrong:.1e}")
    print("  violations: " + ", ".join(f"{k} {v:.1e}" for k, v in viol.items() if k != "contacts"))
    assert err_W == 0.0 and err_q <= 1e-15 and err_u < 1e-10
    assert err < 1e-8 and merit < 1e-8
    assert viol["contacts"]["slip"] + viol["contacts"]["stick"] > 0  # a problem with contact
    assert err_wrong > 1e-6  # far above the 1e-8 tolerance: the check can tell q right from wrong
    return d


def test_two_beams_nneqm1_problem_solves_in_fclib(tmp_path):
    p, s = _two_beams_nneqm1("alart-curnier")
    path = fclib.write_nneqm1_problem(tmp_path / "two_beams.hdf5", s)
    d = _check_two_beams(p, s, path)
    assert int(d["info"]["attributes"]["numberOfDegreeOfFreedom"][0]) == p.V.dofmap.index_map.size_global * 3


def test_two_beams_polar_law(tmp_path):
    """The seed's polar law (NNEQM1's default): the exported force is λ(z) = (p_n, −p_r d(θ))."""
    p, s = _two_beams_nneqm1("polar")
    path = fclib.write_nneqm1_problem(tmp_path / "polar.hdf5", s)
    _check_two_beams(p, s, path)


MPI_SCRIPT = textwrap.dedent("""
    import sys
    import dolfinx_nnqem
    import numpy as np
    from mpi4py import MPI
    from dolfinx_nnqem.io import fclib

    comm = MPI.COMM_WORLD
    rng = np.random.default_rng(5)  # the same data on every rank, as NNEQM1's gathered data
    A = rng.standard_normal((12, 12))
    C = A @ A.T * 1e-9
    c = {"C": C, "w_free": rng.standard_normal(12), "w_m": rng.standard_normal(12),
         "lam_m": rng.standard_normal(12), "mu_f": np.full(4, 0.3), "g0": np.zeros(4),
         "w_prev": rng.standard_normal((4, 3)), "r": 1.0}
    path = fclib.write_condensed_problem(sys.argv[1], c, description=f"written with {comm.size} ranks")
    d = fclib.read_fclib_local(path)  # every rank reads right after the collective write
    same = comm.gather(bool(np.array_equal(d["W"], C)), root=0)
    # an error on rank 0 (the file exists, overwrite=False) is raised on every rank, no hang
    try:
        fclib.write_condensed_problem(sys.argv[1], c, overwrite=False)
        raised = "none"
    except Exception as exc:
        raised = type(exc).__name__
    raised = comm.gather(raised, root=0)
    if comm.rank == 0:
        print("ranks", comm.size, "same", all(same), "errors", ",".join(raised))
""")


@pytest.mark.mpi
def test_mpi_rank0_writes(tmp_path):
    """Collective export on 2 ranks: one file (rank 0 writes), readable on every rank on return."""
    script = tmp_path / "export.py"
    script.write_text(MPI_SCRIPT)
    out = tmp_path / "mpi.hdf5"
    cmd = compat.mpiexec() + ["-n", "2", sys.executable, str(script), str(out)]
    run = subprocess.run(cmd, env=compat.mpi_environment(), capture_output=True, text=True, timeout=120)
    assert run.returncode == 0, run.stderr[-3000:]
    line = [x for x in run.stdout.splitlines() if x.startswith("ranks")]
    print(f"\n  {line}")
    assert line == ["ranks 2 same True errors FileExistsError,RuntimeError"]
    d = fclib.read_fclib_local(out)
    assert d["info"]["description"] == "written with 2 ranks" and d["number_of_contacts"] == 4


def test_reads_other_fclib_storages():
    """The reader takes every fclib_matrix storage: CSC (nz = -1), CSR (nz = -2) and CSparse
    triplets (nz ≥ 0: ``i`` rows, ``p`` columns — fclib_merit_local casts fclib_matrix to ``cs*``);
    checked on a non-symmetric matrix so that a transposition would show."""
    A = np.array([[1.0, 0.0, 2.0], [0.0, 3.0, 0.0], [4.0, 5.0, 0.0]])
    csc = fclib.dense_to_csc(A)
    rows, cols = np.nonzero(A)  # row-major order: CSR
    csr_p = np.concatenate(([0], np.cumsum(np.bincount(rows, minlength=3))))
    as_csc = fclib.fclib_matrix_to_dense(3, 3, -1, csc.p, csc.i, csc.x)
    as_csr = fclib.fclib_matrix_to_dense(3, 3, -2, csr_p, cols, A[rows, cols])
    as_triplet = fclib.fclib_matrix_to_dense(3, 3, rows.size, cols, rows, A[rows, cols])
    print(f"\n  CSC p {csc.p.tolist()} i {csc.i.tolist()} x {csc.x.tolist()}")
    assert csc.p.tolist() == [0, 2, 4, 5] and csc.i.tolist() == [0, 2, 1, 2, 0]
    assert np.array_equal(as_csc, A) and np.array_equal(as_csr, A) and np.array_equal(as_triplet, A)

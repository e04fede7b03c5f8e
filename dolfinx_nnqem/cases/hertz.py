r"""Hertz's sphere-on-flat contact: the reference solution, and its measurement from pair forces.

Hertz (``verification.md`` V6): a sphere of radius R pressed on a flat by the force F touches it
on a disc of radius a with the pressure p(r) = p0 sqrt(1 − r²/a²),

    a = (3 F R / (4 E*))^(1/3),   p0 = 3 F / (2 π a²),   δ = a² / R,

1/E* = (1 − ν1²)/E1 + (1 − ν2²)/E2 (a rigid body contributes nothing).

A pair carries a force, not a pressure. With linear elements the pair force is the tributary
integral of the pressure over the node's surface, f_a = ∫ p N_a dA, so

* the nodal pressure is f_a / A_a, A_a = ∫ N_a dA; at the centre this is p0 up to an O(h²/a²)
  averaging of the curved profile;
* near the edge r = a the pressure falls like a square root within one element: the outermost
  closed pair can lie up to about half an element outside a. So a is measured with the whole
  distribution: the radius of the Hertz pressure (for the measured F) whose consistent nodal
  forces ∫ p N_a dA best fit the pair forces (least squares).
* on unstructured meshes the nodal pressures scatter by a few per cent from node to node, the
  centre node's among them; :func:`fit_hertz_profile` fits a and p0 both (F not imposed), so
  that p0 is measured with every pair.

``docs/verification-hertz.md`` gives the reasoning and the figures. The axis of the sphere is
the y axis through x = z = 0; the contact surface lies in a plane y = const.
"""

from __future__ import annotations

import math

import dolfinx.fem as fem
import numpy as np
import ufl
from petsc4py import PETSc
from scipy.optimize import minimize_scalar

from dolfinx_nnqem import jit
from dolfinx_nnqem.problem.contact_problem import assemble_vector
from dolfinx_nnqem.io.results import values_at_blocks

__all__ = ["NodalLoads", "effective_modulus", "fit_hertz_profile", "hertz_contact", "hertz_quantities", "measure_hertz"]


def effective_modulus(E1: float, nu1: float, E2: float | None = None, nu2: float | None = None) -> float:
    """E* with 1/E* = (1 − ν1²)/E1 + (1 − ν2²)/E2; body 2 rigid when ``E2`` is None."""
    compliance = (1.0 - nu1 ** 2) / E1
    if E2 is not None:
        if nu2 is None:
            raise ValueError("effective_modulus: E2 is given without nu2 (give both, or neither for a rigid body 2)")
        compliance += (1.0 - nu2 ** 2) / E2
    return 1.0 / compliance


def hertz_contact(F: float, R: float, E_star: float) -> tuple[float, float]:
    """Hertz's contact radius a and peak pressure p0 for the force F."""
    a = (3.0 * F * R / (4.0 * E_star)) ** (1.0 / 3.0)
    return a, 3.0 * F / (2.0 * math.pi * a ** 2)


class NodalLoads:
    """Tributary areas and consistent nodal forces of an axisymmetric pressure at given nodes.

    Parameters
    ----------
    problem
        The problem.
    facet_tag
        The contact surface the nodes lie on (one side of the interface).
    blocks
        Global dof-block indices of the nodes, one per pair, the same on every rank.
    """

    def __init__(self, problem, facet_tag: int, blocks: np.ndarray):
        self.problem = problem
        self.blocks = np.asarray(blocks, dtype=np.int64)
        mesh = problem.mesh
        v = ufl.TestFunction(problem.V)
        ds = ufl.Measure("ds", domain=mesh, subdomain_data=problem.facet_tags,
                         metadata={"quadrature_degree": 16})  # the √ kink at r = a
        x = ufl.SpatialCoordinate(mesh)
        self._a = fem.Constant(mesh, PETSc.ScalarType(1.0))  # type: ignore[operator]  # petsc4py's stub types ScalarType as a dtype; it is np.float64
        self._p0 = fem.Constant(mesh, PETSc.ScalarType(1.0))  # type: ignore[operator]  # as above
        p = self._p0 * ufl.sqrt(ufl.max_value(1.0 - (x[0] ** 2 + x[2] ** 2) / self._a ** 2, 0.0))
        self._hertz_form = jit.form(p * v[1] * ds(facet_tag))
        self.area = np.abs(self._per_node(jit.form(v[1] * ds(facet_tag))))

    def _per_node(self, form) -> np.ndarray:
        F = assemble_vector(form, self.problem.V)
        values = values_at_blocks(self.problem, self.blocks, F)[:, 1]
        F.destroy()
        return values

    def hertz(self, a: float, p0: float) -> np.ndarray:
        """∫ p N_a dA at every node for p = p0 sqrt(1 − r²/a²) (magnitudes)."""
        self._a.value, self._p0.value = a, p0
        return np.abs(self._per_node(self._hertz_form))


def measure_hertz(loads: NodalLoads, p_n: np.ndarray, positions: np.ndarray, closed: np.ndarray,
                  symmetry: int, R: float, E_star: float) -> dict:
    """F, a and p0 from the pair forces, against Hertz.

    Parameters
    ----------
    loads
        The nodes' tributary areas and Hertz forces.
    p_n
        Normal pair forces (≥ 0), in the order of ``loads.blocks``.
    positions
        The pairs' positions (x, z give the radius).
    closed
        Which pairs are closed.
    symmetry
        4 for a quarter model, 2 for a half model, 1 for a full one.
    """
    r = np.hypot(positions[:, 0], positions[:, 2])
    F = symmetry * p_n.sum()
    a_hertz, p0_hertz = hertz_contact(F, R, E_star)
    centre = int(np.argmin(r))
    if r[centre] > 1e-12 * max(r.max(), 1.0):
        raise ValueError("measure_hertz: no pair at the centre x = z = 0")
    p0 = p_n[centre] / loads.area[centre]

    def misfit(a):
        return float(np.sum((p_n - loads.hertz(a, 3.0 * F / (2.0 * math.pi * a ** 2))) ** 2))

    fit = minimize_scalar(misfit, bounds=(0.5 * a_hertz, 1.5 * a_hertz), method="bounded",
                          options={"xatol": 1e-6 * a_hertz})
    a = float(fit.x)
    f_hertz_centre = loads.hertz(a_hertz, p0_hertz)[centre]
    return {
        "F": F, "a_hertz": a_hertz, "p0_hertz": p0_hertz, "p0": p0, "a": a,
        "err_p0": p0 / p0_hertz - 1.0, "err_a": a / a_hertz - 1.0,
        # the centre pair's force against the Hertz pressure's consistent nodal force there
        "err_f_centre": p_n[centre] / f_hertz_centre - 1.0,
        "r_closed": r[closed].max(), "r_open": r[~closed].min(), "closed": int(closed.sum()),
        "pressure": p_n / loads.area, "r": r,
    }


def fit_hertz_profile(loads: NodalLoads, p_n: np.ndarray, a_guess: float) -> tuple[float, float]:
    """The Hertz profile p0 sqrt(1 − r²/a²) whose nodal forces best fit the pair forces: (a, p0).

    Least squares over both parameters, F not imposed: for a given a the best p0 is linear,
    p0(a) = Σ f_a h_a / Σ h_a² with h_a the nodal forces of the unit profile, which leaves a
    one-dimensional search in a over [a_guess / 2, 3 a_guess / 2].
    """
    p_n = np.asarray(p_n, dtype=float)

    def best_p0(a: float) -> float:
        unit = loads.hertz(a, 1.0)
        return float(p_n @ unit / (unit @ unit))

    def misfit(a: float) -> float:
        return float(np.sum((p_n - loads.hertz(a, best_p0(a))) ** 2))

    fit = minimize_scalar(misfit, bounds=(0.5 * a_guess, 1.5 * a_guess), method="bounded",
                          options={"xatol": 1e-6 * a_guess})
    a = float(fit.x)
    return a, best_p0(a)


def hertz_quantities(facet_tag: int, a_guess: float):
    """A quantity measure (:data:`dolfinx_nnqem.estimates.quantities.Measure`) of a Hertz contact:
    ``hertz:a`` and ``hertz:p0``, the contact radius and peak pressure of the Hertz profile that
    best fits the pair forces (:func:`fit_hertz_profile`; F not imposed), on the slave surface
    ``facet_tag`` of the problem's one interface (collective)."""
    from dolfinx_nnqem.io.results import pair_table

    def measure(problem) -> dict[str, np.ndarray]:
        table = pair_table(problem)
        loads = NodalLoads(problem, facet_tag, table["slave_block"])
        a, p0 = fit_hertz_profile(loads, -table["force_local_body1"][:, 0], a_guess)
        return {"hertz:a": np.array([a]), "hertz:p0": np.array([p0])}

    return measure

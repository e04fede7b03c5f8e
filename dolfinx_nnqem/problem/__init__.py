"""The problem: mesh, tags, materials per body, supports, loads on a load path and contact — the
one object every solver takes (:class:`ContactProblem`), with what builds it: the supports
(:mod:`.supports`), the loads (:mod:`.loads`), the secant predictor (:mod:`.predictor`), the contact
interfaces on the bodies (:mod:`.interfaces`), the assembly (:mod:`.assembly`), the bodies and
their free rigid modes (:mod:`.bodies`), load amplitudes (:mod:`.amplitude`), input checks
(:mod:`.validation`), mesh reading and writing with the gmsh session of mesh generators
(:mod:`.meshing`) and their gmsh helpers (:mod:`.gmsh_tools`). The benchmark geometries are in
:mod:`dolfinx_nnqem.cases.geometries`."""

from dolfinx_nnqem.contact.specification import Contact
from dolfinx_nnqem.contact.obstacles import Cylinder, Plane, Sphere
from dolfinx_nnqem.problem.amplitude import PiecewiseLinear, PiecewiseLinearPath
from dolfinx_nnqem.problem.contact_problem import (FORCE_FLOOR_STRAIN, BodyForce, ContactProblem, Dirichlet,
                                                   Gravity, Pressure, Traction, assemble_vector)

__all__ = ["FORCE_FLOOR_STRAIN", "BodyForce", "Contact", "ContactProblem", "Cylinder", "Dirichlet", "Gravity",
           "PiecewiseLinear", "PiecewiseLinearPath", "Plane", "Pressure", "Sphere", "Traction", "assemble_vector"]

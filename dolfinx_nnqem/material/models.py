"""Materials by name, from a table of parameters (the problem file's ``[materials.TAG]``).

``model`` names the material (default "von-mises", so that a table without it means what it always
meant); a von Mises table names its hardening law with ``hardening`` ("linear" by default: ``sigma_y0``,
``H``; "voce": ``sigma_y0``, ``Q``, ``b``, ``H``; "table": ``table`` = rows [sigma_y, p] in
CalculiX's ``*PLASTIC`` order) and its back-stresses with ``kinematic`` = [[C_1, gamma_1], ...]
(kinematic hardening). "drucker-prager" takes ``cohesion``, ``friction_angle``, ``dilatancy_angle``
and ``match``, its cohesion hardening by the same ``hardening`` names ("linear": ``H``; "voce":
``Q``, ``b``, ``H``; "table": rows [c, p]), ``cohesion`` in the place of ``sigma_y0``. "neo-hooke" (E, nu,
density) is the compressible Neo-Hookean law, for ``kinematics = "finite"`` only. A key that
the model or the law does not take is refused by name. A new material adds its name and keys to
:data:`MODELS` and a branch to :func:`material_from_table`.
"""

from __future__ import annotations

import math
from collections.abc import Mapping

from dolfinx_nnqem.material.drucker_prager import DruckerPrager
from dolfinx_nnqem.material.elastic import Elastic
from dolfinx_nnqem.material.finite_strain.neo_hooke import NeoHooke
from dolfinx_nnqem.material.hardening import IsotropicHardening, TabulatedHardening, VoceHardening
from dolfinx_nnqem.material.interface import Material
from dolfinx_nnqem.material.von_mises import VonMises

__all__ = ["HARDENING_LAWS", "MODELS", "material_from_table"]

_ELASTIC = frozenset({"model", "E", "nu", "density"})
HARDENING_LAWS: dict[str, frozenset[str]] = {
    "linear": frozenset({"sigma_y0", "H"}),
    "voce": frozenset({"sigma_y0", "Q", "b", "H"}),
    "table": frozenset({"table"}),
}
"""Each von Mises hardening law's own keys."""
_DRUCKER_PRAGER = frozenset({"cohesion", "friction_angle", "dilatancy_angle", "match"})
MODELS: dict[str, frozenset[str]] = {
    "von-mises": _ELASTIC | {"hardening", "kinematic"} | frozenset().union(*HARDENING_LAWS.values()),
    "elastic": _ELASTIC,
    "neo-hooke": _ELASTIC,
    "drucker-prager": (_ELASTIC | {"hardening"} | _DRUCKER_PRAGER
                       | frozenset().union(*HARDENING_LAWS.values()) - {"sigma_y0"}),
}
"""Every material name and the keys its table may hold."""


def material_from_table(params: Mapping[str, object]) -> Material:
    """The material a table of parameters describes (numbers already checked to be numbers).

    Raises
    ------
    ValueError
        Naming the key: an unknown model or law, a key the model or law does not take, a missing
        one, or a parameter out of its range.
    """
    model = params.get("model", "von-mises")
    if model not in MODELS:
        raise ValueError(f"model = {model!r}: expected one of {sorted(MODELS)}")
    foreign = sorted(set(params) - MODELS[str(model)])
    if foreign:
        raise ValueError(f"model = {model!r} takes no key(s) {foreign}; its keys: {sorted(MODELS[str(model)])}")
    number = {k: float(v) for k, v in params.items()  # type: ignore[arg-type]  # numbers, checked by the caller
              if k in ("E", "nu", "density", "sigma_y0", "H", "Q", "b", "cohesion", "friction_angle",
                       "dilatancy_angle")}
    E, nu, density = number["E"], number["nu"], number.get("density", 0.0)
    if model == "elastic":
        return Elastic(E, nu, density)
    if model == "neo-hooke":  # finite strain only (kinematics = "finite")
        return NeoHooke(E, nu, density)
    if model == "drucker-prager":
        return _drucker_prager(params, number)
    law = _hardening_law(params, number, "sigma_y0", extra={"kinematic"})
    kinematic = params.get("kinematic", ())
    if law is None:
        return VonMises(E, nu, number.get("sigma_y0", math.inf), number.get("H", 0.0), density,
                        kinematic=kinematic)  # type: ignore[arg-type]  # pairs, checked there
    return VonMises(E, nu, density=density, hardening=law, kinematic=kinematic)  # type: ignore[arg-type]  # as above


def _hardening_law(params: Mapping[str, object], number: Mapping[str, float], initial: str,
                   extra: set[str]) -> IsotropicHardening | None:
    """The law ``hardening`` names with its keys (``initial``: the key of its value at p = 0,
    "sigma_y0" or "cohesion"); None for "linear" (the material takes ``initial`` and ``H`` itself)."""
    law = params.get("hardening", "linear")
    if law not in HARDENING_LAWS:
        raise ValueError(f"hardening = {law!r}: expected one of {sorted(HARDENING_LAWS)}")
    own = {initial if k == "sigma_y0" else k for k in HARDENING_LAWS[str(law)]}
    foreign = sorted((set(params) - _ELASTIC - {"hardening"} - extra) - own)
    if foreign:
        raise ValueError(f"hardening = {law!r} takes no key(s) {foreign}; its keys: {sorted(own)}")
    if law == "linear":
        return None
    if law == "voce":
        missing = sorted({initial, "Q", "b"} - set(params))
        if missing:
            raise ValueError(f"hardening = 'voce' needs the key(s) {missing} ({initial}(p) = {initial} + "
                             "Q (1 - exp(-b p)) + H p)")
        return VoceHardening(number[initial], number["Q"], number["b"], number.get("H", 0.0))
    if "table" not in params:
        raise ValueError(f"hardening = 'table' needs the key table = [[{initial}, p], ...] (CalculiX's *PLASTIC order)")
    return TabulatedHardening(params["table"])  # type: ignore[arg-type]  # rows, checked there


def _drucker_prager(params: Mapping[str, object], number: Mapping[str, float]) -> DruckerPrager:
    """``model = "drucker-prager"``: the cone's keys, its cohesion hardening by ``hardening``."""
    if "friction_angle" not in params:
        raise ValueError("model = 'drucker-prager' needs the key friction_angle (degrees, 0 <= phi < 90)")
    law = _hardening_law(params, number, "cohesion", extra=set(_DRUCKER_PRAGER - {"cohesion"}))
    if law is None and "cohesion" not in params:
        raise ValueError("model = 'drucker-prager' needs the key cohesion (Pa, > 0)")
    match = params.get("match", "outer")
    E, nu, density = number["E"], number["nu"], number.get("density", 0.0)
    phi, psi = number["friction_angle"], number.get("dilatancy_angle")
    if law is None:
        return DruckerPrager(E, nu, number["cohesion"], phi, psi, str(match), number.get("H", 0.0), density)
    return DruckerPrager(E, nu, None, phi, psi, str(match), density=density, hardening=law)

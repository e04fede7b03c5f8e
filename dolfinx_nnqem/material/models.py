"""Materials by name, from a table of parameters (the problem file's ``[materials.TAG]``).

``model`` names the material (default "von-mises", so that a table without it means what it always
meant); a von Mises table names its hardening law with ``hardening`` ("linear" by default: ``sigma_y0``,
``H``; "voce": ``sigma_y0``, ``Q``, ``b``, ``H``; "table": ``table`` = rows [sigma_y, p] in
CalculiX's ``*PLASTIC`` order). A key that the model or the law does not take is refused by
name. A new material adds its name and keys to :data:`MODELS` and a branch to :func:`material_from_table`.
"""

from __future__ import annotations

import math
from collections.abc import Mapping

from dolfinx_nnqem.material.elastic import Elastic
from dolfinx_nnqem.material.hardening import TabulatedHardening, VoceHardening
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
MODELS: dict[str, frozenset[str]] = {
    "von-mises": _ELASTIC | {"hardening"} | frozenset().union(*HARDENING_LAWS.values()),
    "elastic": _ELASTIC,
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
              if k in ("E", "nu", "density", "sigma_y0", "H", "Q", "b")}
    E, nu, density = number["E"], number["nu"], number.get("density", 0.0)
    if model == "elastic":
        return Elastic(E, nu, density)
    law = params.get("hardening", "linear")
    if law not in HARDENING_LAWS:
        raise ValueError(f"hardening = {law!r}: expected one of {sorted(HARDENING_LAWS)}")
    own = HARDENING_LAWS[str(law)]
    foreign = sorted((set(params) - _ELASTIC - {"hardening"}) - own)
    if foreign:
        raise ValueError(f"hardening = {law!r} takes no key(s) {foreign}; its keys: {sorted(own)}")
    if law == "linear":
        return VonMises(E, nu, number.get("sigma_y0", math.inf), number.get("H", 0.0), density)
    if law == "voce":
        missing = sorted({"sigma_y0", "Q", "b"} - set(params))
        if missing:
            raise ValueError(f"hardening = 'voce' needs the key(s) {missing} (sigma_y = sigma_y0 + Q (1 - exp(-b p)) "
                             "+ H p)")
        voce = VoceHardening(number["sigma_y0"], number["Q"], number["b"], number.get("H", 0.0))
        return VonMises(E, nu, density=density, hardening=voce)
    if "table" not in params:
        raise ValueError("hardening = 'table' needs the key table = [[sigma_y, p], ...] (CalculiX's *PLASTIC order)")
    return VonMises(E, nu, density=density, hardening=TabulatedHardening(params["table"]))  # type: ignore[arg-type]  # rows, checked there

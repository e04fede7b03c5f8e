"""Small strain as the limit of finite strain (issue 41, ``benchmarks/small_strain_limit.py``): the
finite-strain verification cases at 1e-4 of their loads, solved at both kinematics.

The uniaxial stretch's force differs by the closed form 1 − ln λ / (λ (λ − 1)) ≈ 1.5e-4 (Hencky's
law; first order in the strain, coefficient 3/2), the other differences stay below 1e-4. Before the
elastic trial worked on b_e^tr − I, the necking bar's finite-strain solve at 5e-5 of its load
stalled at |R|/F ≈ 1e-10 and failed.
"""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "benchmarks"))
sys.path.insert(0, str(ROOT / "meshes"))
import small_strain_limit as bench  # noqa: E402

SCALE = 1e-4


def test_uniaxial_stretch_differs_by_the_closed_form():
    """The unit cube stretched 1e-4: the force difference equals 1 − ln λ/(λ(λ − 1)) to 1e-9."""
    r = bench.difference("stretch", SCALE)
    print(f"\n  stretch 1e-4: force {r['force']:.6e} (closed form {r['closed form']:.6e}), u {r['u']:.2e}")
    assert abs(r["force"] - r["closed form"]) < 1e-9 and 1.4e-4 < r["force"] < 1.6e-4
    assert r["u"] < 1e-4


def test_neo_hookean_shear_tends_to_linear_elasticity():
    """A shear of 1e-4 (Neo-Hooke against linear elasticity) and 1e-5: the differences fall tenfold."""
    r4, r5 = bench.difference("shear", SCALE), bench.difference("shear", 0.1 * SCALE)
    print(f"\n  shear: force {r4['force']:.2e} / {r5['force']:.2e}, u {r4['u']:.2e} / {r5['u']:.2e}")
    assert r4["force"] < 1e-4 and r4["u"] < 1e-4
    assert 0.08 < r5["force"] / r4["force"] < 0.12 and 0.08 < r5["u"] / r4["u"] < 0.12


@pytest.mark.parametrize("case", ["necking", "sphere", "ironing"])
def test_benchmarks_at_a_ten_thousandth_of_their_loads(case):
    """The necking bar, the deep sphere press and the deep ironing at 1e-4 of their loads: both
    kinematics converge, and the displacements and forces agree to 1e-4."""
    r = bench.difference(case, SCALE)
    print(f"\n  {case} 1e-4: force {r['force']:.2e}, u {r['u']:.2e}")
    assert r["force"] < 1e-4 and r["u"] < 1e-4

"""The seed's two-beam benchmark as a CalculiX input: the yardstick of the small-run speed.

Writes ``two_beams.inp`` (the model of ``demos/two_beams.toml`` and
``../shared/spec/benchmark-two-beams.md``: two cantilevers of 40 C3D8 elements each, 0.2 m cubes,
touching on y = 0.4 over x in [1.6, 2.0]; E = 2e10 Pa, nu = 0.17, von Mises with linear isotropic
hardening sigma_y0 = 5e5 Pa, H = 2e10 Pa, density 2400 kg/m^3; Coulomb friction mu = 0.5; the
traction (1e5, -1e5, 0.5e5) Pa on beam 2's top face as consistent nodal loads, and self-weight;
15 equal increments), and with ``--run`` runs ``ccx`` on it and prints the free-end
displacements next to those of a ``dolfinx-nnqem run`` summary, so that the two programs are
seen to solve the same model.

The comparison is of whole processes with their default outputs: CalculiX writes displacements,
stresses, the equivalent plastic strain and the contact fields of every increment into its
``.frd`` file. Its contact is a penalty method (``PRESSURE-OVERCLOSURE=LINEAR``, and a stick
slope for friction), ours enforces the contact law exactly, so the displacements agree to the
penalty's compliance, not to rounding.

Usage::

    python benchmarks/calculix_two_beams.py OUTDIR            # writes OUTDIR/two_beams.inp
    python benchmarks/calculix_two_beams.py OUTDIR --run [--summary results/two_beams_toml/summary.json]

Then time ``ccx -i two_beams`` (in OUTDIR) against ``dolfinx-nnqem run demos/two_beams.toml
--no-pictures`` as whole processes, alternating (``docs/performance.md``).
"""

from __future__ import annotations

import argparse
import json
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np

H = 0.2  # element edge, m
E, NU, SIGMA_Y0, HARDENING, DENSITY, MU_F = 2.0e10, 0.17, 5.0e5, 2.0e10, 2400.0, 0.5
TRACTION = np.array([1.0e5, -1.0e5, 0.5e5])
PENALTY = 50 * E / H  # normal contact stiffness (Pa/m): CalculiX's guide suggests 5-50 x E / h
STICK_SLOPE = PENALTY  # friction's stick stiffness (Pa/m)
INCREMENTS = 15
PROBES = {"beam1 x=2.0 y=0.0 z=0.0": (1, (2.0, 0.0, 0.0)), "beam2 x=1.6 y=0.8 z=0.4": (2, (1.6, 0.8, 0.4))}


def beam_grid(x0: float, y0: float, nx: int = 10, ny: int = 2, nz: int = 2):
    """Node coordinates and C3D8 connectivity (0-based) of one beam of cubes of edge ``H``.

    The element's nodes 1-4 lie on its lower y face and 5-8 on its upper one, ordered so that
    the local axes (xi, eta, zeta) map to (z, x, y), a right-handed map: CalculiX's face S1 is
    then the lower y face and S2 the upper one.
    """
    ix, iy, iz = np.meshgrid(np.arange(nx + 1), np.arange(ny + 1), np.arange(nz + 1), indexing="ij")
    coords = np.column_stack([x0 + H * ix.ravel(), y0 + H * iy.ravel(), H * iz.ravel()])

    def node(i, j, k):
        return (i * (ny + 1) + j) * (nz + 1) + k

    cells = []
    for i in range(nx):
        for j in range(ny):
            for k in range(nz):
                lower = [node(i, j, k), node(i, j, k + 1), node(i + 1, j, k + 1), node(i + 1, j, k)]
                upper = [node(i, j + 1, k), node(i, j + 1, k + 1), node(i + 1, j + 1, k + 1), node(i + 1, j + 1, k)]
                cells.append(lower + upper)
    return coords, np.array(cells)


def model_text() -> str:
    """The whole ``.inp`` text."""
    c1, e1 = beam_grid(0.0, 0.0)
    c2, e2 = beam_grid(1.6, 0.4)
    coords = np.vstack([c1, c2])
    cells = np.vstack([e1, e2 + len(c1)])
    ids = np.arange(1, len(coords) + 1)
    beam = np.repeat([1, 2], [len(e1), len(e2)])
    lines = ["*HEADING", "Two overlapping cantilevers (the seed benchmark), dolfinx_nnqem's yardstick", "*NODE"]
    lines += [f"{i}, {x:.6f}, {y:.6f}, {z:.6f}" for i, (x, y, z) in zip(ids, coords)]
    for b in (1, 2):
        lines.append(f"*ELEMENT, TYPE=C3D8, ELSET=BEAM{b}")
        lines += [f"{e + 1}, " + ", ".join(str(n + 1) for n in cells[e]) for e in np.flatnonzero(beam == b)]
    lines += ["*ELSET, ELSET=EALL", "BEAM1, BEAM2"]
    lines += _node_set("CLAMP1", ids[np.isclose(coords[:, 0], 0.0)])
    lines += _node_set("CLAMP2", ids[np.isclose(coords[:, 0], 3.6)])
    lines += _contact_surfaces(coords, cells, beam)
    lines += ["*MATERIAL, NAME=CONCRETE", "*ELASTIC", f"{E:.6e}, {NU}", "*PLASTIC",
              f"{SIGMA_Y0:.6e}, 0.0", f"{SIGMA_Y0 + HARDENING * 1.0:.6e}, 1.0", "*DENSITY", f"{DENSITY}",
              "*SOLID SECTION, ELSET=EALL, MATERIAL=CONCRETE",
              "*SURFACE INTERACTION, NAME=ROUGH", "*SURFACE BEHAVIOR, PRESSURE-OVERCLOSURE=LINEAR",
              f"{PENALTY:.6e}", "*FRICTION", f"{MU_F}, {STICK_SLOPE:.6e}",
              "*CONTACT PAIR, INTERACTION=ROUGH, TYPE=SURFACE TO SURFACE", "TOP2, BOTTOM1",
              "*BOUNDARY", "CLAMP1, 1, 3", "CLAMP2, 1, 3",
              "*STEP, INC=1000", "*STATIC, DIRECT", f"{1.0 / INCREMENTS:.15f}, 1.0",
              "*DLOAD", "EALL, GRAV, 9.81, 0.0, -1.0, 0.0", "*CLOAD"]
    lines += _traction_loads(coords, ids)
    lines += ["*NODE FILE", "U, RF", "*EL FILE", "S, PEEQ", "*CONTACT FILE", "CDIS, CSTR",
              "*NODE PRINT, NSET=PROBES", "U", "*END STEP"]
    probes = [ids[_nearest(coords, np.array(p), cells, beam, b)] for b, p in PROBES.values()]
    lines[lines.index("*MATERIAL, NAME=CONCRETE"):lines.index("*MATERIAL, NAME=CONCRETE")] = _node_set("PROBES", probes)
    return "\n".join(lines) + "\n"


def _node_set(name: str, ids) -> list[str]:
    ids = [str(int(i)) for i in ids]
    return [f"*NSET, NSET={name}"] + [", ".join(ids[k:k + 8]) for k in range(0, len(ids), 8)]


def _contact_surfaces(coords, cells, beam) -> list[str]:
    """BOTTOM1: beam 1's upper faces (S2) under the overlap; TOP2: beam 2's lower faces (S1) on it
    (CalculiX names the slave first: TOP2 is beam 2's contact face, the slave)."""
    centre = coords[cells].mean(axis=1)
    overlap = (centre[:, 0] > 1.6) & (centre[:, 0] < 2.0)
    lower1 = np.flatnonzero(overlap & (beam == 1) & np.isclose(centre[:, 1], 0.3))
    upper2 = np.flatnonzero(overlap & (beam == 2) & np.isclose(centre[:, 1], 0.5))
    return (["*SURFACE, NAME=BOTTOM1, TYPE=ELEMENT"] + [f"{e + 1}, S2" for e in lower1]
            + ["*SURFACE, NAME=TOP2, TYPE=ELEMENT"] + [f"{e + 1}, S1" for e in upper2])


def _traction_loads(coords, ids) -> list[str]:
    """The uniform traction on y = 0.8 as consistent nodal loads of bilinear faces: each face
    corner carries a quarter of the face's area."""
    top = np.flatnonzero(np.isclose(coords[:, 1], 0.8))
    inner_x = ~np.isclose(coords[top, 0], 1.6) & ~np.isclose(coords[top, 0], 3.6)
    inner_z = ~np.isclose(coords[top, 2], 0.0) & ~np.isclose(coords[top, 2], 0.4)
    faces = (1 + inner_x) * (1 + inner_z)  # faces touching the node: 1, 2 or 4
    lines = []
    for n, k in zip(top, faces):
        force = k * H * H / 4 * TRACTION
        lines += [f"{ids[n]}, {d + 1}, {force[d]:.6e}" for d in range(3) if force[d] != 0.0]
    return lines


def _nearest(coords, point, cells, beam, body) -> int:
    nodes = np.unique(cells[beam == body])
    return int(nodes[np.argmin(np.linalg.norm(coords[nodes] - point, axis=1))])


def read_probe_displacements(dat: Path) -> np.ndarray:
    """The last increment's displacements of the PROBES nodes from CalculiX's ``.dat`` file."""
    blocks, current = [], None
    for line in dat.read_text().splitlines():
        if line.strip().startswith("displacements"):
            current = []
            blocks.append(current)
        elif current is not None and line.strip() and line.split()[0].isdigit():
            current.append([float(v) for v in line.split()[1:4]])
    return np.array(blocks[-1])


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("outdir", help="where two_beams.inp goes")
    parser.add_argument("--run", action="store_true", help="run ccx on it and print the probe displacements")
    parser.add_argument("--summary", default=None, help="a dolfinx-nnqem summary.json to compare with")
    args = parser.parse_args(argv)
    out = Path(args.outdir)
    out.mkdir(parents=True, exist_ok=True)
    (out / "two_beams.inp").write_text(model_text())
    print(f"wrote {out / 'two_beams.inp'}")
    if not args.run:
        return 0
    ccx = shutil.which("ccx")
    if ccx is None:
        print("no ccx on PATH (Debian: apt-get install calculix-ccx)", file=sys.stderr)
        return 1
    subprocess.run([ccx, "-i", "two_beams"], cwd=out, check=True, stdout=subprocess.DEVNULL)
    u_ccx = read_probe_displacements(out / "two_beams.dat")
    ours = None
    if args.summary:
        ours = {p["name"]: p["u"] for p in json.loads(Path(args.summary).read_text())["probes"]}
    for (name, _), u in zip(PROBES.items(), u_ccx):
        text = f"{name}: CalculiX u = {np.array2string(1e3 * u, precision=4)} mm"
        if ours is not None:
            text += f", dolfinx-nnqem u = {np.array2string(1e3 * np.array(ours[name]), precision=4)} mm"
        print(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())

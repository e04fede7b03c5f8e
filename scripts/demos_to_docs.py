"""Render the demos (jupytext percent-format ``.py`` files) into the docs' tutorial pages.

    python scripts/demos_to_docs.py           # (re)write docs/tutorials/*.md
    python scripts/demos_to_docs.py --check   # exit 1 if a page differs from its demo

Each ``# %% [markdown]`` cell becomes text, each ``# %%`` cell a Python code block, and a
figure the demo writes (a ``NAME.png`` named in a code cell) follows the cell that writes it,
taken from ``docs/figures`` (the stored output of a run of the demo; :data:`TUTORIALS` maps
the demo's file names to the stored ones). The demos are not executed at docs build: they take
minutes on two cores, some need MPI and all need DOLFINx in the docs environment, while the
pages need only their text and figures. ``tests/integration/test_tutorials.py`` checks that the pages are
up to date and that every figure exists.
"""

from __future__ import annotations

import argparse
import re
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PAGES = ROOT / "docs" / "tutorials"

# (step of the tutorial path, demo file, {PNG name the demo writes: stored figure in docs/figures})
TUTORIALS = [
    ("first contact problem", "two_beams.py",
     {"deformed.png": "two_beams_deformed.png", "convergence.png": "two_beams_convergence.png"}),
    ("friction", "contact_interfaces.py",
     {"friction.png": "three_blocks_friction.png", "deformed.png": "three_blocks_deformed.png"}),
    ("friction", "hertz_contact.py",
     {"pressure_profile.png": "hertz_pressure_profile.png", "stick_slip_map.png": "hertz_stick_slip_map.png"}),
    ("friction", "friction_sweep.py", {"contact_force.png": "friction_sweep_contact_force.png"}),
    ("plasticity", "thick_cylinder.py",
     {"pressure_displacement.png": "thick_cylinder_pressure_displacement.png",
      "plastic_zone.png": "thick_cylinder_plastic_zone.png"}),
    ("plasticity", "rigid_indenter.py",
     {"hertz_pressure.png": "rigid_sphere_pressure.png", "plastic_zone.png": "indentation_plastic_zone.png",
      "slide_forces.png": "indenter_slide_forces.png"}),
    ("plasticity", "ironing.py",
     {"forces.png": "ironing_forces.png", "plastic_zone.png": "ironing_plastic_zone.png"}),
    ("plasticity", "deep_ironing.py",
     {"forces.png": "deep_ironing_forces.png", "plastic_strain.png": "deep_ironing_plastic_strain.png",
      "cauchy_stress.png": "deep_ironing_cauchy_stress.png"}),
    ("plasticity", "two_beams_concrete.py",
     {"load_deflection.png": "two_beams_concrete_load_deflection.png",
      "plastic_zone.png": "two_beams_concrete_plastic_zone.png"}),
    ("your own gmsh mesh", "own_gmsh_mesh.py",
     {"deformed.png": "own_mesh_deformed.png", "pair_pressure.png": "own_mesh_pair_pressure.png"}),
    ("error bars", "error_bars.py", {"error_bars.png": "two_beams_error_bars.png"}),
]


def cells(source: str) -> list[tuple[str, str]]:
    """The (kind, text) cells of a percent-format file: kind "markdown" or "code"."""
    lines = source.splitlines()
    if lines and lines[0].strip() == "# ---":  # the jupytext header
        end = next(i for i in range(1, len(lines)) if lines[i].strip() == "# ---")
        lines = lines[end + 1:]
    out: list[tuple[str, list[str]]] = []
    for line in lines:
        marker = re.match(r"^# %%(.*)$", line)
        if marker:
            out.append(("markdown" if "[markdown]" in marker.group(1) else "code", []))
        elif out:
            out[-1][1].append(line)
    result = []
    for kind, body in out:
        if kind == "markdown":
            text = "\n".join(re.sub(r"^# ?", "", line) for line in body)
        else:
            text = "\n".join(body)
        text = text.strip("\n")
        if text.strip():
            result.append((kind, text))
    return result


def render(demo: Path, figures: dict[str, str], step: str) -> str:
    """The Markdown page of one demo."""
    parts = [f"<!-- generated from demos/{demo.name} by scripts/demos_to_docs.py: edit the demo, not this page -->",
             ""]
    shown: set[str] = set()
    for index, (kind, text) in enumerate(cells(demo.read_text())):
        if kind == "markdown":
            parts += [text, ""]
            if index == 0:
                parts += [f"*Tutorial step: {step}. Source: `demos/{demo.name}`; run it with "
                          f"`python demos/{demo.name}` (options: `--help`).*", ""]
            continue
        parts += ["```python", text, "```", ""]
        for name, stored in figures.items():
            if stored not in shown and re.search(rf"[\"'/ ]{re.escape(name)}[\"']", text):
                parts += [f"![{name}](../figures/{stored})", ""]
                shown.add(stored)
    missing = sorted(set(figures.values()) - shown)
    if missing:
        raise ValueError(f"demos/{demo.name}: no code cell writes {missing}")
    return "\n".join(parts).rstrip("\n") + "\n"


def pages() -> dict[Path, str]:
    """Every tutorial page by its path."""
    return {PAGES / f"{Path(name).stem}.md": render(ROOT / "demos" / name, figures, step)
            for step, name, figures in TUTORIALS}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--check", action="store_true", help="only report pages that differ from their demos")
    args = parser.parse_args(argv)
    stale = []
    for path, text in pages().items():
        if args.check:
            if not path.is_file() or path.read_text() != text:
                stale.append(path)
        else:
            path.parent.mkdir(parents=True, exist_ok=True)
            path.write_text(text)
            print(f"wrote {path.relative_to(ROOT)}")
    for path in stale:
        print(f"{path.relative_to(ROOT)} is not up to date: run python scripts/demos_to_docs.py", file=sys.stderr)
    return 1 if stale else 0


if __name__ == "__main__":
    sys.exit(main())

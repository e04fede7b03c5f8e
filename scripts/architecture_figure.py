"""Draw ``docs/figures/architecture.png``: the package's layers, their modules and which layer
imports which, read from the package itself (so the picture cannot drift from the code).

    python scripts/architecture_figure.py            # (re)draw the figure
    python scripts/architecture_figure.py --check    # exit 1 if the modules drawn differ from the package's

``tests/unit/test_docs.py`` runs the check.
"""

from __future__ import annotations

import argparse
import ast
import json
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "dolfinx_nnqem"
FIGURE = ROOT / "docs" / "figures" / "architecture.png"
LISTING = ROOT / "docs" / "figures" / "architecture.json"  # the modules the figure shows

# top to bottom as drawn; each imports only from the rows below it (and the ground)
LAYERS = [
    ("front end", ["cli", "problem_file", "__main__"]),
    ("io / estimates / cases", ["io", "estimates", "cases"]),
    ("solvers", ["solvers"]),
    ("problem", ["problem"]),
    ("physics", ["material", "contact"]),
    ("ground", ["numerics", "compat", "pyvista_compat", "jit", "collective", "chatter", "interrupts", "names", "_moved"]),
]


def modules_of(part: str) -> list[str]:
    """The modules of a subpackage (without __init__), or [part] for a root module."""
    folder = PACKAGE / part
    if folder.is_dir():
        return sorted(p.stem for p in folder.glob("*.py") if p.stem != "__init__")
    return [part]


def listing() -> dict[str, dict[str, list[str]]]:
    return {layer: {part: modules_of(part) for part in parts} for layer, parts in LAYERS}


def check() -> int:
    drawn = json.loads(LISTING.read_text()) if LISTING.exists() else None
    roots = sorted(p.stem for p in PACKAGE.glob("*.py") if p.stem != "__init__")
    listed_roots = sorted(part for _, parts in LAYERS for part in parts if not (PACKAGE / part).is_dir())
    folders = sorted(p.name for p in PACKAGE.iterdir() if p.is_dir() and (p / "__init__.py").exists())
    listed_folders = sorted(part for _, parts in LAYERS for part in parts if (PACKAGE / part).is_dir())
    problems = []
    if roots != listed_roots:
        problems.append(f"root modules {roots} but the figure lists {listed_roots}")
    if folders != listed_folders:
        problems.append(f"subpackages {folders} but the figure lists {listed_folders}")
    if drawn != listing():
        problems.append("the modules drawn differ from the package's: run scripts/architecture_figure.py")
    for problem in problems:
        print(problem, file=sys.stderr)
    return 1 if problems else 0


def draw() -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.patches import FancyBboxPatch

    data = listing()
    fig, ax = plt.subplots(figsize=(13, 9.5))
    ax.set_xlim(0, 13)
    ax.set_ylim(0, len(LAYERS) * 1.6 + 0.2)
    ax.axis("off")
    colours = ["#d8e2dc", "#ffe5d9", "#ffcad4", "#f4acb7", "#cdb4db", "#bde0fe"]
    for row, (layer, parts) in enumerate(data.items()):
        y = (len(LAYERS) - 1 - row) * 1.6 + 0.3
        ax.add_patch(FancyBboxPatch((0.1, y), 12.8, 1.2, boxstyle="round,pad=0.02", fc=colours[row], ec="grey"))
        ax.text(0.3, y + 0.95, layer, fontsize=12, fontweight="bold", va="center")
        width = 12.3 / max(len(parts), 1)
        for k, (part, modules) in enumerate(parts.items()):
            x = 0.4 + k * width
            is_folder = (PACKAGE / part).is_dir()
            title = f"{part}/" if is_folder else f"{part}.py"
            ax.text(x, y + 0.62, title, fontsize=10, fontweight="bold" if is_folder else "normal",
                    family="monospace", va="center")
            if is_folder:
                text = ", ".join(modules)
                lines, line = [], ""
                for word in text.split(" "):
                    if len(line) + len(word) > max(int(width * 9.5), 20):
                        lines.append(line)
                        line = ""
                    line += word + " "
                lines.append(line)
                ax.text(x, y + 0.38, "\n".join(lines), fontsize=7.2, family="monospace", va="top")
        if row < len(LAYERS) - 1:
            ax.annotate("", xy=(12.5, y - 0.38), xytext=(12.5, y + 0.02),
                        arrowprops={"arrowstyle": "->", "color": "grey", "lw": 1.5})
    ax.text(12.55, 0.15, "imports ↓", fontsize=9, color="grey", ha="right")
    fig.suptitle("dolfinx_nnqem: layers, each importing only those below it", fontsize=14)
    fig.tight_layout()
    fig.savefig(FIGURE, dpi=110)
    LISTING.write_text(json.dumps(data, indent=1) + "\n")


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--check", action="store_true")
    args = parser.parse_args(argv)
    if args.check:
        return check()
    draw()
    return check()


if __name__ == "__main__":
    raise SystemExit(main())

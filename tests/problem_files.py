"""Problem-file texts the tests share, built from parameters instead of copied into each test file.

* :func:`two_beams_demo`: ``demos/two_beams.toml`` (the seed's two beams: elastoplastic, loaded,
  15 increments) reading the mesh from an absolute path, so that it can be written anywhere;
* :func:`two_beams_minimal`: the least a problem file on the two beams' mesh needs (materials,
  the contact 21/22, the clamps; no load), for the reader's tests and ``run --check``;
* :func:`pressed_block_stack`: two blocks of a ``build_block_stack`` mesh ``stack.msh`` on
  rollers, the upper one pressed by p = 1e6 onto the lower: the contact patch test;
* :func:`block_under_obstacle`: a block pressed by a rigid obstacle (``[contact.obstacle]``).

Where a test fills a text in later (``str.format`` or ``str.replace``), its placeholders go in
as parameters (``contact_keys="{contact}"``) and the test body is the same as with the copy.
"""

from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
TWO_BEAMS_DEMO = ROOT / "demos" / "two_beams.toml"
TWO_BEAMS_MSH = (ROOT / "meshes" / "two_beams.msh").as_posix()
TWO_BEAMS_XDMF = (ROOT / "meshes" / "two_beams.xdmf").as_posix()
TWO_ELASTIC_BODIES = "[materials.1]\nE = 1.0e9\nnu = 0.3\n[materials.2]\nE = 1.0e9\nnu = 0.3"
"""Bodies 1 and 2 (their cell tags) elastic, E = 1e9, ν = 0.3."""


def two_beams_demo(mesh: str = TWO_BEAMS_XDMF, *, mesh_keys: str = "", solver_lines: str | None = None) -> str:
    """The text of ``demos/two_beams.toml`` with its mesh read from ``mesh``.

    Parameters
    ----------
    mesh
        The mesh file (the demo's own XDMF file by default, by its absolute path).
    mesh_keys
        Lines added to ``[mesh]`` after its ``file`` (e.g. ``"degree = 2"``).
    solver_lines
        Lines in place of the demo's ``increments = 15`` (the last line of ``[solver]``).
    """
    text = TWO_BEAMS_DEMO.read_text()
    for line in ('file = "../meshes/two_beams.xdmf"', "increments = 15"):
        if line not in text:  # the demo changed: these texts would silently keep the demo's values
            raise ValueError(f"{TWO_BEAMS_DEMO} has no line {line!r}: update tests/problem_files.py")
    mesh_lines = f'file = "{mesh}"' + (f"\n{mesh_keys}" if mesh_keys else "")
    text = text.replace('file = "../meshes/two_beams.xdmf"', mesh_lines)
    return text if solver_lines is None else text.replace("increments = 15", solver_lines)


def two_beams_minimal(mesh: str = TWO_BEAMS_MSH, *, materials: str = TWO_ELASTIC_BODIES, mu_f: float = 0.3,
                      clamped: tuple[int, ...] = (11, 12), more: str = "") -> str:
    """A problem file on the two beams' mesh with materials, the contact and clamps only.

    Parameters
    ----------
    mesh
        The mesh file (``meshes/two_beams.msh`` by default; a placeholder a test replaces).
    materials
        The ``[materials.TAG]`` tables, as TOML text.
    mu_f
        The friction coefficient of the contact of surfaces 21 and 22.
    clamped
        The facet tags held fixed (``[[dirichlet]]``; 11 and 12 are the beams' clamped ends).
    more
        Lines appended at the end (e.g. ``[solver]`` and ``[output]`` tables).
    """
    dirichlet = "".join(f"[[dirichlet]]\ntag = {tag}\n" for tag in clamped)
    return (f'[mesh]\nfile = "{mesh}"\n{materials}\n[contact]\nsurface1 = 21\nsurface2 = 22\nmu_f = {mu_f}\n'
            f"{dirichlet}{more}")


def pressed_block_stack(*, mesh_keys: str = "", contact_keys: str = "", solver_keys: str = "") -> str:
    """Two blocks of ``stack.msh`` (``build_block_stack`` tags) pressed together: the patch test.

    Body 1 rests on rollers at its bottom (101, y held), both bodies on rollers at x = 0, 1
    (301, 302: x held) and z = 0, 1 (501, 502: z held); p = 1e6 on body 2's top (202) presses it
    onto body 1 through the interface 201/102 (μ_f = 0.3), in one increment to rtol 1e-12.

    Parameters
    ----------
    mesh_keys, contact_keys, solver_keys
        Lines added to ``[mesh]`` after its ``file``, to ``[[contact]]`` after ``mu_f`` and to
        ``[solver]`` before ``increments``.
    """
    def lines(keys: str) -> str:
        return f"{keys}\n" if keys else ""

    return (f'[mesh]\nfile = "stack.msh"\n{lines(mesh_keys)}{TWO_ELASTIC_BODIES}\n'
            f"[[contact]]\nsurface1 = 201\nsurface2 = 102\nmu_f = 0.3\n{lines(contact_keys)}"
            "[[dirichlet]]\ntag = 101\ncomponents = [1]\n"
            "[[dirichlet]]\ntag = 301\ncomponents = [0]\n[[dirichlet]]\ntag = 302\ncomponents = [0]\n"
            "[[dirichlet]]\ntag = 501\ncomponents = [2]\n[[dirichlet]]\ntag = 502\ncomponents = [2]\n"
            f"[[pressure]]\ntag = 202\np = 1.0e6\n[solver]\n{lines(solver_keys)}increments = 1\nrtol = 1e-12\n")


def block_under_obstacle(obstacle: str, *, mu_f: float, increments: int, more: str = "") -> str:
    """A block (body 1, held at its bottom 101) pressed at its top 201 by a rigid obstacle.

    The mesh file and the method are the placeholders ``MESH`` and ``METHOD`` (the tests replace
    them); the contact is named ``"press"``.

    Parameters
    ----------
    obstacle
        The keys of ``[contact.obstacle]`` (its type, shape and motion), as TOML lines.
    mu_f
        The friction coefficient between the obstacle and the block.
    increments
        The number of increments of ``[solver]``.
    more
        Lines appended at the end (e.g. ``[output]`` tables).
    """
    return ('[mesh]\nfile = "MESH"\n[materials.1]\nE = 1.0e9\nnu = 0.3\n'
            f'[[contact]]\nsurface2 = 201\nmu_f = {mu_f}\nname = "press"\n[contact.obstacle]\n{obstacle}\n'
            f'[[dirichlet]]\ntag = 101\n[solver]\nmethod = "METHOD"\nincrements = {increments}\n{more}')

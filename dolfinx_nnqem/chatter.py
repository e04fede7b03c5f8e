"""Third-party output: silent at the default level, shown with ``-v``.

A run's default output is the package's own lines only. The libraries underneath talk on their
own channels: gmsh prints ``Info : Reading ...`` lines on the C stdout (its ``General.Terminal``
and ``General.Verbosity`` options), numba and other Python libraries emit Python warnings
(``NumbaPerformanceWarning``, deprecations), VTK logs to stderr (``bad X server connection``
when it renders off-screen without a display). :func:`show_third_party_output` decides once per
process whether they are shown; the gmsh users of this package (:mod:`dolfinx_nnqem.problem.meshing`,
:mod:`dolfinx_nnqem.problem_file`) apply :func:`gmsh_options` to their session.

Errors are not hidden: gmsh's API raises an exception for its errors whatever its terminal
setting, and logging's ERROR records are always shown.
"""

from __future__ import annotations

import logging
import sys
import warnings

__all__ = ["GMSH_QUIET", "GMSH_VERBOSE", "apply_gmsh_options", "apply_numba_options", "apply_vtk_options", "gmsh_options", "show_third_party_output",
           "third_party_output_shown"]

# gmsh's General.Verbosity: 0 silent, 1 errors, 2 warnings, 3 direct, 4 information, 5 status
GMSH_QUIET = {"General.Terminal": 0, "General.Verbosity": 1}
GMSH_VERBOSE = {"General.Terminal": 1, "General.Verbosity": 5}

_shown = False
_silenced = False  # show_third_party_output(False) was called (a user's program never calls it)


def show_third_party_output(shown: bool) -> None:
    """Show (``-v``) or silence (the default) gmsh, numba and Python warnings of other packages."""
    global _shown, _silenced
    _shown = bool(shown)
    _silenced = not _shown
    numba_logger = logging.getLogger("numba")
    numba_logger.setLevel(logging.DEBUG if _shown else logging.ERROR)
    if "numba" in sys.modules:  # else when numba is imported (it is only where a kernel compiles)
        apply_numba_options()
    if _shown:
        return
    # warnings raised in other packages (deprecations in VTK, h5py, ...): silent by default; this
    # package's own warnings (module dolfinx_nnqem.*) keep Python's default filters
    warnings.filterwarnings("ignore", category=DeprecationWarning)
    warnings.filterwarnings("ignore", category=FutureWarning, module=r"^(?!dolfinx_nnqem).*")
    warnings.filterwarnings("ignore", category=UserWarning, module=r"^(?!dolfinx_nnqem).*")


def apply_numba_options() -> None:
    """numba's warnings silenced where :func:`show_third_party_output` silenced the libraries
    (call it where numba is imported: its import costs a run 0.1–0.2 s of CPU, so numba is
    imported only where a kernel is compiled)."""
    if not _silenced:
        return
    try:
        from numba.core.errors import NumbaWarning

        warnings.simplefilter("ignore", NumbaWarning)
    except ImportError:  # numba is a dependency, but a missing one must not end the run here
        pass


def third_party_output_shown() -> bool:
    """Whether :func:`show_third_party_output` asked for the libraries' own output."""
    return _shown


def gmsh_options() -> dict[str, int]:
    """gmsh's terminal options for the current level (quiet unless ``-v``)."""
    return dict(GMSH_VERBOSE if _shown else GMSH_QUIET)


def apply_gmsh_options() -> dict[str, float]:
    """Set :func:`gmsh_options` in the open gmsh session; return the previous values (to restore)."""
    import gmsh

    previous = {}
    for name, value in gmsh_options().items():
        previous[name] = gmsh.option.getNumber(name)
        gmsh.option.setNumber(name, value)
    return previous


def apply_vtk_options() -> None:
    """VTK's stderr log: warnings and above with ``-v``, errors only otherwise."""
    from vtkmodules.vtkCommonCore import vtkLogger

    vtkLogger.SetStderrVerbosity(vtkLogger.VERBOSITY_WARNING if _shown else vtkLogger.VERBOSITY_ERROR)

"""The pictures of a run, drawn from its results folder (``RESULTS/pictures/*.png``).

Everything is read back from what the run wrote (:mod:`dolfinx_nnqem.io.reader`): the last
increment of ``fields.xdmf``, the pair CSV files and ``summary.json``. So the pictures of a
finished run, of a run that stopped at an increment that did not converge (its converged
increments) and the ones ``dolfinx-nnqem plot RESULTS_DIR`` redraws with other options are the
same pictures, and redrawing needs no solve, no mesh file and no MPI. One exception, for speed:
at the end of a run the fields of that last increment are not read back but taken from memory,
where the run still holds the values it wrote (:mod:`dolfinx_nnqem.io.live_fields`).

A degree-2 run draws its quadratic displacement: the deformed mesh is made of its Lagrange
cells (10-node tetrahedra, 27-node hexahedra) with u at every P2 node, from memory at the end of
the run and from ``fields_p2.pvd`` when redrawn (``fields.xdmf`` holds u at the mesh's vertices
only; its cell fields colour the cells).

- ``deformed.png``: the deformed mesh (displacements × a scale) coloured by the von Mises
  stress (or the equivalent plastic strain ``p``), the cells where ``p > 0`` outlined (the
  plastic zone), the contact pairs as spheres coloured by state (white open, blue stick, red
  slip). Needs ``fields.xdmf`` (``[output].fields = true``).
- ``pair_pressure.png``: the contact pressure of each pair (``pressure`` of the pair CSV, Pa)
  over the contact surface, one panel per interface, drawn in the two coordinate directions
  along which the surface extends most.
- ``load_curve.png``: the load factor against the support reactions (and obstacle forces) and
  against the displacements of the ``[output.probes]`` (``reaction_history``,
  ``obstacle_force_history``, ``probe_history`` of ``summary.json``).
- ``convergence.png``: the relative residuals ‖R‖/F and ‖H‖/F per iteration, one line per
  increment (``residual_histories``).

A picture whose data the folder lacks is skipped with the reason (:func:`draw_run_pictures`
returns it). ``contact_pressure.png``, the pressure drawn on the surface of the deformed bodies
(``plots.draw_contact_pressure``), needs the live problem, so only :func:`draw_live_pictures`
(the end of a run) draws it. At the end of a command-line run the pictures are drawn by worker
processes started with the run (:mod:`dolfinx_nnqem.io.picture_worker`), with the same
functions (:func:`draw_job`); this module imports no DOLFINx and no MPI for them.
"""

from __future__ import annotations

import logging
import math
import os
from pathlib import Path

from collections.abc import Callable, Collection, Mapping
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np

import dolfinx_nnqem.io.plots as plots
import dolfinx_nnqem.io.vtk_charts as vtk_charts
from dolfinx_nnqem.io.deformed_picture import DeformedScene, _with_quadratic_displacement, draw_deformed  # noqa: F401
from dolfinx_nnqem.io.estimate_pictures import ESTIMATE_PICTURE, draw_error_estimates
from dolfinx_nnqem.io.offscreen import PictureUnavailable
from dolfinx_nnqem.io.reader import read_pairs, read_summary, start_reading_fields

if TYPE_CHECKING:
    from dolfinx_nnqem.problem.contact_problem import ContactProblem

__all__ = ["ALL_PICTURES", "CONTACT_PICTURE", "PICTURE_FOLDER", "PICTURES", "PictureDrawer", "draw_job", "draw_live_pictures",
           "draw_run_pictures", "missing_pictures", "pictures_enabled", "pictures_of_run"]

PICTURE_FOLDER = "pictures"
PICTURES = ("deformed.png", "pair_pressure.png", "load_curve.png", "convergence.png", "error_indicator.png",
            ESTIMATE_PICTURE)
INDICATOR_FIELD = "error_indicator"
"""The cell field of the error indicator (:data:`dolfinx_nnqem.estimates.INDICATOR_NAME`)."""
ENV_SWITCH = "DOLFINX_NNQEM_PICTURES"
"""Environment variable: ``0`` turns the end-of-run pictures off where no flag decides."""

_log = logging.getLogger("dolfinx_nnqem")


def pictures_enabled(flag: bool | None = None) -> bool:
    """Whether a run draws its pictures: ``flag`` if given, else not ``DOLFINX_NNQEM_PICTURES=0``."""
    if flag is not None:
        return bool(flag)
    return os.environ.get(ENV_SWITCH, "1").strip().lower() not in ("0", "false", "no", "off")


def _whole_picture(path: Path, draw: Callable[[Path], object]) -> Path:
    """``draw(temporary)`` beside ``path``, then the rename: a picture is whole or absent.

    A SIGKILL or SIGTERM while a picture was drawn left a 0-byte PNG under its name. The
    temporary (``.NAME.tmp-PID.png``: matplotlib reads the format from the suffix) is
    removed on any error or interrupt; a killed process leaves it, and the next run in the
    folder removes it (:func:`~dolfinx_nnqem.io.safe_io.remove_stale_temporaries`). Errors are
    raised as the drawing raised them (the reason a picture is not drawn)."""
    # safe_io's naming (.NAME.tmp-PID), the suffix kept; safe_io itself imports MPI, which a
    # picture worker cannot
    tmp = path.with_name(f".{path.name}.tmp-{os.getpid()}{path.suffix}")
    try:
        draw(tmp)
        with open(tmp, "rb+") as fh:  # whole on disk before its name says it is there
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    return path


def _title(summary: dict) -> str:
    """What the run is and how far it got (a failed run says where it stopped)."""
    factors = summary.get("load_factors", [])
    text = f"{summary.get('method', '?')}: load factor {factors[-1]:.4g}" if factors else "no converged increment"
    text += f" (increment {len(factors)} of {summary.get('increments', '?')})"
    status = summary.get("status", "")
    if status == "not converged":
        failure = summary.get("failure", {})
        text += f"; not converged at load factor {failure.get('load_factor', float('nan')):.4g}"
    elif status not in ("completed", ""):
        text += f"; {status}"
    return text


# -- curves --------------------------------------------------------------------------------------
def _rows_by_interface(rows: list[dict]) -> dict[str, list[dict]]:
    out: dict[str, list[dict]] = {}
    for row in rows:
        out.setdefault(row.get("interface", ""), []).append(row)
    return out


def draw_pair_pressure(rows: list[dict], path: Path, *, title: str = "") -> Path:
    """Pair pressure (Pa) over each contact surface, one panel per interface (VTK's charts)."""
    groups = _rows_by_interface(rows)
    panels = vtk_charts.ChartPanels(len(groups), 5.5, 4.5, title)
    for index, (name, group) in enumerate(groups.items()):
        x = np.array([[float(r["slave_x"]), float(r["slave_y"]), float(r["slave_z"])] for r in group])
        pressure = np.array([float(r["pressure"]) for r in group])
        # the surface's two longest extents name the axes (a contact plane x-z shows x and z)
        a, b = sorted(np.argsort(np.ptp(x, axis=0))[-2:])
        closed = np.array([r["state"] != "open" for r in group])
        vtk_charts.add_scatter(panels, index, x[:, a], x[:, b], pressure, value_label="pressure (Pa)",
                               xlabel=f"{'xyz'[a]} (m)", ylabel=f"{'xyz'[b]} (m)",
                               title=f"interface {name}: max {pressure.max():.3g} Pa", grey=~closed, grey_label="open")
    panels.save(path)
    return path


def _largest_component(history: list[list[float]]) -> tuple[int, np.ndarray]:
    """(k, values of component k) for the component with the largest last magnitude."""
    values = np.asarray(history, dtype=float).reshape(len(history), -1)
    k = int(np.argmax(np.abs(values[-1])))
    return k, values[:, k]


def load_curve_series(summary: dict) -> tuple[list[tuple[str, np.ndarray]], list[tuple[str, np.ndarray]]]:
    """The load curve's data: ([(label, force per increment, N)], [(label, displacement, m)])."""
    forces, displacements = [], []
    for key, what in (("reaction_history", "reaction of tag"), ("obstacle_force_history", "obstacle")):
        history = summary.get(key, [])
        for name in (history[-1] if history else {}):
            k, values = _largest_component([h.get(name, [math.nan] * 3) for h in history])
            forces.append((f"{what} {name}: F{'xyz'[k]}", values))
    probes = summary.get("probe_history", [])
    # the two-beam benchmark renames its probes "free_end_corners"
    names = [p["name"] for p in summary.get("probes") or summary.get("free_end_corners") or []]
    for i, name in enumerate(names if probes else []):
        k, values = _largest_component([h[i] for h in probes])
        displacements.append((f"{name}: u{'xyz'[k]}", values))
    return forces, displacements


def draw_load_curve(summary: dict, path: Path, *, title: str = "") -> Path:
    """Load factor against reactions (N) and probe displacements (mm)."""
    factors = np.asarray(summary.get("load_factors", []), dtype=float)
    forces, displacements = load_curve_series(summary)
    panels = [(s, "force (N)", 1.0) for s in [forces] if s] + [(s, "displacement (mm)", 1e3)
                                                               for s in [displacements] if s]
    if not panels:
        raise ValueError("summary.json has no reaction_history or probe_history")
    pictures = vtk_charts.ChartPanels(len(panels), 6.0, 4.5, title)
    for chart, (series, xlabel, unit) in zip(pictures.charts, panels):
        lines = []
        for k, (label, values) in enumerate(series):
            n = min(len(values), len(factors))
            lines.append((label, unit * values[:n], factors[:n], vtk_charts.CYCLE[k % len(vtk_charts.CYCLE)]))
        vtk_charts.add_lines(chart, lines, xlabel=xlabel, ylabel="load factor")
    pictures.save(path)
    return path


def draw_convergence(summary: dict, path: Path, *, title: str = "") -> Path:
    """‖R‖/F and ‖H‖/F per iteration, one line per increment (log scale)."""
    histories = [np.asarray(h, dtype=float).reshape(-1, 2) for h in summary.get("residual_histories", []) if h]
    if not histories:
        raise ValueError("summary.json has no residual_histories")
    with_contact = any(np.any(h[:, 1] > 0) for h in histories)
    # not "‖R‖": VTK's Arial has no "‖", and "||R||" is taken for mathematics (drawn by matplotlib's
    # mathtext) in a process where VTK's matplotlib module is loaded (pyvista.plotting loads it)
    names = ["equilibrium norm(R)/F"] + (["contact norm(H)/F"] if with_contact else [])
    panels = vtk_charts.ChartPanels(len(names), 6.0, 4.5, title)
    colours = vtk_charts.sequential_colours(len(histories))
    labelled = len(histories) <= 12
    for column, (chart, name) in enumerate(zip(panels.charts, names)):
        lines = [(f"increment {k + 1}" if labelled else None, np.arange(len(h)), np.maximum(h[:, column], 1e-17), colour)
                 for k, (h, colour) in enumerate(zip(histories, colours))]
        vtk_charts.add_lines(chart, lines, xlabel="iteration", ylabel=name, log_y=True, marker_size=6.0,
                             legend=labelled)
    panels.save(path)
    return path


# -- the whole set -------------------------------------------------------------------------------
def draw_run_pictures(folder: str | os.PathLike, *, out: str | os.PathLike | None = None,
                      scale: float | None = None, field: str = "von_mises",
                      camera: str = "iso", step: dict | None = None,
                      names: Collection[str] = PICTURES) -> dict[str, Path | str]:
    """Draw :data:`PICTURES` from a results folder; not collective (call it on one rank).

    Parameters
    ----------
    folder
        A run's output folder (``summary.json``, ``fields.xdmf``, ``pairs.pvd``).
    out
        Where the PNG files go (default ``folder/pictures``).
    scale
        Displacement magnification of ``deformed.png`` (default: 1 for a finite-strain run, else
        the largest displacement drawn as 10 % of the model's size); the rigid obstacles are
        moved by the same scale × their displacement.
    field
        Cell field of ``deformed.png``: ``"von_mises"`` or ``"p"``.
    camera
        ``"iso"``, ``"xy"``, ``"xz"`` or ``"yz"``.
    step
        The fields of the last increment the folder lists, as the run still holds them
        (:func:`~dolfinx_nnqem.io.live_fields.gather_field_step`): ``deformed.png`` is drawn
        from them instead of reading ``fields.xdmf`` (and ``fields_p2.pvd``) back.
    names
        The pictures drawn, of :data:`PICTURES` (default all; a picture worker draws a part).

    Returns
    -------
    dict
        Per picture name of ``names`` (in the order of :data:`PICTURES`), its path, or the reason
        it was not drawn (a string). The pictures of what the run did not make are left out:
        ``error_estimates.png`` without an estimate, ``error_indicator.png`` without that field.
    """

    names = _picture_names(names)
    folder = Path(folder)
    out = Path(out) if out is not None else folder / PICTURE_FOLDER
    out.mkdir(parents=True, exist_ok=True)
    summary = read_summary(folder)
    title = _title(summary)
    pairs = read_pairs(folder)
    rows = pairs[-1]["rows"] if pairs else []
    done: dict[str, Path | str] = {}
    if not summary.get("load_factors"):
        return {name: "not drawn: no converged increment" for name in names}
    fields = _start_fields(folder, names, step, done)
    try:
        _draw_curves(out, names, summary, rows, title, done)
    finally:  # the reading process is waited for whatever happened
        steps = _wait_for_fields(fields, done)
    if steps:
        last = steps[-1] if step is not None else _with_quadratic_displacement(folder, steps[-1])
        if scale is None and summary.get("kinematics") == "finite":
            scale = 1.0  # large displacements: their true size
        _draw_fields(out, names, last, rows, done, title=title, scale=scale, field=field, camera=camera,
                     obstacles=summary.get("obstacles"))
    else:
        for name in ("deformed.png", "error_indicator.png"):
            done.setdefault(name, "not drawn: no fields (the run was made with fields = false)")
    return {name: done[name] for name in names if name in done}


def _picture_names(names: Collection[str]) -> list[str]:
    """``names``, of :data:`PICTURES`, in the order of :data:`PICTURES`; ValueError names the others."""
    unknown = set(names) - set(PICTURES)
    if unknown:
        raise ValueError(f"pictures {sorted(unknown)}: expected some of {PICTURES}")
    return [name for name in PICTURES if name in names]


def _attempt(done: dict[str, Path | str], out: Path, name: str, draw: Callable[..., object], /, *args: Any,
             **kwargs: Any) -> None:
    """``done[name]``: the picture ``draw(*args, path, **kwargs)`` drawn whole at ``out / name``,
    or why not, for the reasons a folder's data or the machine give (a missing field, no VTK)."""
    try:
        done[name] = _whole_picture(out / name, lambda path: draw(*args, path, **kwargs))
    except (ValueError, KeyError, OSError, IndexError, PictureUnavailable) as error:  # data missing, no VTK
        done[name] = f"not drawn: {error}"


def _start_fields(folder: Path, names: Collection[str], step: dict | None,
                  done: dict[str, Path | str]) -> Callable[[], list[dict]] | None:
    """What returns the field steps of the pictures drawn on the mesh, or None (none asked for,
    or no ``fields.xdmf``; a failure to start reading goes in ``done``).

    The reading starts here, before the curves are drawn: where this process cannot use h5py,
    a child process reads the last step meanwhile (:func:`~dolfinx_nnqem.io.reader.start_reading_fields`).
    """
    if "deformed.png" not in names and "error_indicator.png" not in names:
        return None
    if step is not None:
        return lambda: [step]  # from memory: nothing to read
    if not (folder / "fields.xdmf").exists():
        return None
    try:
        return start_reading_fields(folder, last_only=True)
    except OSError as error:
        done["deformed.png"] = f"not drawn: {error}"
        return None


def _wait_for_fields(fields: Callable[[], list[dict]] | None, done: dict[str, Path | str]) -> list[dict]:
    """The field steps ``fields`` returns, waited for; none without it, or when reading failed
    (the reason goes in ``done``)."""
    try:
        return fields() if fields is not None else []
    except OSError as error:
        done["deformed.png"] = f"not drawn: {error}"
        return []


def _draw_curves(out: Path, names: Collection[str], summary: dict, rows: list[dict], title: str,
                 done: dict[str, Path | str]) -> None:
    """The pictures of ``names`` drawn from the pair CSV and ``summary.json``: the pair pressure,
    the load curve, the convergence and the error estimates."""
    if "pair_pressure.png" not in names:
        pass
    elif rows:
        _attempt(done, out, "pair_pressure.png", draw_pair_pressure, rows, title=title)
    else:
        done["pair_pressure.png"] = "not drawn: no contact pairs"
    if "load_curve.png" in names:
        _attempt(done, out, "load_curve.png", draw_load_curve, summary, title=title)
    if "convergence.png" in names:
        _attempt(done, out, "convergence.png", draw_convergence, summary, title=title)
    if ESTIMATE_PICTURE in names and "error_estimates" in summary:  # (a run without estimates: none)
        _attempt(done, out, ESTIMATE_PICTURE, draw_error_estimates, summary, title=title)


def _draw_fields(out: Path, names: Collection[str], last: dict, rows: list[dict], done: dict[str, Path | str], *,
                 title: str, scale: float | None, field: str, camera: str, obstacles: dict | None) -> None:
    """The pictures of ``names`` drawn on the deformed mesh of the ``last`` field step, with the
    rigid ``obstacles`` of ``summary.json``: ``deformed.png`` and ``error_indicator.png``, one
    scene coloured in turn by ``field`` and by the error indicator (:class:`DeformedScene`)."""
    scene = DeformedScene(last, rows, title=title, scale=scale, camera=camera, obstacles=obstacles)
    try:
        if "deformed.png" in names:
            _attempt(done, out, "deformed.png", scene.draw, field)
        if "error_indicator.png" in names and "error_indicator" in last:  # (written by the command line)
            _attempt(done, out, "error_indicator.png", scene.draw, "error_indicator")
    finally:
        scene.close()


CONTACT_PICTURE = "contact_pressure.png"
"""The picture of the contact pressure on the deformed bodies' surface (the live problem's)."""

ALL_PICTURES = (*PICTURES, CONTACT_PICTURE)
"""Every picture the end of a run draws, in their order."""


def pictures_of_run(folder: str | os.PathLike) -> tuple[str, ...]:
    """The pictures of :data:`ALL_PICTURES` that the run in ``folder`` makes.

    ``error_estimates.png`` only where ``summary.json`` holds an estimate, and
    ``error_indicator.png`` only where ``fields.xdmf`` holds that cell field (a command-line run
    writes it, a Python run with its own writers may not); without ``fields.xdmf`` neither
    ``deformed.png`` nor ``error_indicator.png``. Otherwise a restart would look for a picture
    the run never draws, and draw "the rest" again on every restart.
    """
    folder = Path(folder)
    try:
        summary = read_summary(folder)
    except (OSError, ValueError):
        summary = {}
    fields = folder / "fields.xdmf"
    try:
        fields_text = fields.read_text(errors="replace") if fields.is_file() else None
    except OSError:
        fields_text = None
    left_out = set()
    if "error_estimates" not in summary:
        left_out.add(ESTIMATE_PICTURE)
    if fields_text is None:
        left_out.update(("deformed.png", "error_indicator.png"))
    elif f'Name="{INDICATOR_FIELD}"' not in fields_text:
        left_out.add("error_indicator.png")
    return tuple(name for name in ALL_PICTURES if name not in left_out)


def missing_pictures(folder: str | os.PathLike) -> tuple[str, ...]:
    """The pictures of :func:`pictures_of_run` that ``folder/pictures`` does not hold (a picture
    there is whole: each is written to a temporary and renamed)."""
    pictures = Path(folder) / PICTURE_FOLDER
    return tuple(name for name in pictures_of_run(folder) if not (pictures / name).is_file())


def draw_job(job: Mapping[str, Any]) -> dict[str, Path | str]:
    """Draw the end-of-run pictures a job names, in this process; never raises for a picture.

    The same function draws them in the run's process and in a picture worker
    (:mod:`dolfinx_nnqem.io.picture_worker`): a job holds plain data only.

    Parameters
    ----------
    job
        ``folder`` (the results folder), ``names`` (pictures of :data:`PICTURES`), ``step``
        (the last increment's fields from memory, or None) and ``contact``: for
        :data:`CONTACT_PICTURE`, the data of :func:`~dolfinx_nnqem.io.plots.contact_pressure_data`,
        the reason it is not drawn (a string), or None (not asked for).

    Returns
    -------
    dict
        Per picture, its path or the reason it was not drawn (``"not drawn: ..."``), in the
        order of :data:`PICTURES`, :data:`CONTACT_PICTURE` last.
    """
    folder = Path(job["folder"])
    names = tuple(job.get("names", ()))
    done: dict[str, Path | str] = {}
    if names:
        try:
            done = draw_run_pictures(folder, step=job.get("step"), names=names)
        except Exception as error:  # noqa: BLE001  (the results are written; a picture is a bonus)
            done = {name: f"not drawn: {type(error).__name__}: {error}" for name in names}
    contact = job.get("contact")
    if isinstance(contact, str):
        done[CONTACT_PICTURE] = contact
    elif contact is not None:
        path = folder / PICTURE_FOLDER / CONTACT_PICTURE
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            done[CONTACT_PICTURE] = _whole_picture(path, lambda tmp: plots.draw_contact_pressure(contact, tmp))
        except Exception as error:  # noqa: BLE001  (as above: a picture never ends the run)
            done[CONTACT_PICTURE] = f"not drawn: {type(error).__name__}: {error}"
    return done


class PictureDrawer(Protocol):
    """What draws a job of :func:`draw_job` elsewhere (the picture workers of a run,
    :class:`~dolfinx_nnqem.io.picture_worker.PictureWorkers`)."""

    def draw(self, job: Mapping[str, Any]) -> dict[str, Path | str]:
        """The same as ``draw_job(job)``."""
        ...


def draw_live_pictures(problem: ContactProblem, folder: str | os.PathLike, *, completed: bool,
                       step: dict | None = None, worker: PictureDrawer | None = None,
                       names: Collection[str] = ALL_PICTURES) -> dict[str, Path | str]:
    """The end of a run: :func:`draw_run_pictures` on rank 0 (with the run's last ``step`` of
    the fields, from memory, where it has one), and :data:`CONTACT_PICTURE` of the live problem.

    Collective. ``contact_pressure.png`` is drawn from the problem's pair table and slave surface,
    gathered on rank 0 (:func:`~dolfinx_nnqem.io.plots.contact_pressure_data`), when the problem
    has contact and the run ``completed`` (after a failed increment the problem holds no
    converged state); otherwise that picture is skipped. A picture that cannot be drawn never
    ends the run: its reason is logged.

    ``worker``: picture workers started with the run (:mod:`dolfinx_nnqem.io.picture_worker`,
    rank 0's; None elsewhere): they draw the pictures, with their libraries imported already;
    what a worker could not draw (it died, it could not start) is drawn here. Without one,
    everything is drawn in this process (:func:`draw_job`).

    ``names``: the pictures to draw, of :data:`ALL_PICTURES` (the same on every rank; a restart
    of a run that had completed draws the missing ones).
    """

    folder = Path(folder)
    contact: dict | str | None = None  # rank 0: the data of contact_pressure.png, or why not
    if CONTACT_PICTURE in names and problem.has_contact and completed:
        try:  # the gathers inside are reached on every rank before anything can fail
            contact = plots.contact_pressure_data(problem)
        except Exception as error:  # noqa: BLE001  (a picture never ends the run)
            contact = f"not drawn: {type(error).__name__}: {error}"
    done: dict[str, Path | str] = {}
    if problem.comm.rank == 0:
        job = {"folder": folder, "names": tuple(name for name in PICTURES if name in names), "step": step,
               "contact": contact}
        done = worker.draw(job) if worker is not None else draw_job(job)
    done = problem.comm.bcast(done, root=0)
    for name, result in done.items():
        if isinstance(result, str):
            _log.warning(f"picture {name}: {result}")
    return done

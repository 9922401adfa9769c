"""The ``nurbsdem`` command line.

Commands here: ``info``, ``shape``, ``import-giraffe``, ``import-3dm``. More are added to
the group :data:`main` elsewhere.

Error handling: every error that is the user's fault (:class:`~nurbsdem.errors.NurbsdemError`,
and :class:`OSError` for files) is printed as one line
``nurbsdem: error: <file>:<line or patch>: <message>`` on stderr with exit status 2 and no
traceback. The group class :class:`NurbsdemGroup` does this for every subcommand (so
``@main.command()`` is all a new command needs); :func:`handles_errors` is the same wrapper
as a decorator for code outside the group (put it directly above the ``def``).
Any other exception is a bug: one line ``nurbsdem: internal error (a bug ...)`` naming a log
file that holds the traceback, exit status 3 (``NURBSDEM_DEBUG=1`` shows the traceback).
RuntimeWarnings are not shown.
"""
from __future__ import annotations

import functools
import math
import sys
from pathlib import Path
from typing import Any, Callable, NoReturn

import click
import numpy as np

from . import __version__
from .errors import NurbsdemError

#: Exit status for errors that are the user's fault.
EXIT_USER_ERROR = 2


def error_message(exc: BaseException) -> str:
    """The one-line text of a user error (without the ``nurbsdem: error:`` prefix)."""
    if isinstance(exc, OSError) and not isinstance(exc, NurbsdemError):
        name = exc.filename
        what = exc.strerror or str(exc)
        return f"{name}: {what}" if name is not None else what
    return " ".join(str(exc).split("\n"))


def fail(message: str) -> NoReturn:
    """Print ``nurbsdem: error: message`` on stderr and exit with status 2."""
    click.echo(f"nurbsdem: error: {message}", err=True)
    raise click.exceptions.Exit(EXIT_USER_ERROR)


def warn(message: str) -> None:
    """Print ``nurbsdem: warning: message`` on stderr."""
    click.echo(f"nurbsdem: warning: {message}", err=True)


def handles_errors(func: Callable) -> Callable:
    """Decorator: the error policy of :func:`run_reporting_errors` (user errors one line,
    exit status 2; internal errors one line and a log file, exit status 3)."""

    @functools.wraps(func)
    def wrapper(*args: Any, **kwargs: Any) -> Any:
        return run_reporting_errors(lambda: func(*args, **kwargs))

    return wrapper


#: Exit status for internal errors (bugs): one line on stderr, the traceback in a log file.
EXIT_INTERNAL_ERROR = 3


def internal_error_log(exc: BaseException) -> Path | None:
    """Write the traceback of an unexpected exception to a log file (in the temporary
    folder, or ``$NURBSDEM_ERROR_LOG``) and return its path (None if it cannot be written)."""
    import datetime
    import os
    import tempfile
    import traceback

    stamp = datetime.datetime.now().strftime("%Y%m%d-%H%M%S")
    path = Path(os.environ.get("NURBSDEM_ERROR_LOG")
                or Path(tempfile.gettempdir()) / f"nurbsdem-error-{stamp}-{os.getpid()}.log")
    text = (f"nurbsdem {__version__}, python {sys.version.split()[0]}\n"
            f"command: {' '.join(sys.argv)}\n\n"
            + "".join(traceback.format_exception(type(exc), exc, exc.__traceback__)))
    try:
        path.write_text(text)
    except OSError:
        return None
    return path


def internal_error(exc: BaseException) -> NoReturn:
    """Report a bug in one line (exit status 3); the traceback goes to a log file."""
    log = internal_error_log(exc)
    where = f"; the traceback is in {log}" if log is not None else ""
    what = " ".join(f"{type(exc).__name__}: {exc}".split())
    if len(what) > 200:
        what = what[:200] + "..."
    click.echo(f"nurbsdem: internal error (a bug in nurbsdem, please report it): {what}{where}",
               err=True)
    raise click.exceptions.Exit(EXIT_INTERNAL_ERROR)


def run_reporting_errors(call: Callable[[], Any]) -> Any:
    """Run ``call()`` with the command line's error policy: user errors (NurbsdemError,
    OSError, MemoryError) as one line with exit status 2, interruptions with 130, anything
    else as an internal error (exit status 3, traceback in a log file). Numerical
    RuntimeWarnings are not shown (the checks report what matters).
    Set ``NURBSDEM_DEBUG=1`` to get Python's traceback instead."""
    import os
    import warnings

    with warnings.catch_warnings(), np.errstate(all="ignore"):
        warnings.simplefilter("ignore", RuntimeWarning)
        try:
            result = call()
            sys.stdout.flush()          # a closed pipe shows here (e.g. ``| head``)
            return result
        except (click.exceptions.ClickException, click.exceptions.Exit, click.exceptions.Abort):
            raise
        except BrokenPipeError:
            _quiet_broken_pipe()
        except (NurbsdemError, OSError) as exc:
            fail(error_message(exc))
        except MemoryError:
            fail("out of memory: the model is too large for this machine")
        except KeyboardInterrupt as exc:
            said = " ".join(str(exc).split())
            click.echo(f"nurbsdem: {said}" if said else "nurbsdem: interrupted", err=True)
            raise click.exceptions.Exit(130)
        except Exception as exc:
            if os.environ.get("NURBSDEM_DEBUG"):
                raise
            internal_error(exc)


#: Exit status when the reader of the standard output went away (128 + SIGPIPE, what a
#: program killed by SIGPIPE reports to the shell).
EXIT_BROKEN_PIPE = 141


def _quiet_broken_pipe() -> NoReturn:
    """The reader of stdout closed the pipe (``nurbsdem info ... | head``): nothing more can
    be shown there, so exit quietly.  stdout is pointed at /dev/null first so that the
    interpreter's own flush at exit does not fail again and print a traceback."""
    import os
    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        os.close(devnull)
    except (OSError, ValueError, AttributeError):     # not a real file (e.g. tests)
        pass
    raise click.exceptions.Exit(EXIT_BROKEN_PIPE)


class NurbsdemGroup(click.Group):
    """A click group whose subcommands all report user errors as one line (exit 2) and
    internal errors as one line pointing to a log file (exit 3)."""

    def invoke(self, ctx: click.Context) -> Any:
        return run_reporting_errors(lambda: super(NurbsdemGroup, self).invoke(ctx))


@click.group(cls=NurbsdemGroup)
@click.version_option(__version__, prog_name="nurbsdem")
def main() -> None:
    """nurbsdem: DEM with exact convex NURBS particles."""


# ---------------------------------------------------------------------- info
def _fmt_vec(v) -> str:
    return "[" + ", ".join(f"{x:.9g}" for x in np.asarray(v).ravel()) + "]"


def _warnings_to_stderr(func: Callable) -> Callable:
    """Decorator: while the command runs, the ``nurbsdem`` logger's warnings (e.g. a nearly
    convex shape) go to the current stderr as ``nurbsdem: warning: ...`` (one line each)."""
    import logging

    class _Echo(logging.Handler):
        def emit(self, record: logging.LogRecord) -> None:
            warn(record.getMessage())

    @functools.wraps(func)
    def wrapper(*args: Any, **kwargs: Any) -> Any:
        log = logging.getLogger("nurbsdem")
        saved = (log.handlers[:], log.propagate, log.level)
        log.handlers = [_Echo(logging.WARNING)]
        log.propagate = False
        log.setLevel(logging.WARNING)
        try:
            return func(*args, **kwargs)
        finally:
            log.handlers, log.propagate = saved[0], saved[1]
            log.setLevel(saved[2])

    return wrapper


def _convexity_tol_option(func: Callable) -> Callable:
    """The ``--convexity-tol`` option (accepted non-convexity relative to the size)."""
    return click.option(
        "--convexity-tol", "convexity_tol", type=click.FloatRange(min=0.0), default=None,
        help="Accepted non-convexity (height of the surface above its own tangent planes) "
             "relative to the particle size; default 1e-4, 0 = strict.")(func)


@main.command()
@click.argument("shape_file", metavar="SHAPE.yaml")
@click.option("--density", type=float, default=None,
              help="Also print mass (kg) and mass inertia (kg m^2) for this density (kg/m^3).")
@_convexity_tol_option
def info(shape_file: str, density: float | None, convexity_tol: float | None) -> None:
    """Print a shape's patches, mass properties and checks."""
    from .geometry.connectivity import (DEFAULT_CONVEXITY_TOL, check_shape, convexity_warning,
                                        measure_convexity)
    from .io.shapefile import load_shape

    if density is not None and not (math.isfinite(density) and density > 0):
        raise NurbsdemError(f"--density must be a positive number (kg/m^3), got {density:g}")
    shape = load_shape(shape_file, check=False)
    conn = shape.connectivity
    out = click.echo
    out(f"shape: {shape.name or '(unnamed)'}  ({shape_file})")
    out(f"patches: {len(shape.patches)}")
    for i, p in enumerate(shape.patches):
        nu, nv = p.shape
        spans_u = len(np.unique(p.knots_u)) - 1
        spans_v = len(np.unique(p.knots_v)) - 1
        rational = "rational" if not np.all(p.weights == p.weights.flat[0]) else "polynomial"
        out(f"  patch {i}: degrees ({p.degree_u}, {p.degree_v}), control points {nu} x {nv}, "
            f"knot spans {spans_u} x {spans_v}, domain {_fmt_vec(p.domain)}, {rational}")
    npole = int(np.sum(conn.neighbours[:, :, 0] == -2))
    nseam = sum(1 for i in range(len(shape.patches)) for e in range(4)
                if conn.neighbours[i, e, 0] == i)
    out(f"connectivity: {len(conn.corners)} corner nodes (3+ patches), {npole} pole edges, "
        f"{nseam} seam edges")
    out(f"volume: {shape.volume:.9g} m^3")
    out(f"centroid: {_fmt_vec(shape.centroid)} m")
    out("inertia tensor about the centroid (volume, m^5):")
    for row in shape.inertia:
        out("  " + _fmt_vec(row))
    moments, axes = np.linalg.eigh(shape.inertia)
    out(f"principal moments (m^5): {_fmt_vec(moments)}")
    out("principal axes (columns):")
    for row in axes:
        out("  " + _fmt_vec(row))
    if density is not None:
        out(f"mass: {density * shape.volume:.9g} kg  (density {density:g} kg/m^3)")
        out(f"principal moments (kg m^2): {_fmt_vec(density * moments)}")
    out(f"bounding radius: {shape.bounding_radius:.9g} m")
    closed = conn.closed
    out(f"closed: {'yes' if closed else 'no'}")
    tol = DEFAULT_CONVEXITY_TOL if convexity_tol is None else convexity_tol
    cv = measure_convexity(shape.patches)
    out(f"non-convexity: {cv.height:.3g} m = {cv.relative:.3g} of the size {cv.size:.6g} m "
        f"(tolerance {tol:g}; height of the surface above its own tangent planes)"
        + ("" if cv.convex else f"; {cv.where}: {cv.describe()}"))
    try:
        cv = check_shape(shape, source=shape_file, convexity_tol=tol)
    except NurbsdemError:
        out("convex, outward oriented: no")
        raise
    msg = convexity_warning(cv, shape_file, tol)
    if msg:
        warn(msg)
    out("convex, outward oriented: yes" + (" (within the tolerance)" if msg else ""))


# ---------------------------------------------------------------------- shape
_KINDS = ("sphere", "ellipsoid", "single-patch-sphere", "particle")
#: open wall surfaces (:mod:`nurbsdem.geometry.surfaces`): written as patches, not particles
_SURFACES = ("cylinder", "cone", "plane")


@main.command()
@click.argument("kind", type=click.Choice(_KINDS + _SURFACES))
@click.option("-o", "--output", required=True, metavar="FILE.yaml", help="Shape file to write.")
@click.option("--radius", type=float, help="Radius (m) for sphere and single-patch-sphere.")
@click.option("--semi-axes", type=(float, float, float), default=None, metavar="A B C",
              help="Semi-axes along x, y, z (m) for ellipsoid.")
@click.option("--kind", "particle_kind", type=click.Choice(["A", "B", "C"]),
              help="Which of the paper's particles, for particle.")
@click.option("--length", type=float, help="Length along the axis (m) for cylinder and cone.")
@click.option("--top-radius", type=float, help="Radius at the far end (m) for cone.")
@click.option("--size", type=(float, float), default=None, metavar="LU LV",
              help="Side lengths (m) for plane.")
@click.option("--outward", is_flag=True,
              help="cylinder, cone: the front faces away from the axis (default: towards it).")
@click.option("--name", default=None, help="Name stored in the file.")
def shape(kind: str, output: str, radius: float | None, semi_axes, particle_kind: str | None,
          length: float | None, top_radius: float | None, size, outward: bool,
          name: str | None) -> None:
    """Generate a shape file: KIND is sphere (--radius), ellipsoid (--semi-axes A B C),
    single-patch-sphere (--radius) or particle (--kind A|B|C); or an open wall surface:
    cylinder (--radius --length), cone (--radius --top-radius --length) along z from the
    origin, or plane (--size LU LV) through the origin with its front along +z."""
    if kind in _SURFACES:
        _surface_file(kind, output, radius, length, top_radius, size, outward, name)
        return
    from .geometry import generators as gen
    from .geometry.shape import Shape
    from .io.shapefile import save_shape

    def need(value, opt: str):
        if value is None:
            raise NurbsdemError(f"shape {kind}: {opt} is required")
        if not isinstance(value, str):
            for x in np.ravel(value):
                if x > 0:   # zero, negative, nan: the generator's own message
                    _check_length(float(x), f"shape {kind}: {opt}")
        return value

    try:
        if kind == "sphere":
            patches = gen.sphere_patches(need(radius, "--radius"))
            default = f"sphere r={radius:g}"
        elif kind == "single-patch-sphere":
            patches = gen.single_patch_sphere_patches(need(radius, "--radius"))
            default = f"single-patch sphere r={radius:g}"
        elif kind == "ellipsoid":
            a, b, c = need(semi_axes, "--semi-axes A B C")
            patches = gen.ellipsoid_patches(a, b, c)
            default = f"ellipsoid {a:g}x{b:g}x{c:g}"
        else:
            from .geometry.particles import paper_particle
            patches = paper_particle(need(particle_kind, "--kind A|B|C"))
            default = str(particle_kind)
    except ValueError as exc:  # bad radius / semi-axes
        raise NurbsdemError(f"shape {kind}: {exc}") from None
    sh = Shape(patches, name=name if name is not None else default)
    save_shape(output, sh)
    click.echo(f"wrote {output}: {sh.name}, {len(sh.patches)} patches, "
               f"volume {sh.volume:.9g} m^3")


def _surface_file(kind: str, output: str, radius, length, top_radius, size, outward: bool,
                  name: str | None) -> None:
    """``nurbsdem shape cylinder|cone|plane``: one exact open patch written as a shape file."""
    from .geometry import surfaces
    from .io.shapefile import save_shape

    def need(value, opt: str):
        if value is None:
            raise NurbsdemError(f"shape {kind}: {opt} is required")
        return value

    try:
        if kind == "cylinder":
            patch = surfaces.cylinder_patch(need(radius, "--radius"), need(length, "--length"),
                                            inward=not outward)
            default = f"cylinder r={radius:g} l={length:g}"
        elif kind == "cone":
            patch = surfaces.cone_patch(need(radius, "--radius"),
                                        need(top_radius, "--top-radius"),
                                        need(length, "--length"), inward=not outward)
            default = f"cone r={radius:g}..{top_radius:g} l={length:g}"
        else:
            lu, lv = need(size, "--size LU LV")
            patch = surfaces.plane_patch((0, 0, 0), (0, 0, 1), (lu, lv), (1, 0, 0))
            default = f"plane {lu:g}x{lv:g}"
    except ValueError as exc:
        raise NurbsdemError(f"shape {kind}: {exc}") from None
    save_shape(output, [patch], name=name if name is not None else default)
    click.echo(f"wrote {output}: {name or default}, 1 open patch (a wall surface)")


# ---------------------------------------------------------------------- imports
def _checked(sh, convexity_tol: float | None):
    """The shape checked (closed, outward, convex within ``convexity_tol``); a nearly convex
    shape's warning goes to the ``nurbsdem`` logger (one line)."""
    from .geometry.shape import Shape
    return Shape(sh.patches, name=sh.name, source=sh.source, convexity_tol=convexity_tol)


def _check_length(x: float, what: str) -> None:
    """A size given on the command line: finite, > 0 and in the range the deck accepts."""
    from .io.deck import RANGES
    rng = RANGES["Radius"]
    if not (math.isfinite(x) and x > 0):
        raise NurbsdemError(f"{what} must be a positive number (m), got {x:g}")
    if not rng.lo <= x <= rng.hi:
        raise NurbsdemError(f"{what} {x:g} m is out of range: it must be between {rng.lo:g} "
                            f"and {rng.hi:g} m ({rng.reason})")


def _finish_import(sh, output: str, scale: float) -> None:
    from .io.shapefile import check_patch_numbers, save_shape

    if scale != 1.0:
        if not (math.isfinite(scale) and scale > 0):
            raise NurbsdemError(f"--scale must be a positive number, got {scale:g}")
        size = scale * max(float(np.abs(p.control_points).max()) for p in sh.patches)
        _check_length(size, f"--scale {scale:g}: the scaled shape's largest coordinate")
        sh = sh.scaled(scale)
        for i, p in enumerate(sh.patches):
            check_patch_numbers(p, f"{output} (after --scale {scale:g})", f"patch {i}")
    save_shape(output, sh)
    click.echo(f"wrote {output}: {sh.name}, {len(sh.patches)} patches, "
               f"volume {sh.volume:.9g} m^3")


@main.command("import-giraffe")
@click.argument("cad_file", metavar="FILE")
@click.option("-o", "--output", required=True, metavar="SHAPE.yaml", help="Shape file to write.")
@click.option("--name", default=None, help="Name stored in the file (default: file stem).")
@click.option("--scale", type=float, default=1.0, show_default=True,
              help="Factor applied to the coordinates (e.g. 0.001 for mm -> m).")
@_convexity_tol_option
@_warnings_to_stderr
def import_giraffe_cmd(cad_file: str, output: str, name: str | None, scale: float,
                       convexity_tol: float | None) -> None:
    """Convert a Giraffe CAD file (one record per patch) to a shape file."""
    from .io.giraffe import import_giraffe

    sh, warnings = import_giraffe(cad_file, name=name, check=False)
    sh = _checked(sh, convexity_tol)
    for w in warnings:
        warn(f"{cad_file}: {w}")
    _finish_import(sh, output, scale)


@main.command("import-3dm")
@click.argument("cad_file", metavar="FILE.3dm")
@click.option("-o", "--output", required=True, metavar="SHAPE.yaml", help="Shape file to write.")
@click.option("--name", default=None, help="Name stored in the file (default: file stem).")
@click.option("--scale", type=float, default=1.0, show_default=True,
              help="Factor applied to the coordinates (e.g. 0.001 for mm -> m).")
@_convexity_tol_option
@_warnings_to_stderr
def import_3dm_cmd(cad_file: str, output: str, name: str | None, scale: float,
                   convexity_tol: float | None) -> None:
    """Convert the NURBS surfaces and Brep faces of a Rhino .3dm file to a shape file
    (needs the optional package rhino3dm)."""
    from .io.rhino import import_3dm

    sh = _checked(import_3dm(cad_file, name=name, check=False), convexity_tol)
    _finish_import(sh, output, scale)


# ---------------------------------------------------------------------- fit, export
@main.command("fit")
@click.argument("mesh_file", metavar="MESH")
@click.option("-o", "--output", required=True, metavar="SHAPE.yaml", help="Shape file to write.")
@click.option("--control-points", "n_cp", type=click.IntRange(3, 20), default=8,
              show_default=True, help="Control points per patch and direction.")
@click.option("--degree", type=click.IntRange(2, 5), default=3, show_default=True,
              help="Degree of the patches (3: bicubic).")
@click.option("--scale", type=float, default=1.0, show_default=True,
              help="Factor applied to the coordinates (e.g. 0.001 for mm -> m).")
@click.option("--name", default=None, help="Name stored in the file (default: file stem).")
@_convexity_tol_option
@_warnings_to_stderr
def fit_cmd(mesh_file: str, output: str, n_cp: int, degree: int, scale: float,
            name: str | None, convexity_tol: float | None) -> None:
    """Fit a closed six-patch NURBS particle (cube-sphere) by least squares to the convex hull
    of a mesh, or to the points of a cloud (STL, PLY, OBJ, OFF, or XYZ text)."""
    from .geometry.fit import fit_particle, read_input
    from .io.shapefile import save_shape

    if not (math.isfinite(scale) and scale > 0):
        raise NurbsdemError(f"--scale must be > 0, got {scale:g}")
    data = read_input(mesh_file)
    if scale != 1.0:
        data.points = data.points * scale
        if data.mesh is not None:
            data.mesh = data.mesh.copy()
            data.mesh.apply_scale(scale)
    res = fit_particle(data, n_cp=n_cp, degree=degree, convexity_tol=convexity_tol,
                       name=name if name is not None else Path(mesh_file).stem)
    for line in res.lines():
        click.echo(line)
    save_shape(output, res.shape)
    click.echo(f"wrote {output}: {res.shape.name}, 6 patches, volume {res.shape.volume:.9g} m^3")


@main.command("export")
@click.argument("shape_file", metavar="SHAPE.yaml")
@click.option("-o", "--output", required=True, metavar="FILE",
              help="FILE.stl (tessellated triangles) or FILE.3dm (Rhino NURBS surfaces).")
@click.option("--resolution", type=click.IntRange(1, 512), default=24, show_default=True,
              help="STL: quads per patch and parameter direction (two triangles each).")
@_convexity_tol_option
@_warnings_to_stderr
def export_cmd(shape_file: str, output: str, resolution: int,
               convexity_tol: float | None) -> None:
    """Export a shape to STL (for other DEM codes and printers) or Rhino .3dm (NURBS)."""
    from .io.export import export_shape
    from .io.shapefile import load_shape

    shape = load_shape(shape_file, convexity_tol=convexity_tol)
    click.echo(export_shape(shape, output, resolution))


# --------------------------------------------------------------------------- the solver
def _setup_logging(quiet: bool, verbose: bool) -> None:
    import logging
    level = logging.WARNING if quiet else (logging.DEBUG if verbose else logging.INFO)
    if _launched_rank() > 0:
        level = logging.ERROR        # several MPI ranks: rank 0 tells what happens
    logger = logging.getLogger("nurbsdem")
    logger.setLevel(level)
    if not logger.handlers:
        h = logging.StreamHandler()
        h.setFormatter(logging.Formatter("nurbsdem: %(levelname)s: %(message)s"))
        logger.addHandler(h)
    logger.propagate = False


@main.command()
@click.argument("deck", metavar="CASE.inp")
@_warnings_to_stderr
def check(deck: str) -> None:
    """Parse and validate a deck without solving; print a model summary (warnings on
    stderr, ``nurbsdem: warning: deck:line: ...``)."""
    from .io.deck import parse_deck
    model = parse_deck(deck)
    click.echo(model.summary())
    for line in _output_times(model):
        click.echo(line)
    click.echo(f"{deck}: OK")


def _output_times(model) -> list[str]:
    """When the output is written, per time step of the deck's steps: an interval that is
    not a whole number of time steps is served by the first time step at or after each of
    its multiples (:mod:`nurbsdem.io.intervals`)."""
    from .io import intervals
    out = model.output
    settings = (("VTK", out.vtk_every), ("monitors", out.monitors_every),
                ("results.h5", out.results_interval), ("checkpoints", out.checkpoint_every))
    by_dt: dict[float, list[int]] = {}
    for s in model.steps:
        dt = getattr(s, "time_step", None)
        if dt:
            by_dt.setdefault(float(dt), []).append(s.id)
    lines, inexact = [], False
    for dt, ids in by_dt.items():
        parts = [f"{name} {intervals.describe(every, dt)}" for name, every in settings]
        inexact |= any(every > 0 and not intervals.exact(every, dt) for _, every in settings)
        which = "step" if len(ids) == 1 else "steps"
        lines.append(f"output with TimeStep {dt:g} s ({which} {', '.join(map(str, ids))}): "
                     + "; ".join(parts))
    if inexact:
        lines.append("(an output interval that is not a whole number of time steps is served "
                     "by the first time step at or after each of its multiples)")
    return lines


@main.command()
@click.argument("deck", metavar="CASE.inp")
@click.option("--output", "output", default=None, metavar="DIR",
              help="Results directory (default: the deck's Output Directory).")
@click.option("--restart", default=None, metavar="FILE",
              help="Continue from a checkpoint (e.g. results/checkpoint.h5).")
@click.option("--quiet", is_flag=True, help="No progress display and no log messages.")
@click.option("--verbose", is_flag=True, help="Debug log messages.")
def solve(deck: str, output: str | None, restart: str | None, quiet: bool, verbose: bool) -> None:
    """Run the solution steps of a deck and write the results."""
    from .simulation import Simulation
    _setup_logging(quiet, verbose)
    sim = Simulation.from_deck(deck, output=output, restart=restart, quiet=quiet)
    rank = _launched_rank()
    if not quiet and rank == 0:
        _tell_first_compilation()
    if restart is not None and Path(restart).parent.is_dir() and rank == 0:
        from .io.writers import clean_output_directory
        clean_output_directory(Path(restart).parent)   # undo a killed run; stale temporaries
    if restart is not None and not Path(restart).is_file():
        fail(f"{restart}: no such checkpoint file")
    from .first_run import prepare_first_solve
    loop = prepare_first_solve(sim)   # a cold cache: compile in parallel, loop in the background
    from .warmup import reporting_compiles
    try:
        with reporting_compiles(not quiet and rank == 0):      # names each kernel it compiles
            summary = _stopping_all_ranks(sim.run)   # the Python API's path: Simulation -> Solver
    finally:
        if loop is not None:
            loop.finish()
    if not quiet and rank == 0:
        click.echo(summary.text())
        click.echo(f"results in {sim.solver.outdir}")


@main.command()
@click.option("--jobs", type=click.IntRange(min=1), default=None,
              help="Stages compiled at the same time, each in its own process "
                   "(default: the usable cores).")
@click.option("--all", "everything", is_flag=True,
              help="Also the kernels of mesh and surface walls.")
def warmup(jobs: int | None, everything: bool) -> None:
    """Compile the solver's kernels into numba's cache now, so that the first run starts at
    once (after an install, an upgrade or an edit of the kernels' sources)."""
    from .warmup import ALL_STAGES, STAGES, warm_up
    stages = ALL_STAGES if everything else STAGES
    total = sum(s.weight for s in stages)
    with click.progressbar(length=1000, label="compiling the kernels", show_eta=False,
                           file=sys.stderr) as bar:
        def done(name: str, seconds: float) -> None:
            bar.label = f"compiled {name} ({seconds:.0f} s)"
            weight = next(s.weight for s in stages if s.name == name)
            bar.update(round(1000 * weight / total))
        times = warm_up(jobs, on_done=done, stages=stages)
    click.echo(f"kernels compiled in {len(times)} stages: "
               + ", ".join(f"{name} {seconds:.0f} s" for name, seconds in times.items()))


def _tell_first_compilation() -> None:
    """One log line when numba's cache lacks the compiled loop (a fresh install, an upgrade
    or an edited source): the run starts only after minutes of compiling."""
    import logging

    from numba.core import config

    from .cachecheck import compiles_first
    if config.DISABLE_JIT:
        logging.getLogger("nurbsdem").info(
            "NUMBA_DISABLE_JIT is set: the kernels run as plain Python (for debugging; "
            "hundreds of times slower, the same results)")
    elif compiles_first():
        logging.getLogger("nurbsdem").info(
            "compiling the kernels for this machine first (once after an install, an upgrade "
            "or an edit of their sources; `nurbsdem warmup` compiles them ahead; later runs "
            "load them from the cache)")


def _launched_rank() -> int:
    """This process's rank when an MPI launcher started it (0 otherwise), from the
    launcher's environment (without initialising MPI)."""
    import os
    for name in ("PMI_RANK", "OMPI_COMM_WORLD_RANK", "PMIX_RANK"):
        value = os.environ.get(name, "")
        if value.isdigit():
            return int(value)
    return 0


def _stopping_all_ranks(call: Callable[[], Any]) -> Any:
    """``call()``; on several MPI ranks an error on one of them stops all (MPI_Abort, after
    the one-line message), instead of leaving the others waiting for it."""
    try:
        return call()
    except BaseException as exc:
        mpi = sys.modules.get("mpi4py.MPI")
        if mpi is None or mpi.COMM_WORLD.size == 1:
            raise
        if isinstance(exc, (NurbsdemError, OSError)):
            message, code = f"nurbsdem: error: {error_message(exc)}", EXIT_USER_ERROR
        else:
            message = f"nurbsdem: internal error on rank {mpi.COMM_WORLD.rank}: {exc!r}"
            code = EXIT_INTERNAL_ERROR
        click.echo(message, err=True)
        sys.stderr.flush()
        mpi.COMM_WORLD.Abort(code)
        raise


@main.command()
@click.option("--quick", is_flag=True, help="The CI mode (about two minutes on 2 cores).")
@click.option("--output", default=None, metavar="DIR",
              help="Folder of verification.md and its figures (default: docs/ of the checkout).")
def bench(quick: bool, output: str | None) -> None:
    """Run the benchmarks and write the verification report (docs/verification.md + PNGs).

    Needs a source checkout: the report lives in benchmarks/report.py next to the package."""
    import runpy
    script = Path(__file__).resolve().parent.parent / "benchmarks" / "report.py"
    if not script.is_file():
        fail(f"{script.parent}: benchmarks folder not found; `nurbsdem bench` needs a source "
             "checkout (the benchmarks are not part of an installed wheel)")
    argv = (["--quick"] if quick else []) + (["--output", output] if output else [])
    ns = runpy.run_path(str(script), run_name="nurbsdem_bench")
    code = ns["main"](argv)
    if code:
        sys.exit(code)


if __name__ == "__main__":  # pragma: no cover - python -m nurbsdem.cli
    sys.exit(main())

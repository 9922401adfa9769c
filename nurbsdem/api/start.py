"""The solver of a scene built in Python, made at its first step: the whole scene validated
(the checks of ``nurbsdem check``), the bodies placed, the solver made and started."""
from __future__ import annotations

from pathlib import Path
from typing import Any, Callable

from ..errors import InputError
from ..model import Model


def _check_interfaces(model: Model) -> None:
    """The deck's check (:func:`~nurbsdem.dynamics.laws.interface.check_coverage`)."""
    from ..dynamics.laws.interface import check_coverage, python_name

    def fail(message: str, line: int | None):
        raise InputError(message)
    check_coverage(model, fail, lambda material: None, python_name,
                   ": add_interface(...) for them")


def make_solver(model: Model, *, restart: Path | None, quiet: bool, write_output: bool,
                restart_check: Callable[[Path], dict], options: dict[str, Any]):
    """Validate the whole scene, place the bodies and make the
    :class:`~nurbsdem.solver.Solver` (not started)."""
    from ..placement import explicit_bodies
    from ..solver import Solver
    from ..validation import check_model, validate_scene
    if not model.particles and not model.inlets:
        raise InputError("no particles: add_particle(...) or add_inlet(...) before running a "
                         "step")
    _check_interfaces(model)
    check_model(model)
    model.bodies = explicit_bodies(model)
    validate_scene(model)
    return Solver(model, restart=restart, quiet=quiet, write_output=write_output,
                  restart_check=restart_check, **options)


def start_solver(solver, output_dir: Path | None, restart: Path | None) -> None:
    """Start ``solver``: after a restart that writes files, the output folder of the
    checkpoint cleaned of what came after it; the checkpoint file must exist."""
    if output_dir is not None and solver.write_output:
        from ..io.writers import clean_output_directory
        if restart is not None and restart.parent.is_dir():
            clean_output_directory(restart.parent)
    if restart is not None and not restart.is_file():
        raise InputError(f"{restart}: no such checkpoint file")
    solver.start()

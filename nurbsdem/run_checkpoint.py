"""A run's checkpoint (``checkpoint.h5`` in the output directory): the state a solver writes
every ``Checkpoint Every`` seconds of simulated time and at the end of each step
(:func:`write_checkpoint`), and reads back to continue bit for bit (:func:`load_restart`)."""
from __future__ import annotations

import copy
import math
import time

import numpy as np

from . import __version__
from .errors import InputError
from .io.checkpoint import save_checkpoint
from .model import Bodies

CHECKPOINT_NAME = "checkpoint.h5"


def run_state(solver) -> dict:
    """What a checkpoint holds of a :class:`~nurbsdem.solver.Solver` now (the scene's state
    is collective: every rank calls this)."""
    return {
        "version": __version__, "deck": solver.model.text, "time": solver.time,
        "step_index": solver.step_index, "step_progress": solver.step_progress,
        "bodies": solver.bodies.as_dict(), "wall_offset": solver.wall_offset,
        "energy_offset": dict(solver.ledger.offset),
        "mech0": solver.ledger.mech0 if solver.ledger.mech0 is not None else float("nan"),
        "system": solver.system.get_state() if solver.system is not None else {},
        "scene": solver.scene.state() if solver.scene is not None else {},   # collective
        "carry_hist": ({"keys": solver.carry_hist[0], "springs": solver.carry_hist[1]}
                       if solver.carry_hist is not None else {}),
        "motion": solver.motion_spec,
        # where Rotate steps left the mesh and surface walls: R (9,) then t (3,) each
        "curved_rest": solver.curved.rest_state(),
        "flow": solver.flow.state() if solver.flow.active else {},
    }


def write_checkpoint(solver, writers) -> None:
    """Queue the solver's checkpoint on the output worker of ``writers`` (rank 0; nothing
    without output); the time it takes counts as output."""
    if not solver.write_output:
        return
    t0 = time.perf_counter()
    state = run_state(solver)
    if solver.rank == 0:        # written by the output worker: a copy of the state
        writers.checkpoint(save_checkpoint, solver.outdir / CHECKPOINT_NAME,
                           copy.deepcopy(state))
    solver.timers["output"] += time.perf_counter() - t0


def load_restart(solver) -> dict:
    """Read the solver's restart checkpoint, check it belongs to this deck (the parsed model
    is compared, so comments and layout may change, or ``solver.restart_check`` decides) and
    restore the run's state from it; returns the checkpoint's state."""
    from .io.checkpoint import restart_state
    path = solver.restart_path
    if solver.restart_check is not None:
        st = solver.restart_check(path)
    else:
        st = restart_state(path, solver.model)
    try:
        _restore(solver, st)
    except (KeyError, TypeError, ValueError, IndexError) as exc:
        raise InputError(f"the checkpoint is incomplete or corrupted ({type(exc).__name__}: "
                         f"{exc})", path=str(path)) from None
    if not 0 <= solver.step_index <= (len(solver.model.steps) if solver.restart_check is None
                                      else 10 ** 9):
        raise InputError(f"the checkpoint is corrupted (step index {solver.step_index})",
                         path=str(path))
    return st


def _restore(solver, st: dict) -> None:
    """Set the solver's run state from checkpoint state ``st`` (:func:`run_state`)."""
    solver.time = float(st["time"])
    solver.step_index = int(st["step_index"])
    solver.step_progress = int(st["step_progress"])
    solver.bodies = Bodies.from_dict(st["bodies"])
    off = np.array(st["wall_offset"], float).reshape(-1, 3)
    solver.wall_offset = np.zeros((len(solver.model.wall_names), 3))
    solver.wall_offset[:len(off)] = off      # mesh and surface walls: after the flat ones
    solver.ledger.offset = {k: float(v) for k, v in dict(st["energy_offset"]).items()}
    solver.ledger.mech0 = None if math.isnan(st["mech0"]) else float(st["mech0"])
    ch = st.get("carry_hist") or {}
    solver.carry_hist = (ch["keys"], ch["springs"]) if ch else None
    solver.curved.restore(st.get("curved_rest"))
    solver.flow.restore(st.get("flow"))

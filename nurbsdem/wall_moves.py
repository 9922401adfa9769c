"""The walls of a ``MoveWall`` step in time: each wall the step moves
(:meth:`~nurbsdem.model.MoveWallStep.moves`) translates by its displacement at constant
velocity or by its table (:mod:`nurbsdem.wall_tables`) from where it is at the step's start,
and a mesh or surface wall turns at its angular velocity or by its table's rotation vectors
about its centre; a flat wall with a ``Force`` is servo-controlled
(:mod:`nurbsdem.wall_servo`, ``solver.servo``); the other walls stay where they are.

Where the walls were at the step's start (``offsets`` (W,3) m; ``d0``: the first wall's) and
when the step started (``t_start``, s) are kept in the solver's ``motion_spec`` for the
checkpoint, so that a restart inside the step continues from the same numbers.
"""
from __future__ import annotations

import numpy as np

from . import wall_servo
from .dynamics import PrescribedMotion


def plan(solver, step, restored) -> tuple[list[PrescribedMotion], dict]:
    """(the walls' translations (W,), {k: pose} of the mesh and surface walls that turn, k
    counted among those walls) for MoveWall ``step`` of ``solver``; sets its motion_spec."""
    from .contact.curved_walls import WallPose
    from .wall_tables import TablePose, table_motion
    model = solver.model
    names = model.wall_names
    k0 = names.index(step.wall)
    spec = restored.get("motion") if restored else None
    offsets = solver.wall_offset.copy()
    if spec:
        t_start = float(spec["t_start"])
        if spec.get("offsets") is not None:
            offsets = np.array(spec["offsets"], float).reshape(-1, 3)
        offsets[k0] = np.array(spec["d0"], float)
    else:
        t_start = solver.time - solver.step_progress * float(step.time_step)
    solver.motion_spec = {"d0": offsets[k0].copy(), "t_start": t_start, "offsets": offsets}
    motions = solver._fixed_motions()
    poses = {}
    first_curved = len(model.walls)
    for m in step.moves():
        k = names.index(m.wall)
        d0 = offsets[k]
        if m.table is not None:
            motions[k] = table_motion(m.table, t_start, d0)
        elif m.displacement is not None:
            motions[k] = PrescribedMotion.piecewise_linear(
                [t_start, t_start + step.duration], [d0, d0 + m.displacement])
        turns = m.rotate or (m.table is not None and m.table.rotation is not None)
        if k < first_curved or not turns:
            continue
        c = k - first_curved
        R0, shift0 = solver.curved.rest.get(c, (np.eye(3), np.zeros(3)))
        # the centre before the wall's displacement (the pose adds it back)
        centre = np.asarray(m.center, float) - d0
        if m.rotate:
            poses[c] = WallPose(omega=np.asarray(m.angular_velocity, float), center=centre,
                                t0=t_start, R0=R0, shift0=shift0)
        else:
            poses[c] = TablePose(center=centre, t0=t_start, R0=R0, shift0=shift0,
                                 knots=t_start + m.table.times, rotvecs=m.table.rotation)
    solver.servo = wall_servo.plan(solver, step, motions, offsets, t_start, spec)
    return motions, poses

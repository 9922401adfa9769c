"""Mesh and surface walls turned by a motion table (``MoveWall NAME Table`` with rotation
vectors, :class:`~nurbsdem.wall_tables.TablePose`) in the compiled deck steps.

A table's pose (an interpolated rotation vector about a centre, :mod:`nurbsdem.wall_tables`)
and its angular velocity change along the step. The Python side tabulates both at the times
the loop evaluates the contacts (the ends of its internal steps, the times the Python driver
uses, :meth:`DeckSteps._wall_tables`) with the very functions the Python driver calls
(``TablePose.at``, ``TablePose.angular_velocity``), and the loop, before each evaluation,
writes the pose into the wall's rest pose of the packed walls
(:data:`~nurbsdem.contact.curved_compiled.CurvedConst`, with a zero angular velocity and
centre there, so that :func:`~nurbsdem.contact.curved_walls.wall_pose_at` returns it as it
is, plus the wall's displacement) and the spin into the system's ``spin`` (W,6) rows: the
two drivers see the same bits.

Lengths in metres, angles in radians, times in seconds.
"""
from __future__ import annotations

import numpy as np

from ..jit import internal


def table_turns(provider, cc, spin: np.ndarray, times: np.ndarray) -> tuple:
    """(which (Wc,) bool, R (T,Wc,3,3), shift (T,Wc,3) m, spin (T,W,6)) of the curved walls
    of ``provider`` (a :class:`~nurbsdem.contact.curved_walls.CurvedWallContacts`, or None)
    that a table turns, at the loop's ``times`` (T,) s: their poses without the displacement
    and the system's spin rows (the others' as ``spin`` holds them); T = 0 when none turns by
    a table.  Sets those walls' angular velocity and centre in ``cc`` to zero (module
    docstring)."""
    walls = [] if provider is None else provider.walls
    which = np.array([hasattr(w.pose, "angular_velocity") for w in walls], np.bool_)
    W = spin.shape[0]
    if not which.any():
        return which, np.zeros((0, len(walls), 3, 3)), np.zeros((0, len(walls), 3)), \
            np.zeros((0, W, 6))
    T = len(times)
    R = np.zeros((T, len(walls), 3, 3))
    shift = np.zeros((T, len(walls), 3))
    spins = np.repeat(spin[None], T, axis=0)
    first = cc.first
    for w in np.flatnonzero(which).tolist():
        pose = walls[w].pose
        cc.omega[w] = 0.0
        cc.center[w] = 0.0
        for k, t in enumerate(times.tolist()):
            R[k, w], shift[k, w] = pose.at(t)
            spins[k, first + w] = np.concatenate([pose.angular_velocity(t), pose.center])
    return which, R, shift, spins


@internal
def turn_walls(cc, spin, turns, t: int) -> None:
    """Before the loop's evaluation at its t-th time: the table-turned walls' poses into the
    rest poses of ``cc`` and the spin rows into ``spin`` (``turns``: :func:`table_turns`)."""
    which, R, shift, spins = turns
    if R.shape[0] == 0:
        return
    for w in range(which.shape[0]):
        if which[w]:
            cc.R0[w, :, :] = R[t, w]
            cc.shift0[w, :] = shift[t, w]
    spin[:, :] = spins[t]

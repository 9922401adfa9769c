"""The deck's ``MoveWall … Table`` and ``MoveWall … Force`` steps and the steps that move
several walls.

``Step ID MoveWall NAME Table FILE [Center cx cy cz] [Duration T] TimeStep DT [Damping ..]
[Accuracy ..] [Safety ..]``: the wall follows the CSV table FILE (resolved against the deck's
folder; :mod:`nurbsdem.wall_tables`), the step lasting T s (default: the table's last time).

``Step ID MoveWall NAME Force F MaxSpeed v Gain g Duration T TimeStep DT [Damping ..]
[Accuracy ..] [Safety ..]``: the flat wall NAME is servo-controlled to a push of F N of the
particles along its normal, at most v m/s, with gain g m/(s N) (:mod:`nurbsdem.wall_servo`).

A ``Step`` line whose id is the previous step's adds a wall to that MoveWall step:
``Step ID MoveWall NAME2 Displacement ..`` (or ``Rotate ..``, or ``Table ..``) with no timing
keys, the first line's ``Duration``, ``TimeStep`` and the rest applying to every wall of the
step; each wall moves at most once per step.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from ..errors import InputError
from ..model import MoveWallStep

#: the keys of a step's timing, on the first of its lines only
TIMING = ("Duration", "TimeStep", "Damping", "Accuracy", "Safety")
#: the keys of a servo wall's motion
SERVO = ("Force", "MaxSpeed", "Gain")
#: the keys that choose a wall's motion
MODES = ("ToContact", "Displacement", "Rotate", "Table", "Force")


def read_table(builder, e, file: str):
    """The WallTable of the CSV ``file`` of entry ``e`` (relative: to the deck's folder); a
    bad row: an InputError naming the CSV and its line, and the step's deck line."""
    from ..wall_tables import read_wall_table
    path = Path(file) if Path(file).is_absolute() else builder.base / file
    try:
        return read_wall_table(path, file)
    except InputError as exc:
        raise InputError(f"{exc} (the Table of Step {e.id}, {builder.model.path}:{e.line})"
                         ) from None


def table_step(builder, e, name: str) -> MoveWallStep:
    """``MoveWall NAME Table FILE [Center ..] [Duration T] TimeStep DT ..``."""
    builder.only(e, {"MoveWall", "Table", "Center", *TIMING}, "MoveWall Table")
    builder.require(e, "TimeStep")
    table = read_table(builder, e, e.get("Table"))
    duration = e.get("Duration")
    if duration is None:
        e = _with(e, Duration=table.duration)
    dur, dt = builder.timing(e)
    return MoveWallStep(e.id, e.line, wall=name, table=table,
                        center=_center(e, table), duration=dur, time_step=dt,
                        damping=builder.damping(e),
                        accuracy=builder.optional_positive(e, "Accuracy"),
                        safety=builder.optional_positive(e, "Safety"))


def servo(builder, e, name: str) -> dict:
    """The keys of ``MoveWall NAME Force F MaxSpeed v Gain g [Direction dx dy dz]``: F (N)
    any number, v > 0 (m/s), g >= 0 (m/(s N)), the direction of advance made unit (None: a
    flat wall's normal; :func:`check_moves` requires it for mesh and surface walls)."""
    builder.require(e, "MaxSpeed", "Gain")
    return dict(wall=name, force=float(e.get("Force")),
                max_speed=builder.positive(e, "MaxSpeed", e.get("MaxSpeed")),
                gain=builder.positive(e, "Gain", e.get("Gain"), strict=False),
                direction=unit_direction(builder, e))


def unit_direction(builder, e) -> np.ndarray | None:
    """The entry's ``Direction`` made unit (d / |d|; None when absent); zero: an error at
    its line."""
    d = e.get("Direction")
    if d is None:
        return None
    if not np.linalg.norm(d) > 0:
        builder.fail(f"Step {e.id}: Direction must not be zero", e.line)
    return d / np.linalg.norm(d)


def force_step(builder, e, name: str) -> MoveWallStep:
    """``MoveWall NAME Force F MaxSpeed v Gain g [Direction ..] Duration T TimeStep DT ..``."""
    builder.only(e, {"MoveWall", *SERVO, "Direction", *TIMING}, "MoveWall Force")
    builder.require(e, "Duration", "TimeStep")
    dur, dt = builder.timing(e)
    return MoveWallStep(e.id, e.line, **servo(builder, e, name), duration=dur, time_step=dt,
                        damping=builder.damping(e),
                        accuracy=builder.optional_positive(e, "Accuracy"),
                        safety=builder.optional_positive(e, "Safety"))


def _with(e, **values):
    from dataclasses import replace
    return replace(e, values={**e.values, **values})


def _center(e, table) -> np.ndarray | None:
    """The rotation centre of a table that turns the wall (default: the origin), else None."""
    if table.rotation is None:
        return None if e.get("Center") is None else np.asarray(e.get("Center"), float)
    return np.asarray(e.get("Center", np.zeros(3)), float)


def add_wall_move(builder, e, first: MoveWallStep) -> None:
    """A further line of MoveWall step ``first`` (same id): its wall's motion joins the step
    (:attr:`~nurbsdem.model.MoveWallStep.also`)."""
    label = f"Step {e.id}"
    if first.to_contact:
        builder.fail(f"{label}: a ToContact step moves one wall; give each its own step",
                     e.line)
    if not e.has("MoveWall"):
        builder.fail(f"{label}: a further line of a step moves another wall "
                     f"(Step {e.id} MoveWall NAME ..); step ids must otherwise be unique",
                     e.line)
    for k in TIMING:
        if e.has(k):
            builder.fail(f"{label}: {k} belongs on the step's first line (line {first.line}); "
                         f"its further lines name a wall and its motion only", e.line)
    name = e.get("MoveWall")
    if name in {m.wall for m in first.moves()}:
        builder.fail(f"{label}: wall {name!r} moves twice in this step", e.line)
    modes = [k for k in MODES if e.has(k)]
    if e.has("Rotate") and modes == ["Displacement", "Rotate"]:
        modes = ["Rotate"]
    if len(modes) != 1 or modes[0] == "ToContact":
        builder.fail(f"{label}: MoveWall {name} needs exactly one of Displacement, Rotate, "
                     f"Table, Force (Rotate may take a Displacement)", e.line)
    common = dict(duration=first.duration, time_step=first.time_step, damping=first.damping,
                  accuracy=first.accuracy, safety=first.safety)
    if modes[0] == "Displacement":
        builder.only(e, {"MoveWall", "Displacement"}, "MoveWall Displacement")
        move = MoveWallStep(e.id, e.line, wall=name, displacement=e.get("Displacement"),
                            **common)
    elif modes[0] == "Rotate":
        builder.only(e, {"MoveWall", "Rotate", "AngularVelocity", "Center", "Displacement"},
                     "MoveWall Rotate")
        builder.require(e, "AngularVelocity")
        if not np.linalg.norm(e.get("AngularVelocity")) > 0:
            builder.fail(f"{label}: AngularVelocity must not be zero", e.line)
        move = MoveWallStep(e.id, e.line, wall=name, rotate=True,
                            angular_velocity=np.asarray(e.get("AngularVelocity"), float),
                            center=np.asarray(e.get("Center", np.zeros(3)), float),
                            displacement=e.get("Displacement"), **common)
    elif modes[0] == "Force":
        builder.only(e, {"MoveWall", *SERVO, "Direction"}, "MoveWall Force")
        move = MoveWallStep(e.id, e.line, **servo(builder, e, name), **common)
    else:
        builder.only(e, {"MoveWall", "Table", "Center"}, "MoveWall Table")
        table = read_table(builder, e, e.get("Table"))
        move = MoveWallStep(e.id, e.line, wall=name, table=table, center=_center(e, table),
                            **common)
    first.also.append(move)


def check_moves(builder, model) -> None:
    """Each moved wall exists; a table with rotation columns turns a mesh or surface wall; a
    servo (``Force``) of a mesh or surface wall has a ``Direction``, and a flat wall's
    advances towards the particles (its normal's side)."""
    names = model.wall_names
    curved = {w.name for w in model.curved_walls}
    for s in model.steps:
        for m in s.moves() if isinstance(s, MoveWallStep) else ():
            if m.wall not in names:
                known = f" (walls: {', '.join(names)})" if names else " (no walls defined)"
                builder.fail(f"Step {s.id}: no wall named {m.wall!r}{known}", m.line)
            if m.table is not None and m.table.rotation is not None and m.wall not in curved:
                builder.fail(f"Step {s.id}: the table {m.table.file} has rotation columns "
                             f"(rx, ry, rz) but wall {m.wall!r} is flat: only mesh and surface "
                             f"walls turn", m.line)
            if m.force is not None:
                check_servo_direction(model, m, builder.fail, f"Step {s.id}: MoveWall "
                                      f"{m.wall} Force")
            if m is not s and m.rotate and m.wall not in curved:
                builder.fail(f"Step {s.id}: MoveWall {m.wall} Rotate: only mesh and surface "
                             f"walls turn (flat walls translate: Displacement)", m.line)


def check_servo_direction(model, m, fail, what: str) -> None:
    """A servo's direction of advance (``m.direction``): required for a mesh or surface wall
    (no normal of its own); a flat wall's, when given, must have a positive component along
    its normal (towards the particles).  ``fail(message, line)`` reports."""
    curved = {w.name for w in model.curved_walls}
    if m.direction is None:
        if m.wall in curved:
            fail(f"{what}: a mesh or surface wall needs Direction dx dy dz (the way it "
                 f"advances towards the particles)", m.line)
        return
    if m.wall not in curved:
        n = model.walls[model.wall_names.index(m.wall)].normal
        if not float(np.asarray(m.direction) @ n) > 1e-12:
            fail(f"{what}: Direction must advance the flat wall towards the particles "
                 f"(along its normal {tuple(float(x) for x in n)})", m.line)

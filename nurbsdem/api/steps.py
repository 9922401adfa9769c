"""The steps of :class:`~nurbsdem.simulation.Simulation` from its methods' arguments: each
argument checked as the deck checks the same key of a ``Step`` line, the step object the
same as the deck's (:class:`~nurbsdem.model.DynamicStep`,
:class:`~nurbsdem.model.ReplicateStep`, :class:`~nurbsdem.model.MoveWallStep`). Messages
start with ``Step N:``, N the id the step gets."""
from __future__ import annotations

from typing import Any, Sequence

import numpy as np

from ..errors import InputError
from ..model import DAMPING_SCHEMES, DynamicStep, Model, MoveWallStep, ReplicateStep
from .checks import number, vector


def next_step_id(model: Model) -> int:
    """The id of the next step (1, 2, ... in the order the steps run)."""
    return max((s.id for s in model.steps), default=0) + 1


def damping(sid: int, value: Any) -> str:
    """The damping scheme, "explicit" or "implicit" (the deck's ``Damping``)."""
    if not isinstance(value, str) or value.lower() not in DAMPING_SCHEMES:
        raise InputError(f"Step {sid}: damping must be 'explicit' or 'implicit', got "
                         f"{value!r}")
    return value.lower()


def optional_positive(key: str, sid: int, value: Any) -> float | None:
    """A step's optional positive number (``Accuracy``, ``Safety``; None: not given)."""
    return None if value is None else number(key, value, f"Step {sid}", positive=True)


def timing(sid: int, duration: Any, time_step: Any) -> tuple[float, float]:
    """(duration, time step) in s, both > 0, the time step not longer than the duration."""
    dur = number("Duration", duration, f"Step {sid}", positive=True)
    dt = number("TimeStep", time_step, f"Step {sid}", positive=True)
    if dt > dur:
        raise InputError(f"Step {sid}: time_step {dt:g} s exceeds duration {dur:g} s")
    return dur, dt


def dynamic_step(sid: int, duration: Any, time_step: Any, damping_scheme: Any, accuracy: Any,
                 safety: Any) -> DynamicStep:
    """``Dynamic`` (see :meth:`~nurbsdem.simulation.Simulation.run_dynamic`)."""
    dur, dt = timing(sid, duration, time_step)
    return DynamicStep(sid, 0, dur, dt, damping=damping(sid, damping_scheme),
                       accuracy=optional_positive("Accuracy", sid, accuracy),
                       safety=optional_positive("Safety", sid, safety))


def replicate_step(sid: int, layers: Any, height: Any) -> ReplicateStep:
    """``Replicate`` (see :meth:`~nurbsdem.simulation.Simulation.replicate`)."""
    if isinstance(layers, bool) or not isinstance(layers, (int, np.integer)) or layers < 1:
        raise InputError(f"Step {sid}: layers must be an integer >= 1, got {layers!r}")
    h = number("Height", height, f"Step {sid}", positive=True)
    return ReplicateStep(sid, 0, int(layers), h)


def move_wall_step(model: Model, sid: int, name: Any,
                   displacement: Sequence[float] | None, duration: Any, time_step: Any, *,
                   to_contact: bool, gap: Any, direction: Sequence[float] | None,
                   damping_scheme: Any, accuracy: Any, safety: Any,
                   angular_velocity: Sequence[float] | None,
                   center: Sequence[float], table: Any = None,
                   servo: dict | None = None) -> MoveWallStep:
    """``MoveWall`` (see :meth:`~nurbsdem.simulation.Simulation.move_wall`): a turn of a
    mesh or surface wall (with a displacement too, if given), a flat wall moved to contact,
    a wall's displacement, a table of its motion (a CSV path or an array of rows), or a
    servo (``servo``: a dict of force, max_speed and gain; the deck's ``Force``)."""
    what = f"Step {sid}"
    if not isinstance(name, str) or name not in model.wall_names:
        names = ", ".join(model.wall_names) or "no walls defined"
        raise InputError(f"{what}: no wall named {name!r} (walls: {names})")
    curved = name in {w.name for w in model.curved_walls}
    if servo is not None:
        if to_contact or (displacement, table, angular_velocity) != (None, None, None):
            raise InputError(f"{what}: force takes max_speed, gain, duration and time_step, "
                             f"not displacement, table, angular_velocity or to_contact")
        return _servo_step(model, sid, name, servo, direction, duration, time_step,
                           damping_scheme, accuracy, safety)
    if table is not None:
        if to_contact or displacement is not None or angular_velocity is not None:
            raise InputError(f"{what}: table takes center, duration and time_step, not "
                             f"displacement, angular_velocity or to_contact")
        return _table_step(sid, name, curved, table, center, duration, time_step,
                           damping_scheme, accuracy, safety)
    if angular_velocity is not None:
        if not curved:
            raise InputError(f"{what}: only mesh and surface walls turn (angular_velocity)")
        if to_contact or duration is None or time_step is None:
            raise InputError(f"{what}: angular_velocity takes center, duration, time_step "
                             f"and optionally displacement, not to_contact")
        return _turn(sid, name, angular_velocity, center, displacement, duration, time_step,
                     damping_scheme, accuracy, safety)
    if curved and to_contact and direction is None:
        raise InputError(f"{what}: to_contact of a mesh or surface wall needs a direction")
    if to_contact:
        if displacement is not None or duration is not None or time_step is not None:
            raise InputError(f"{what}: to_contact=True takes gap and direction, not "
                             f"displacement, duration or time_step")
        return _to_contact(sid, name, gap, direction)
    if displacement is None or duration is None or time_step is None:
        raise InputError(f"{what}: move_wall needs displacement, duration and time_step "
                         f"(or to_contact=True)")
    disp = vector("Displacement", displacement, what)
    dur, dt = timing(sid, duration, time_step)
    return MoveWallStep(sid, 0, wall=name, displacement=disp, duration=dur, time_step=dt,
                        damping=damping(sid, damping_scheme),
                        accuracy=optional_positive("Accuracy", sid, accuracy),
                        safety=optional_positive("Safety", sid, safety))


def _turn(sid: int, name: str, angular_velocity: Any, center: Any, displacement: Any,
          duration: Any, time_step: Any, damping_scheme: Any, accuracy: Any,
          safety: Any) -> MoveWallStep:
    """``MoveWall NAME Rotate``: a turn at ``angular_velocity`` (rad/s) about ``center`` (m),
    with a translation by ``displacement`` (m; None: none)."""
    what = f"Step {sid}"
    omega = vector("AngularVelocity", angular_velocity, what)
    if not np.linalg.norm(omega) > 0:
        raise InputError(f"{what}: angular_velocity must not be zero")
    dur, dt = timing(sid, duration, time_step)
    shift = None if displacement is None else vector("Displacement", displacement, what)
    return MoveWallStep(sid, 0, wall=name, rotate=True, angular_velocity=omega,
                        center=vector("Center", center, what), displacement=shift, duration=dur,
                        time_step=dt, damping=damping(sid, damping_scheme),
                        accuracy=optional_positive("Accuracy", sid, accuracy),
                        safety=optional_positive("Safety", sid, safety))


def move_walls_step(model: Model, sid: int, moves: Any, duration: Any, time_step: Any, *,
                    damping_scheme: Any, accuracy: Any, safety: Any) -> MoveWallStep:
    """Several walls in one ``MoveWall`` step (the deck's ``Step`` lines of one id):
    ``moves`` a list of ``(name, motion)``, motion a dict of ``displacement``, ``table`` or
    ``angular_velocity`` (and ``center``) as :func:`move_wall_step` takes them; the timing
    (``duration``, default the first wall's table's; ``time_step``, ...) is the step's."""
    what = f"Step {sid}"
    keys = {"displacement", "table", "angular_velocity", "center", "force", "max_speed",
            "gain", "direction"}
    if not isinstance(moves, (list, tuple)) or not moves:
        raise InputError(f"{what}: move_wall takes a wall name or a non-empty list of "
                         f"(name, motion) pairs")
    steps: list[MoveWallStep] = []
    for item in moves:
        pair = item if isinstance(item, (list, tuple)) and len(item) == 2 else (None, None)
        name, motion = pair
        if not isinstance(motion, dict) or not set(motion) <= keys or not (
                {"displacement", "table", "angular_velocity", "force"} & set(motion)):
            raise InputError(f"{what}: each wall of the list is (name, motion), motion a dict "
                             f"of displacement, table, angular_velocity (and center) or force "
                             f"(with max_speed and gain), got {item!r}")
        if name in {m.wall for m in steps}:
            raise InputError(f"{what}: wall {name!r} moves twice in this step")
        steps.append(move_wall_step(
            model, sid, name, motion.get("displacement"),
            steps[0].duration if steps else duration, time_step, to_contact=False, gap=0.0,
            direction=motion.get("direction"), damping_scheme=damping_scheme,
            accuracy=accuracy, safety=safety,
            angular_velocity=motion.get("angular_velocity"),
            center=motion.get("center", (0.0, 0.0, 0.0)), table=motion.get("table"),
            servo=servo_of(sid, motion.get("force"), motion.get("max_speed"),
                           motion.get("gain"))))
    first = steps[0]
    first.also = steps[1:]
    return first


def servo_of(sid: int, force: Any, max_speed: Any, gain: Any) -> dict | None:
    """The servo of ``move_wall(force=, max_speed=, gain=)`` (None: no ``force``)."""
    if force is None:
        if (max_speed, gain) != (None, None):
            raise InputError(f"Step {sid}: max_speed and gain go with force")
        return None
    if max_speed is None or gain is None:
        raise InputError(f"Step {sid}: force needs max_speed and gain")
    return dict(force=force, max_speed=max_speed, gain=gain)


def _servo_step(model: Model, sid: int, name: str, servo: dict, direction: Any,
                duration: Any, time_step: Any, damping_scheme: Any, accuracy: Any,
                safety: Any) -> MoveWallStep:
    """``MoveWall NAME Force F MaxSpeed v Gain g [Direction ..]``: a wall servo-controlled to
    the particles' push F (N) along ``direction`` (made unit; None: a flat wall's normal;
    required for a mesh or surface wall) at most v m/s (> 0), gain g m/(s N) (>= 0)."""
    from ..io.deck_moves import check_servo_direction
    what = f"Step {sid}"
    if duration is None or time_step is None:
        raise InputError(f"{what}: force needs duration and time_step")
    d = _unit_direction(direction, what)
    dur, dt = timing(sid, duration, time_step)
    step = MoveWallStep(sid, 0, wall=name, force=number("Force", servo["force"], what),
                        max_speed=number("MaxSpeed", servo["max_speed"], what, positive=True),
                        gain=number("Gain", servo["gain"], what, nonnegative=True),
                        direction=d, duration=dur, time_step=dt,
                        damping=damping(sid, damping_scheme),
                        accuracy=optional_positive("Accuracy", sid, accuracy),
                        safety=optional_positive("Safety", sid, safety))

    def fail(message: str, line: int) -> None:
        raise InputError(message)
    check_servo_direction(model, step, fail, f"{what}: force")
    return step


def _table_step(sid: int, name: str, curved: bool, table: Any, center: Any, duration: Any,
                time_step: Any, damping_scheme: Any, accuracy: Any,
                safety: Any) -> MoveWallStep:
    """``MoveWall NAME Table``: the wall follows ``table``, a CSV file's path or an array of
    rows t, x, y, z[, rx, ry, rz] (:mod:`nurbsdem.wall_tables`), over ``duration`` s
    (None: the table's last time)."""
    from pathlib import Path

    from ..wall_tables import read_wall_table, table_from_array
    what = f"Step {sid}"
    if isinstance(table, (str, Path)):
        tab = read_wall_table(Path(table), str(table))
    else:
        tab = table_from_array(table, what)
    if tab.rotation is not None and not curved:
        raise InputError(f"{what}: the table has rotation columns (rx, ry, rz) but wall "
                         f"{name!r} is flat: only mesh and surface walls turn")
    if time_step is None:
        raise InputError(f"{what}: table needs time_step")
    dur, dt = timing(sid, tab.duration if duration is None else duration, time_step)
    centre = None if tab.rotation is None else vector("Center", center, what)
    return MoveWallStep(sid, 0, wall=name, table=tab, center=centre, duration=dur,
                        time_step=dt, damping=damping(sid, damping_scheme),
                        accuracy=optional_positive("Accuracy", sid, accuracy),
                        safety=optional_positive("Safety", sid, safety))


def _to_contact(sid: int, name: str, gap: Any, direction: Any) -> MoveWallStep:
    """``MoveWall NAME ToContact``: along ``direction`` (made unit; None: the wall's normal)
    until the nearest particle is ``gap`` m away."""
    what = f"Step {sid}"
    g = number("Gap", gap, what, nonnegative=True)
    return MoveWallStep(sid, 0, wall=name, to_contact=True, gap=g,
                        direction=_unit_direction(direction, what))


def _unit_direction(direction: Any, what: str) -> np.ndarray | None:
    """``direction`` made unit (the deck's ``Direction``: d / |d|); None stays None."""
    if direction is None:
        return None
    d = vector("Direction", direction, what)
    if not np.linalg.norm(d) > 0:
        raise InputError(f"{what}: direction must not be zero")
    return d / np.linalg.norm(d)


def move_wall_of(model: Model, name: Any, displacement: Any, duration: Any, time_step: Any, *,
                 to_contact: bool, gap: float, direction: Any, damping: str, accuracy: Any,
                 safety: Any, angular_velocity: Any, center: Any, table: Any, force: Any,
                 max_speed: Any, gain: Any) -> MoveWallStep:
    """The step of :meth:`~nurbsdem.simulation.Simulation.move_wall` (its arguments; ``name``
    a wall's name or a list of ``(name, motion dict)`` pairs)."""
    sid = next_step_id(model)
    if not isinstance(name, str):
        if (displacement, table, angular_velocity, force) != (None, None, None, None) or to_contact:
            raise InputError(f"Step {sid}: with a list of walls, each wall's motion is in its "
                             f"own dict")
        return move_walls_step(model, sid, name, duration, time_step, damping_scheme=damping,
                               accuracy=accuracy, safety=safety)
    return move_wall_step(model, sid, name, displacement, duration, time_step,
                          to_contact=to_contact, gap=gap, direction=direction,
                          damping_scheme=damping, accuracy=accuracy, safety=safety,
                          angular_velocity=angular_velocity, center=center, table=table,
                          servo=servo_of(sid, force, max_speed, gain))


def keep_tables(step: MoveWallStep, output_dir) -> None:
    """Write the motion tables given as arrays to ``<output_dir>/tables/`` (the deck text
    names them)."""
    from ..wall_tables import keep_table
    for m in step.moves():
        if m.table is not None and m.table.file is None:
            keep_table(m.table, output_dir / "tables" / f"step{m.id}_{m.wall}.csv")

"""Force-controlled walls (servo walls): ``Step ID MoveWall NAME Force F MaxSpeed v Gain g
[Direction dx dy dz] Duration T TimeStep DT``, as in oedometric and triaxial tests.

The wall translates along n — a flat wall's normal (which points to the particles) or the
unit ``Direction`` (required for a mesh or surface wall, which has no normal of its own) —
at a speed set once per deck step from the particles' push on it, F_measured = reaction · n
(N, the wall's reaction of ``monitors/wall_NAME.csv`` along n, measured at the end of the
deck step before):

    u = clamp(g · (F − F_measured), −v, v)      (m/s; velocity u · n)

so the wall advances into the particles while they push less than F and backs off while
they push more. The gain g (m/(s N)) sets how fast the error closes: with the contact
stiffness k (N/m) the wall meets, one deck step DT changes the push by about k · g · DT
times the error, so g = 1 / (N · k · DT) closes it in about N deck steps (N ≈ 100 is
smooth; N below ~2 overshoots and oscillates). ``MaxSpeed`` v caps the speed, e.g. while the
wall travels to first contact.

The speed is known one deck step at a time, so a step with a servo wall runs its deck steps
one per compiled chunk (:meth:`nurbsdem.solver.Solver._time_loop` calls :meth:`Servo.update`
after each). Each servo wall's motion over a deck step starting at t_k from d_k (m) is
d(t) = d_k + u · (t − t_k) · n; (t_k, d_k, u) of each servo wall are kept in the solver's
``motion_spec`` (``servo``), so that a checkpoint holds them and a restart inside the step
continues with the same numbers, bit for bit.
"""
from __future__ import annotations

import numpy as np

from .dynamics import PrescribedMotion


class ServoMotion:
    """The translation of a servo wall, ``t -> (d (3,) m, velocity (3,) m/s)``: from ``d0``
    (3,) m at ``t0`` s at ``speed`` m/s along the unit ``normal`` (3,)."""

    def __init__(self, normal: np.ndarray, d0: np.ndarray, t0: float) -> None:
        self.normal = np.asarray(normal, float)
        self.d0 = np.array(d0, float)
        self.t0 = float(t0)
        self.speed = 0.0

    def __call__(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        return self.d0 + (self.speed * (t - self.t0)) * self.normal, self.speed * self.normal

    def state(self) -> dict:
        """(d_k, t_k, u) of the present deck step, as checkpoints keep them."""
        return {"d": self.d0.copy(), "t": self.t0, "u": self.speed}


class Servo:
    """The servo walls of one MoveWall step: ``moves`` the step's wall moves with a
    ``force`` (:class:`~nurbsdem.model.MoveWallStep`), ``index`` their wall indices,
    ``motions`` their :class:`ServoMotion`, ``spec`` the solver's ``motion_spec``."""

    def __init__(self, moves: list, index: list[int], motions: list[ServoMotion],
                 spec: dict) -> None:
        self.moves, self.index, self.motions, self.spec = moves, index, motions, spec

    def update(self, system) -> None:
        """Set each servo wall's speed for the next deck step of ``system`` (a
        :class:`~nurbsdem.dynamics.DemSystem` at the end of a deck step, or at the step's
        start) from its reaction now, starting where the wall is now; record them in
        ``spec``."""
        t_k = float(system.time)
        d = system.wall_displacement
        r = system.wall_reaction
        for m, k, mo in zip(self.moves, self.index, self.motions):
            push = float(r[k] @ mo.normal)
            mo.speed = float(np.clip(m.gain * (m.force - push), -m.max_speed, m.max_speed))
            mo.d0, mo.t0 = d[k].copy(), t_k
            self.spec["servo"][m.wall] = mo.state()


def plan(solver, step, motions: list[PrescribedMotion], offsets: np.ndarray,
         t_start: float, spec: dict | None) -> Servo | None:
    """Put the servo walls' motions of MoveWall ``step`` into ``motions`` (by wall index) and
    return their :class:`Servo` (None: the step has no servo wall). They start at rest at
    ``offsets`` at ``t_start``, or, restarting inside the step, where the checkpoint's
    ``spec`` (the ``motion_spec`` read back) says."""
    servos = [m for m in step.moves() if m.force is not None]
    if not servos:
        return None
    names = solver.model.wall_names
    kept = (spec or {}).get("servo") or {}
    index, ms = [], []
    solver.motion_spec["servo"] = {}
    for m in servos:
        k = names.index(m.wall)
        axis = m.direction if m.direction is not None else solver.model.walls[k].normal
        mo = ServoMotion(axis, offsets[k], t_start)
        if m.wall in kept:
            s = kept[m.wall]
            mo.d0 = np.array(s["d"], float).reshape(3)
            mo.t0, mo.speed = float(s["t"]), float(s["u"])
            solver.motion_spec["servo"][m.wall] = mo.state()
        motions[k] = PrescribedMotion(mo)
        index.append(k)
        ms.append(mo)
    return Servo(servos, index, ms, solver.motion_spec)

"""The steps that take no simulated time: ``Replicate`` (copies of the particles, whose energy
the solver books) and ``MoveWall … ToContact`` (a wall translated until its gap to the
nearest particle is ``Gap``; mesh and surface walls: :mod:`nurbsdem.curved_to_contact`)."""
from __future__ import annotations

import math

import numpy as np

from .errors import InputError
from .geometry.rotation import quat_to_matrix
from .model import Bodies, Model, MoveWallStep


def mechanical_energy(model: Model, bodies: Bodies) -> float:
    """Kinetic + potential energy of a set of bodies (no contacts), J."""
    g = model.gravity
    e = 0.0
    for i in range(len(bodies)):
        entry = model.shapes[int(bodies.shape_id[i])]
        rho = model.materials[int(bodies.material_id[i])].density
        m = entry.mass(rho)
        R = quat_to_matrix(bodies.quaternion[i])
        J = R @ entry.mass_inertia(rho) @ R.T
        w = bodies.angular_velocity[i]
        e += 0.5 * m * bodies.velocity[i] @ bodies.velocity[i] + 0.5 * w @ J @ w
        e -= m * g @ bodies.position[i]
    return float(e)


def to_contact(model: Model, bodies: Bodies, wall_offset: np.ndarray,
               step: MoveWallStep, curved=None, time: float = 0.0) -> float:
    """Translate the wall along its direction until the nearest particle is ``gap`` away
    (its row of ``wall_offset`` (walls, 3) m replaced); returns the travel (m).  A mesh or
    surface wall (``curved``: the model's
    :class:`~nurbsdem.curved_wall_motion.CurvedWallMotion`, at time ``time`` s) goes to
    :func:`~nurbsdem.curved_to_contact.curved_to_contact`."""
    k = model.wall_names.index(step.wall)
    if k >= len(model.walls):
        from .curved_to_contact import curved_to_contact
        return curved_to_contact(model, bodies, wall_offset, step, curved, time)
    wall = model.walls[k]
    n = wall.normal
    direction = n if step.direction is None else np.asarray(step.direction, float)
    direction = direction / np.linalg.norm(direction)
    speed = float(direction @ n)     # how fast the gap closes per metre of travel
    if speed <= 1e-12:
        raise model.error(f"Step {step.id}: the direction does not move wall "
                          f"'{step.wall}' towards the particles", step.line)
    origin = wall.center + wall_offset[k]
    dist = distance_to_plane(model, bodies, origin, n)
    travel = (dist - step.gap) / speed
    wall_offset[k] = wall_offset[k] + travel * direction
    return travel


def distance_to_plane(model: Model, b: Bodies, origin: np.ndarray, n: np.ndarray) -> float:
    """Smallest signed distance (m) from the particles to the plane (origin, n), measured
    along n, exactly: the support point of each particle along −n (paper Eq. 8)."""
    from .contact.flat_wall import detect_wall
    if len(b) == 0:
        raise InputError("MoveWall ToContact needs particles")
    t1 = np.cross(n, [1.0, 0, 0])
    if np.linalg.norm(t1) < 0.5:
        t1 = np.cross(n, [0, 1.0, 0])
    t1 /= np.linalg.norm(t1)
    t2 = np.cross(n, t1)
    big = 1e3 * (1.0 + float(np.abs(b.position).max()))
    o = origin - big * (t1 + t2)
    Rs = b.rotation_matrices()
    best = math.inf
    for i in range(len(b)):
        entry = model.shapes[int(b.shape_id[i])]
        pos = b.position[i] - Rs[i] @ entry.centroid
        # move a probe plane through the particle's centroid so the sphere test passes
        shift = float(n @ (b.position[i] - origin))
        res = detect_wall(entry.shape, (pos, Rs[i]), (o + shift * n, 2 * big * t1, 2 * big * t2))
        best = min(best, shift + res.signed_distance)
    return best

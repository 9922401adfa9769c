"""Where a model's mesh and surface walls are in time: at rest where earlier ``MoveWall NAME
Rotate`` steps left them, the one of the current Rotate step turning at its angular velocity
about its centre (:class:`CurvedWallMotion`), and the contact provider that holds them
(:mod:`nurbsdem.contact.curved_walls`)."""
from __future__ import annotations

import contextlib

import numpy as np

from .errors import InputError


class CurvedWallMotion:
    """The poses of the mesh and surface walls of ``model`` (wall k: the k-th of
    ``model.curved_walls``, after the flat walls in the system)."""

    def __init__(self, model) -> None:
        self.model = model
        #: wall k -> (R (3,3), t (3,) m) where Rotate steps left it (absent: never turned)
        self.rest: dict[int, tuple[np.ndarray, np.ndarray]] = {}
        #: (k, omega (3,) rad/s, centre (3,) m, t0 s) of the Rotate step running now, or None
        self.rotation = None
        self._geometry = None

    @contextlib.contextmanager
    def turning(self, k: int, omega, center, t_start: float):
        """Wall k turns at ``omega`` about ``center`` (before its displacement: the pose adds
        it) from ``t_start`` (s) while inside."""
        self.rotation = (k, np.asarray(omega, float), np.asarray(center, float), t_start)
        try:
            yield
        finally:
            self.rotation = None

    def pose(self, k: int):
        """The pose in time of mesh or surface wall k: where earlier Rotate steps left it,
        turning now when the current step rotates it (:attr:`rotation`)."""
        from .contact.curved_walls import WallPose
        R0, shift0 = self.rest.get(k, (np.eye(3), np.zeros(3)))
        rot = self.rotation
        if rot is None or rot[0] != k:
            return WallPose(R0=R0, shift0=shift0)
        return WallPose(omega=rot[1], center=rot[2], t0=rot[3], R0=R0, shift0=shift0)

    def poses(self, t: float, wall_d: np.ndarray) -> list | None:
        """(R, t) of each mesh or surface wall at time t (s) with the walls' displacements
        wall_d (W,3) m, for walls.pvd; None: none."""
        if not self.model.curved_walls:
            return None
        first = len(self.model.walls)
        return [self.pose(k).at(t, wall_d[first + k])
                for k in range(len(self.model.curved_walls))]

    def spin(self, n_walls: int) -> np.ndarray:
        """(W,6) angular velocity and centre of each of the system's ``n_walls`` walls (the one
        a Rotate step turns; 0 for the others)."""
        spin = np.zeros((n_walls, 6))
        rot = self.rotation
        if rot is not None:
            spin[len(self.model.walls) + rot[0]] = np.concatenate([rot[1], rot[2]])
        return spin

    def contacts(self, scene, shape_ids: np.ndarray, comm):
        """The scene with the model's mesh and surface walls for particles of shapes
        ``shape_ids`` (exact spheres only; the Python path of the deck steps:
        :mod:`nurbsdem.contact.curved_walls`); refused on several MPI ranks (``comm``)."""
        from .contact.curved_walls import CurvedWall, CurvedWallContacts
        from .io.deck_curved import curved_wall_geometry, refuse_nurbs_particles, sphere_radii
        model = self.model
        refuse_nurbs_particles(model, shape_ids)
        if comm is not None:
            raise InputError("mesh and surface walls run on one MPI rank only")
        if self._geometry is None:
            self._geometry = [curved_wall_geometry(w, f"{model.path}:{w.line}")
                              for w in model.curved_walls]
        radius, spheres = sphere_radii(model, shape_ids)
        walls = [CurvedWall(kind, geom, self.pose(k))
                 for k, (kind, geom) in enumerate(self._geometry)]
        return CurvedWallContacts(scene, radius, spheres, walls, first_wall=len(model.walls))

    def rest_state(self) -> dict:
        """The rest poses for a checkpoint: R (9,) then t (3,) per wall, keyed by str(k)."""
        return {str(k): np.concatenate([R.ravel(), t]) for k, (R, t) in self.rest.items()}

    def restore(self, state: dict | None) -> None:
        """The rest poses of a checkpoint (:meth:`rest_state`)."""
        self.rest = {int(k): (np.asarray(v, float)[:9].reshape(3, 3), np.asarray(v, float)[9:12])
                     for k, v in dict(state or {}).items()}

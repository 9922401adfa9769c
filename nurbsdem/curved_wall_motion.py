"""Where a model's mesh and surface walls are in time: at rest where earlier ``MoveWall``
steps left them, those the current step turns (``Rotate``: at an angular velocity about a
centre; ``Table``: by interpolated rotation vectors) as their poses say
(:class:`CurvedWallMotion`), and the contact provider that holds them
(:mod:`nurbsdem.contact.curved_walls`)."""
from __future__ import annotations

import contextlib

import numpy as np



class CurvedWallMotion:
    """The poses of the mesh and surface walls of ``model`` (wall k: the k-th of
    ``model.curved_walls``, after the flat walls in the system)."""

    def __init__(self, model) -> None:
        self.model = model
        #: wall k -> (R (3,3), t (3,) m) where earlier steps left it (absent: never turned)
        self.rest: dict[int, tuple[np.ndarray, np.ndarray]] = {}
        #: wall k -> its pose in time (:class:`~nurbsdem.contact.curved_walls.WallPose` or
        #: :class:`~nurbsdem.wall_tables.TablePose`) for the walls the running step turns
        self.turning: dict = {}
        self._geometry = None

    @contextlib.contextmanager
    def moving(self, poses: dict):
        """The walls of ``poses`` (k -> pose in time) turn as their poses say while inside."""
        self.turning = dict(poses)
        try:
            yield
        finally:
            self.turning = {}

    def pose(self, k: int):
        """The pose in time of mesh or surface wall k: where earlier steps left it, or the
        current step's pose of it when the step turns it (:attr:`turning`)."""
        from .contact.curved_walls import WallPose
        if k in self.turning:
            return self.turning[k]
        R0, shift0 = self.rest.get(k, (np.eye(3), np.zeros(3)))
        return WallPose(R0=R0, shift0=shift0)

    def poses(self, t: float, wall_d: np.ndarray) -> list | None:
        """(R, t) of each mesh or surface wall at time t (s) with the walls' displacements
        wall_d (W,3) m, for walls.pvd; None: none."""
        if not self.model.curved_walls:
            return None
        first = len(self.model.walls)
        return [self.pose(k).at(t, wall_d[first + k])
                for k in range(len(self.model.curved_walls))]

    def spin(self, n_walls: int, t: float = 0.0) -> np.ndarray:
        """(W,6) angular velocity (rad/s) and centre (m) at time t (s) of each of the system's
        ``n_walls`` walls (0 for those that do not turn)."""
        spin = np.zeros((n_walls, 6))
        first = len(self.model.walls)
        for k, pose in self.turning.items():
            omega = pose.angular_velocity(t) if hasattr(pose, "angular_velocity") else pose.omega
            spin[first + k] = np.concatenate([omega, pose.center])
        return spin

    def attach(self, sysm, provider) -> None:
        """Give the system ``sysm`` the contact provider of the mesh and surface walls and
        their spin (``wall_spin``); a wall turned by a table turns at a rate that changes in
        time, so its spin is set anew at each force evaluation's time (:class:`_Spinning`)."""
        sysm.wall_spin = self.spin(sysm.walls.n, sysm.time)
        if any(hasattr(p, "angular_velocity") for p in self.turning.values()):
            provider = _Spinning(provider, self, sysm)
        sysm.set_contact_provider(provider)

    def contacts(self, scene, shape_ids: np.ndarray):
        """The scene with the model's mesh and surface walls for particles of shapes
        ``shape_ids`` (exact spheres by closed forms, NURBS particles by their support
        mapping through the scene's contact table; the Python path of the deck steps:
        :mod:`nurbsdem.contact.curved_walls`).  On several MPI ranks each rank solves the
        contacts of the particles it owns."""
        from .contact.curved_walls import CurvedWall, CurvedWallContacts
        from .io.deck_curved import sphere_radii
        model = self.model
        radius, spheres = sphere_radii(model, shape_ids)
        walls = [CurvedWall(kind, geom, self.pose(k), name=model.curved_walls[k].name)
                 for k, (kind, geom) in enumerate(self.geometry())]
        return CurvedWallContacts(scene, radius, spheres, walls, first_wall=len(model.walls),
                                  table=getattr(scene, "table", None),
                                  body_shape=getattr(scene, "body_shape", None))

    def geometry(self) -> list:
        """(kind, geometry) of each mesh and surface wall in its own frame (built once:
        :func:`~nurbsdem.io.deck_curved.curved_wall_geometry`)."""
        from .io.deck_curved import curved_wall_geometry
        if self._geometry is None:
            model = self.model
            self._geometry = [curved_wall_geometry(w, f"{model.path}:{w.line}")
                              for w in model.curved_walls]
        return self._geometry

    def rest_state(self) -> dict:
        """The rest poses for a checkpoint: R (9,) then t (3,) per wall, keyed by str(k)."""
        return {str(k): np.concatenate([R.ravel(), t]) for k, (R, t) in self.rest.items()}

    def restore(self, state: dict | None) -> None:
        """The rest poses of a checkpoint (:meth:`rest_state`)."""
        self.rest = {int(k): (np.asarray(v, float)[:9].reshape(3, 3), np.asarray(v, float)[9:12])
                     for k, v in dict(state or {}).items()}


class _Spinning:
    """A contact provider that first sets the system's ``wall_spin`` to the walls' spin at
    the evaluation's time (walls turned by a table), then asks the wrapped one; any other
    attribute is the wrapped provider's."""

    def __init__(self, provider, motion: CurvedWallMotion, sysm) -> None:
        self._provider, self._motion, self._sysm = provider, motion, sysm

    def __call__(self, kin):
        self._sysm.wall_spin[:] = self._motion.spin(self._sysm.walls.n, kin.t)
        return self._provider(kin)

    @property
    def inner(self):
        """The wrapped provider (the compiled deck steps take it, with the walls' poses and
        spin tabulated at the loop's times: :mod:`nurbsdem.dynamics.deck_steps`)."""
        return self._provider

    def __getattr__(self, name):
        if name.startswith("__") or name in ("_provider", "_motion", "_sysm"):
            raise AttributeError(name)
        return getattr(self._provider, name)

"""The kinds of mesh and surface walls (the curved walls) and what each answers.

A curved wall kind is one object of its own module (:data:`~nurbsdem.contact.mesh_kind.MESH`,
:data:`~nurbsdem.contact.surface_kind.SURFACE`) that answers the questions of
:class:`WallKind`: the step's contact provider
(:class:`~nurbsdem.contact.curved_walls.CurvedWallContacts`), the pre-run checks
(:mod:`nurbsdem.wall_checks`) and ``MoveWall ToContact`` (:mod:`nurbsdem.curved_to_contact`)
ask the wall's kind (:func:`kind_of`) and hold no branch per kind.  The compiled deck steps
hold the kinds' kernels side by side in :mod:`nurbsdem.contact.curved_compiled` (numba
dispatches on the kind's code there; each kind packs its own arrays for them), and a deck
names a kind by its ``Walls`` entry
(:mod:`nurbsdem.io.deck_curved`).  Lengths in metres; a pose (R, t) places a wall:
``x_world = R x_wall + t``.
"""
from __future__ import annotations

from typing import Any, Protocol

import numpy as np

from .mesh_kind import MESH
from .surface_kind import SURFACE


class WallKind(Protocol):
    """What a curved wall kind answers about its geometry ``g`` (the kind's geometry class,
    ``geometry_type``, in the wall's own frame)."""

    #: the kind's code (:mod:`nurbsdem.contact.kinds`: its row of ``PAIR_SOLVER``) and name
    #: (:attr:`~nurbsdem.model.CurvedWallSpec.kind`)
    code: int
    name: str
    geometry_type: type
    #: in messages of one-sided walls: what makes the wall's front, and how to make the wall
    #: act on both sides ("" where it cannot)
    front_rule: str
    two_sided_hint: str

    def box_points(self, g) -> tuple[np.ndarray, float]:
        """(points (P,3) m, pad m): the wall lies in the box of the points widened by pad
        (the broad phase against the particles' bounding spheres)."""

    def size(self, g) -> float:
        """The wall's size (m): the scale of its tolerances."""

    def new_state(self, g) -> Any:
        """What a provider keeps of the wall between evaluations (its per-particle parts
        sized by the particles of each query)."""

    def sphere_rows(self, state: Any, g, idx: np.ndarray, x: np.ndarray, radii: np.ndarray,
                    R: np.ndarray, t: np.ndarray) -> tuple:
        """(rows_f (K,NF), owner (K,), rank (K,)) of the touching contacts of the exact
        spheres ``idx`` (centres x (N,3), radii (N,)) with the wall at (R, t): each row's
        sphere and its rank among that sphere's contacts with the wall (below
        :data:`~nurbsdem.contact.kinds.MAX_PER_WALL`)."""

    def particle_rows(self, state: Any, g, table, idx: np.ndarray, body_shape: np.ndarray,
                      pose_origin: np.ndarray, rot: np.ndarray, R: np.ndarray, t: np.ndarray,
                      label: str) -> tuple:
        """:meth:`sphere_rows` for the NURBS particles ``idx`` (shapes ``body_shape`` in the
        :class:`~nurbsdem.contact.detect.ContactTable` ``table``, poses pose_origin (N,3) m,
        rot (N,3,3)); a contact the kind refuses raises naming ``label``."""

    def sphere_crossings(self, g, x: np.ndarray, r: np.ndarray,
                         idx: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(front (N,), back (N,)): the depth (m, 0: none) by which each sphere of ``idx``
        crosses the wall at rest from the side it acts on, and from behind."""

    def particle_crossings(self, g, shapes, x: np.ndarray,
                           rot: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`sphere_crossings` of NURBS particles (``shapes``, centroids x, rotations)."""

    def sphere_travels(self, g, x: np.ndarray, reach: np.ndarray, R: np.ndarray,
                       t: np.ndarray, d: np.ndarray) -> np.ndarray | None:
        """The travel (N,) m along the unit direction d that brings the wall at (R, t) within
        ``reach`` of the centres x, in closed form; None without one (then ``ToContact``
        finds it on :meth:`sphere_row`)."""

    def sphere_row(self, g, x: np.ndarray, r: float, R: np.ndarray, t: np.ndarray):
        """The contact row (NF,) of least signed distance of one sphere with the wall at
        (R, t); None without one.  Asked only of a kind whose :meth:`sphere_travels` has no
        closed form (the mesh has one and no ``sphere_row``)."""

    def particle_row(self, g, table, pos: np.ndarray, Rb: np.ndarray, R: np.ndarray,
                     t: np.ndarray, reach: float, where: str, work=None):
        """The contact row (NF,) of least signed distance of one NURBS particle with the wall
        at (R, t), among the wall's features within ``reach`` of its centroid; None without
        one (``work``: :meth:`row_work`)."""

    def row_work(self, g) -> Any:
        """A workspace :meth:`particle_row` reuses across calls (None: none)."""

    def packed(self, geometries: list, nurbs: bool) -> dict:
        """The kind's fields of the compiled deck steps' packed walls
        (:data:`~nurbsdem.contact.curved_compiled.CurvedConst`), for the curved walls'
        ``geometries`` in the provider's order (every kind's: a wall of another kind has an
        empty slice of the joined arrays and zeros in the per-wall ones); ``nurbs``: NURBS
        particles meet the walls."""

    def packed_work(self, geometries: list, n: int, const: dict) -> dict:
        """The kind's fields of the compiled deck steps' workspaces
        (:data:`~nurbsdem.contact.curved_compiled.CurvedWork`) for n particles (``const``:
        every kind's :meth:`packed` fields)."""


#: the curved wall kinds
WALL_KINDS: tuple[WallKind, ...] = (MESH, SURFACE)


def kind_of(geometry) -> WallKind:
    """The kind of a wall's geometry."""
    for kind in WALL_KINDS:
        if isinstance(geometry, kind.geometry_type):
            return kind
    raise TypeError(f"no curved wall kind has geometry {type(geometry).__name__}")


def kind_named(name: str) -> WallKind:
    """The kind of a :class:`~nurbsdem.model.CurvedWallSpec` (its ``kind``: "mesh", ...)."""
    for kind in WALL_KINDS:
        if kind.name == name:
            return kind
    raise KeyError(f"no curved wall kind {name!r}")

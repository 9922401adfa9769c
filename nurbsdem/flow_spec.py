"""What a deck (block ``Flow``) or :meth:`Simulation.add_inlet` / :meth:`~Simulation.add_outlet`
says of the inlets and outlets of a scene: :class:`InletSpec` and :class:`OutletSpec`, held by
:attr:`nurbsdem.model.Model.inlets` and :attr:`~nurbsdem.model.Model.outlets`.  The solver
runs them (:mod:`nurbsdem.flow_run`) with :mod:`nurbsdem.dynamics.flow`.  Units: SI."""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

#: the segment length (s) of a timed step with inlets or outlets when none gives ``Every``
DEFAULT_EVERY = 0.01


@dataclass
class InletSpec:
    """``Inlet ID Name n Shapes s1 .. Fractions f1 .. Material m (Box x0 y0 z0 x1 y1 z1 |
    Disc cx cy cz Normal nx ny nz Radius r [Thickness t]) Rate r Count c [Velocity vx vy vz]
    [Seed s] [Every e]``: particles of the shapes ``shapes`` (by number fractions summing to
    1) and material ``material_id``, placed in the box [lo, hi] (m), or in the disc of
    centre ``centre`` (m), axis ``normal``, radius ``radius`` and thickness ``thickness``
    (m) when ``normal`` is given (lo, hi None), at ``rate`` particles/s until ``count`` of
    them, with velocity ``velocity`` (m/s), a random stream of its own (``seed``), inserted
    at the end of each ``every`` seconds and at the end of each timed step."""

    id: int
    name: str
    shapes: tuple
    fractions: tuple
    material_id: int
    lo: np.ndarray | None
    hi: np.ndarray | None
    rate: float
    count: int
    velocity: np.ndarray = field(default_factory=lambda: np.zeros(3))
    seed: int = 0
    every: float = DEFAULT_EVERY
    line: int | None = None
    centre: np.ndarray | None = None
    normal: np.ndarray | None = None
    radius: float = 0.0
    thickness: float = 0.0

    @property
    def is_disc(self) -> bool:
        """Whether the inlet's region is a disc (else a box)."""
        return self.normal is not None

    @property
    def region_word(self) -> str:
        """The deck key of the region: ``Box`` or ``Disc``."""
        return "Disc" if self.is_disc else "Box"

    def region(self):
        """The :class:`~nurbsdem.dynamics.flow.InsertionRegion` the particles are placed in."""
        from .dynamics.flow import InsertionRegion
        if self.is_disc:
            return InsertionRegion(centre=np.asarray(self.centre, float),
                                   axis=np.asarray(self.normal, float), radius=self.radius,
                                   thickness=self.thickness)
        return InsertionRegion(lo=np.asarray(self.lo, float), hi=np.asarray(self.hi, float))


@dataclass
class OutletSpec:
    """``Outlet ID Name n Box x0 y0 z0 x1 y1 z1 [Every e]`` or ``Outlet ID Name n Point x y z
    Normal nx ny nz [Every e]``: the particles whose centroid lies in the box [lo, hi] (m), or
    beyond the plane through ``point`` (m) on the side ``normal`` points to, are removed at
    the end of each ``every`` seconds."""

    id: int
    name: str
    lo: np.ndarray | None = None
    hi: np.ndarray | None = None
    point: np.ndarray | None = None
    normal: np.ndarray | None = None
    every: float = DEFAULT_EVERY
    line: int | None = None

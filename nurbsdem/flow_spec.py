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
    """``Inlet ID Name n Shapes s1 .. Fractions f1 .. Material m Box x0 y0 z0 x1 y1 z1 Rate r
    Count c [Velocity vx vy vz] [Seed s] [Every e]``: particles of the shapes ``shapes`` (by
    number fractions summing to 1) and material ``material_id``, placed in the box [lo, hi]
    (m) at ``rate`` particles/s until ``count`` of them, with velocity ``velocity`` (m/s), a
    random stream of its own (``seed``), inserted at the end of each ``every`` seconds."""

    id: int
    name: str
    shapes: tuple
    fractions: tuple
    material_id: int
    lo: np.ndarray
    hi: np.ndarray
    rate: float
    count: int
    velocity: np.ndarray = field(default_factory=lambda: np.zeros(3))
    seed: int = 0
    every: float = DEFAULT_EVERY
    line: int | None = None


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

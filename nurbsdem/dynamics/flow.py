"""Inflow and outflow: where and when particles enter a scene, and which ones leave it.

**Inlets** create particles during a dynamic step in a region (an axis-aligned box, or a disc
given by a centre, an axis and a radius, with a thickness) at a rate (particles/s, or kg/s
through the mean mass of the mix) until a count, a mass or a time is reached.  Each new
particle draws its shape from the mix by the given fractions, a uniformly random orientation
and the inlet's velocity.  Its position is the first of ``max_attempts`` uniform draws in the
region where its bounding sphere overlaps neither a particle already there nor one placed in
the same call (the compiled sphere grid of the ``Random`` placement over the bounding spheres
near the region, :mod:`nurbsdem.geometry.sphere_grid`); in a periodic cell, with the images
across its faces of the particles near them.  When the region has no room, the particles
wait for the next call and :attr:`Inlet.waiting` says how many (the driver reports it once).

**Outlets** remove the particles whose centroid is in a box or beyond a plane, and count
them and their mass (:class:`Outlet`, with the rows of ``monitors/outlet_<name>.csv``).

Units: SI (m, s, kg).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from ..contact.periodic import PeriodicCell, ghost_images
from ..geometry.rotation import random_quaternions
from ..geometry.sphere_grid import add_sphere, add_spheres, first_clear, sphere_grid


@dataclass
class InsertionRegion:
    """A box [lo, hi] (m), or a disc (``centre``, ``axis``, ``radius``, ``thickness`` m)
    when ``axis`` is given."""

    lo: np.ndarray | None = None
    hi: np.ndarray | None = None
    centre: np.ndarray | None = None
    axis: np.ndarray | None = None
    radius: float = 0.0
    thickness: float = 0.0

    def sample(self, rng: np.random.Generator, n: int, margin: np.ndarray) -> np.ndarray:
        """n points (n,3) drawn uniformly in the region shrunk by ``margin`` (n,) m (each new
        particle's bounding radius: it starts wholly inside)."""
        if self.is_disc:
            e1, e2, e3 = _frame(self.axis)
            rho = np.sqrt(rng.uniform(0, 1, n)) * np.maximum(self.radius - margin, 0.0)
            phi = rng.uniform(0, 2 * math.pi, n)
            h = rng.uniform(-0.5, 0.5, n) * np.maximum(self.thickness - 2 * margin, 0.0)
            return (self.centre + (rho * np.cos(phi))[:, None] * e1
                    + (rho * np.sin(phi))[:, None] * e2 + h[:, None] * e3)
        lo = self.lo[None] + margin[:, None]
        hi = np.maximum(self.hi[None] - margin[:, None], lo)
        return lo + rng.uniform(0, 1, (n, 3)) * (hi - lo)

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """The region's axis-aligned bounding box (m)."""
        if self.is_disc:
            ext = np.full(3, self.radius + 0.5 * self.thickness)
            return self.centre - ext, self.centre + ext
        return self.lo, self.hi

    @property
    def is_disc(self) -> bool:
        """Whether the region is a disc (it has an axis; else a box)."""
        return self.axis is not None

    def support(self, d: np.ndarray) -> float:
        """max x·d over the region (m × |d|): the box's farthest corner along d; the disc's
        centre plus its radius along d's part across the axis and half its thickness along
        the axis."""
        d = np.asarray(d, float)
        if self.is_disc:
            e3 = self.axis / np.linalg.norm(self.axis)
            along = float(d @ e3)
            across = float(np.linalg.norm(d - along * e3))
            return float(self.centre @ d) + self.radius * across + 0.5 * self.thickness * abs(along)
        return float(np.sum(np.maximum(self.lo * d, self.hi * d)))

    def outline(self, k: int = 32) -> np.ndarray:
        """Points (m, (n,3)) whose convex hull is the box (its 8 corners), or inscribed in the
        disc (``k`` points on each rim circle and its centre)."""
        if self.is_disc:
            e1, e2, e3 = _frame(self.axis)
            phi = np.linspace(0.0, 2 * math.pi, k, endpoint=False)
            ring = self.radius * (np.cos(phi)[:, None] * e1 + np.sin(phi)[:, None] * e2)
            h = 0.5 * self.thickness * e3
            return np.concatenate([self.centre + ring + h, self.centre + ring - h,
                                   self.centre[None]])
        return np.array([[x, y, z] for x in (self.lo[0], self.hi[0])
                         for y in (self.lo[1], self.hi[1]) for z in (self.lo[2], self.hi[2])])

    def volume(self, radius: float = 0.0) -> float:
        """The volume (m^3) that bounding spheres of ``radius`` m placed in the region fill:
        the box's, or the disc's radius² π times its thickness, at least the spheres'
        diameter (a thin disc holds one layer of them)."""
        if self.is_disc:
            return math.pi * self.radius ** 2 * max(self.thickness, 2.0 * radius)
        return float(np.prod(self.hi - self.lo))

    def centres(self, margin: float) -> "InsertionRegion":
        """The region in which :meth:`sample` places the centre of a particle of bounding
        radius ``margin`` m (the region shrunk by it, as :meth:`sample` shrinks it)."""
        if self.is_disc:
            return InsertionRegion(centre=self.centre, axis=self.axis,
                                   radius=max(self.radius - margin, 0.0),
                                   thickness=max(self.thickness - 2 * margin, 0.0))
        lo = self.lo + margin
        return InsertionRegion(lo=lo, hi=np.maximum(self.hi - margin, lo))


def _frame(axis: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Unit vectors e1, e2 across ``axis`` and e3 along it (right-handed)."""
    e3 = np.asarray(axis, float) / np.linalg.norm(axis)
    e1 = np.cross(e3, np.eye(3)[int(np.argmin(np.abs(e3)))])
    e1 /= np.linalg.norm(e1)
    return e1, np.cross(e3, e1), e3


@dataclass
class NewParticles:
    """Particles an inlet created: shape indices into the mix's shapes (k,), positions (k,3)
    m, orientations as unit quaternions (k,4) (w, x, y, z), velocities (k,3) m/s."""

    shapes: np.ndarray
    positions: np.ndarray
    quaternions: np.ndarray
    velocities: np.ndarray


@dataclass
class Inlet:
    """An inlet (module docstring).

    shapes: the mix's shape ids; fractions (same length, summing to 1) by number;
    radii, masses: each mix shape's bounding radius (m) and mass (kg); rate: particles/s
    (``rate_is_mass``: kg/s); limits: ``count``, ``mass`` (kg), ``until`` (s), any of them
    None; ``start`` (s) when its rate clock starts, ``base`` the particles (a real number)
    it owed then (:meth:`restart_clock`); ``seed`` for its own random stream;
    ``max_attempts`` draws per particle before it waits; ``cell``: the scene's periodic cell
    (:class:`~nurbsdem.contact.periodic.PeriodicCell`, the region inside it along its
    periodic axes), whose images of the particles near its faces a new particle must clear
    too, or None.
    """

    region: InsertionRegion
    shapes: np.ndarray
    fractions: np.ndarray
    radii: np.ndarray
    masses: np.ndarray
    rate: float
    rate_is_mass: bool = False
    velocity: np.ndarray = field(default_factory=lambda: np.zeros(3))
    count: int | None = None
    mass: float | None = None
    until: float | None = None
    start: float = 0.0
    base: float = 0.0
    seed: int = 0
    max_attempts: int = 50
    cell: PeriodicCell | None = None
    inserted: int = 0
    inserted_mass: float = 0.0
    waiting: int = 0
    _queue: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    _rng: np.random.Generator | None = None

    def __post_init__(self) -> None:
        self.fractions = np.asarray(self.fractions, float)
        self._rng = np.random.default_rng(self.seed)

    @property
    def number_rate(self) -> float:
        """Particles per second: the rate, or the mass rate over the mix's mean mass."""
        if self.rate_is_mass:
            return self.rate / float(np.dot(self.fractions, self.masses))
        return self.rate

    def _credit(self, t: float) -> float:
        """Particles owed in all by time t (s), before rounding down: :attr:`base` plus rate ×
        the time since :attr:`start` within the time limit."""
        if t <= self.start:
            return self.base
        end = t if self.until is None else max(min(t, self.until), self.start)
        return self.base + self.number_rate * (end - self.start)

    def owed_total(self, t: float) -> int:
        """The particles owed in all by time t (s): the credit rounded down, within the
        count."""
        total = int(math.floor(self._credit(t) + 1e-9))
        return total if self.count is None else min(total, self.count)

    def restart_clock(self, t: float) -> None:
        """Start the rate clock at t (s) (a timed step begins): the credit owed by then, its
        fraction of a particle included, stays owed (:attr:`base`; a waiting particle still
        enters), and the rate counts on from t, so that a run of steps owes rate × the time
        the inlet was open, rounded down once."""
        self.base = self._credit(t)
        self.start = t

    def due(self, t: float) -> int:
        """How many particles the inlet owes by time t (s): :meth:`owed_total` less those
        inserted, none once the mass limit is reached."""
        owed = max(self.owed_total(t) - self.inserted, 0)
        if self.mass is not None and self.inserted_mass >= self.mass:
            owed = 0
        return owed

    def _draw_shapes(self, n: int) -> np.ndarray:
        """Indices into the mix for n more particles, kept in a queue so that a particle that
        waits keeps its shape (the mix's fractions hold over the whole run)."""
        if len(self._queue) < n:
            more = self._rng.choice(len(self.shapes), size=n - len(self._queue),
                                    p=self.fractions)
            self._queue = np.concatenate([self._queue, more])
        return self._queue[:n]

    def insert(self, t: float, centers: np.ndarray, radii: np.ndarray) -> NewParticles:
        """The particles due at t (s), placed without overlapping the bounding spheres
        (centers (N,3), radii (N,) m) of the particles present; those that find no room
        wait (:attr:`waiting`)."""
        n = self.due(t)
        kinds = self._draw_shapes(n)
        r_new = self.radii[kinds]
        grid, n_near = self._obstacles(centers, radii, r_new)
        placed_x, taken = np.empty((n, 3)), []
        for k in range(n):
            x = self._place_one(float(r_new[k]), grid)
            if x is None:
                break                      # the region is full: the rest waits, in order
            placed_x[k] = x
            add_sphere(grid, n_near + k, x[0], x[1], x[2], float(r_new[k]))
            taken.append(kinds[k])
        m = len(taken)
        self._queue = self._queue[m:]
        self.inserted += m
        self.inserted_mass += float(self.masses[np.asarray(taken, np.int64)].sum()) if m else 0.0
        self.waiting = n - m
        return NewParticles(self.shapes[np.asarray(taken, np.int64)],
                            placed_x[:m].copy(),
                            random_quaternions(self._rng, m),
                            np.repeat(np.asarray(self.velocity, float)[None], m, axis=0))

    def _obstacles(self, centers: np.ndarray, radii: np.ndarray,
                   r_new: np.ndarray) -> tuple[tuple, int]:
        """The sphere grid (:mod:`nurbsdem.geometry.sphere_grid`) of the bounding spheres
        that a new particle of radii ``r_new`` in the region could meet, with room for the new
        ones after them; and their count.  In a periodic cell these include the images across
        its faces of the particles near them; two new particles, both inside the region and
        so inside the cell, cannot meet through a face."""
        lo, hi = self.region.bounds()
        reach = (float(radii.max()) if len(radii) else 0.0) + (float(r_new.max())
                                                                if len(r_new) else 0.0)
        if self.cell is not None and len(centers):
            images, owner, _ = ghost_images(np.asarray(centers, float), reach, self.cell)
            centers = np.concatenate([centers, images])
            radii = np.concatenate([radii, radii[owner]])
        near = np.flatnonzero(np.all((centers >= lo - reach) & (centers <= hi + reach),
                                     axis=1)) if len(centers) else np.zeros(0, np.int64)
        largest = max(float(radii[near].max()) if len(near) else 0.0,
                      float(r_new.max()) if len(r_new) else 0.0)
        grid = sphere_grid(len(near) + len(r_new), 2.0 * largest if largest > 0.0 else 1.0)
        add_spheres(grid, np.ascontiguousarray(centers[near], float),
                    np.ascontiguousarray(radii[near], float))
        return grid, len(near)

    def _place_one(self, r: float, grid: tuple) -> np.ndarray | None:
        """A position for a particle of bounding radius r clear of the spheres of ``grid``
        (the particles present and those placed in this call): the first of ``max_attempts``
        uniform draws in the region that is, or None."""
        candidates = self.region.sample(self._rng, self.max_attempts,
                                        np.full(self.max_attempts, r))
        k = first_clear(grid, np.ascontiguousarray(candidates, float), r)
        return candidates[k] if k >= 0 else None


@dataclass
class Outlet:
    """An outlet: a box [lo, hi] (m), or the half-space beyond a plane (``point``, unit
    ``normal`` pointing out of the scene) when ``normal`` is given; it counts what it
    removed."""

    name: str
    lo: np.ndarray | None = None
    hi: np.ndarray | None = None
    point: np.ndarray | None = None
    normal: np.ndarray | None = None
    count: int = 0
    mass: float = 0.0
    rows: list[tuple[float, int, float, float]] = field(default_factory=list)

    def catches(self, x: np.ndarray) -> np.ndarray:
        """Bool (N,): the centroids x (N,3) that are in the outlet."""
        if self.normal is not None:
            return (x - self.point) @ self.normal > 0.0
        return np.all((x >= self.lo) & (x <= self.hi), axis=1)

    def remove(self, t: float, x: np.ndarray, masses: np.ndarray) -> np.ndarray:
        """The indices of the particles (centroids x (N,3), masses (N,) kg) to remove at t
        (s); adds them to the count and the discharged mass and appends a monitor row
        (t, count, mass, mass flow rate since the previous row)."""
        gone = np.flatnonzero(self.catches(x))
        self.count += len(gone)
        self.mass += float(masses[gone].sum())
        t0, _, m0, _ = self.rows[-1] if self.rows else (t, 0, 0.0, 0.0)
        rate = (self.mass - m0) / (t - t0) if t > t0 else 0.0
        self.rows.append((t, self.count, self.mass, rate))
        return gone

"""Regular lattices of particle positions, and the dense pack built from one that the
time-step control is verified on (tests/test_stepcontrol.py, benchmarks/bench_timestep.py)."""
from __future__ import annotations

import numpy as np


def fcc_positions(cells: int, spacing: float, origin=(0.0, 0.0, 0.0)) -> np.ndarray:
    """Centres (M,3) of a face-centred cubic block of ``cells``³ unit cells, nearest neighbours
    ``spacing`` apart (m): the points (i, j, k)·spacing/√2 with 0 <= i, j, k <= 2·cells and
    i + j + k even.  Interior points have the 12 neighbours of the FCC lattice."""
    if cells < 1 or not spacing > 0:
        raise ValueError("fcc_positions needs cells >= 1 and spacing > 0")
    g = np.arange(2 * cells + 1)
    i, j, k = np.meshgrid(g, g, g, indexing="ij")
    even = ((i + j + k) % 2) == 0
    pts = np.stack([i[even], j[even], k[even]], axis=1).astype(float)
    return pts * (spacing / np.sqrt(2.0)) + np.asarray(origin, float)[None]


def fcc_sphere_block(dt: float, cells: int = 2, overlap: float = 1e-5, substeps: int | None = None,
                     watch_period2: bool = True, seed: int = 1, safety: float = 0.5,
                     implicit_damping: bool = False):
    """A dense pack: exact NURBS spheres with particle C's mass (paper Table 1: volume
    21.29 cm³, density 2700 kg/m³, volume-equivalent radius) in FCC order, each interior
    sphere with 12 contacts ``overlap`` (m) deep, held by six walls that touch the outer
    spheres as deep; zero gravity; the paper's contact law (εn 1e5, cn 1e2, εt 1e4, μ 0.5);
    small random velocities (1 mm/s); ``safety`` and ``implicit_damping`` as for the
    :class:`~nurbsdem.dynamics.DemSystem` (a step's ``Safety`` and ``Damping``).  Returns
    ``(system, trace)``: a
    :class:`~nurbsdem.dynamics.DemSystem` with deck step ``dt`` (s) and the list that receives
    the centroids (N,3) at every force evaluation (every internal step)."""
    from .contact.scene import SceneContacts
    from .dynamics import ContactLaw, DemSystem, InterfaceTable, sphere_inertia
    from .shapes import box_walls, sphere

    volume = 21.29e-6
    r = (3 * volume / (4 * np.pi)) ** (1 / 3)
    m = 2700 * volume
    X = fcc_positions(cells, 2 * r - overlap, origin=(0.1, 0.1, 0.1))
    law = ContactLaw(en=1e5, cn=1e2, et=1e4, ct=0.0, mu=0.5)
    s = DemSystem(dt=dt, gravity=(0, 0, 0), interfaces=InterfaceTable(default=law),
                  substeps=substeps, watch_period2=watch_period2, safety=safety,
                  implicit_damping=implicit_damping)
    rng = np.random.default_rng(seed)
    for x in X:
        s.add_particle(m, sphere_inertia(m, r), x, v=rng.normal(0, 1e-3, 3), radius=r)
    walls = list(box_walls(X.min(0) - r + overlap, X.max(0) + r - overlap, top=True).values())
    for _ in walls:
        s.add_wall()
    scene = SceneContacts([sphere(r)], np.zeros(len(X), np.int64), walls)
    trace: list[np.ndarray] = []

    def provider(kin):
        trace.append(kin.x.copy())
        return scene(kin)
    s.set_contact_provider(provider)
    return s, trace

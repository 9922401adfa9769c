"""The record a contact provider hands to the dynamics at each force evaluation
(docs/conventions.md): arrays over the K active contacts, counters, and optional extras.
One record for every provider: the scene's (:class:`~nurbsdem.contact.scene.SceneContacts`)
and the analytic test provider's (:class:`~nurbsdem.dynamics.analytic_contact.SpherePlaneProvider`).

Units: metres; global body indices (particles 0..N-1, walls N..N+W-1); ``normal`` from A
towards B; ``depth`` >= 0; ``key`` = body_a · (N+W) + body_b.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass
class ContactSet:
    """Active contacts of one evaluation (docs/conventions.md): arrays over K contacts, plus
    counters."""

    body_a: np.ndarray
    body_b: np.ndarray
    point_a: np.ndarray
    point_b: np.ndarray
    normal: np.ndarray
    depth: np.ndarray
    key: np.ndarray
    degenerated: np.ndarray
    monitored: int = 0
    active: int = 0
    degenerated_count: int = 0
    failed: int = 0
    #: failed LCPs answered by the previous solution moved rigidly (one evaluation at most)
    reused: int = 0
    #: failed LCPs whose pair was left out of the force evaluation
    dropped: int = 0
    #: keys of the pairs left out (their elastic energy is booked as dissipated by the system)
    dropped_keys: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    near_a: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    near_b: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    near_point: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    near_normal: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    near_gap: np.ndarray = field(default_factory=lambda: np.zeros(0))
    #: surface parameters (uA, vA, uB, vB) and local patch indices of the active contacts
    #: (patch −1: a closed form for exact spheres), for the curvature of Hertz contact
    params: np.ndarray = field(default_factory=lambda: np.zeros((0, 4)))
    patch_a: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    patch_b: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    #: periodic cells (:mod:`nurbsdem.contact.periodic`): per active contact the translation
    #: (m) of the image of body B it touches (zeros: B itself; the points are in that image);
    #: empty: no periodic cell
    image: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    #: the same for the separated pairs (``near_*``)
    near_image: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    #: the translation (N,3) (m) taken off each particle's centroid by the wrap into the cell
    #: at this evaluation's list build (empty: no wrap); the system applies it to its state
    wrap: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))

    @classmethod
    def empty(cls) -> "ContactSet":
        z = np.zeros(0, np.int64)
        e3 = np.zeros((0, 3))
        return cls(z, z.copy(), e3, e3.copy(), e3.copy(), np.zeros(0), z.copy(), z.copy())

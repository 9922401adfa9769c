"""Analytic contact providers (spheres and planes) to verify the dynamics without NURBS.

:class:`SpherePlaneProvider` returns a :class:`~nurbsdem.contact.contactset.ContactSet`
for spheres of given radii (centred on the particle centroids) and half-space walls (a plane
through ``point`` with unit normal ``normal`` pointing into the domain, translated by the wall's
prescribed displacement).  Pair convention: sphere–sphere i < j gives body_a = i, body_b = j;
sphere–wall gives body_a = particle, body_b = wall, normal from the sphere towards the wall
(= −wall normal).  O(N²) pair loop in numpy: for tests and benchmarks with small N.
"""
from __future__ import annotations

import numpy as np

from ..contact.contactset import ContactSet


class SpherePlaneProvider:
    """Contacts between spheres (radii (N,) m) and planes (walls, in the system's wall order).

    planes: list of (point (3,), inward unit normal (3,)) at zero wall displacement.
    """

    def __init__(self, radii, planes=()) -> None:
        self.radii = np.asarray(radii, dtype=float)
        self.plane_points = np.array([np.asarray(p, float) for p, _ in planes]).reshape(-1, 3)
        nrm = np.array([np.asarray(n, float) for _, n in planes]).reshape(-1, 3)
        if len(nrm):
            nrm = nrm / np.linalg.norm(nrm, axis=1)[:, None]
        self.plane_normals = nrm

    def __call__(self, kin) -> ContactSet:
        x = kin.x
        r = self.radii
        N = x.shape[0]
        nb = kin.n_bodies
        A, B, PA, PB, NR, D = [], [], [], [], [], []
        if N > 1:
            i, j = np.triu_indices(N, 1)
            dvec = x[j] - x[i]
            dist = np.linalg.norm(dvec, axis=1)
            pen = r[i] + r[j] - dist
            m = pen > 0
            if m.any():
                n = dvec[m] / dist[m][:, None]
                A.append(i[m]); B.append(j[m]); NR.append(n); D.append(pen[m])
                PA.append(x[i[m]] + r[i[m]][:, None] * n)
                PB.append(x[j[m]] - r[j[m]][:, None] * n)
        for k in range(self.plane_normals.shape[0]):
            nw = self.plane_normals[k]
            p0 = self.plane_points[k] + kin.wall_displacement[k]
            h = (x - p0) @ nw
            pen = r - h
            m = pen > 0
            if m.any():
                idx = np.nonzero(m)[0]
                A.append(idx); B.append(np.full(idx.size, N + k, dtype=np.int64))
                NR.append(np.repeat(-nw[None], idx.size, axis=0)); D.append(pen[m])
                PA.append(x[idx] - r[idx][:, None] * nw[None])
                PB.append(x[idx] - h[idx][:, None] * nw[None])
        if not A:
            return ContactSet.empty()
        a = np.concatenate(A).astype(np.int64)
        b = np.concatenate(B).astype(np.int64)
        K = a.size
        return ContactSet(a, b, np.concatenate(PA), np.concatenate(PB), np.concatenate(NR),
                          np.concatenate(D), a * nb + b, np.zeros(K, dtype=np.int64),
                          monitored=K, active=K)


def sphere_inertia(mass: float, radius: float) -> np.ndarray:
    """Solid sphere inertia about its centre, (2/5) m r² I (kg m²)."""
    return 0.4 * mass * radius ** 2 * np.eye(3)

"""Contacts with a periodic image of a body, for the internal step's compiled parts.

In a periodic cell (:mod:`nurbsdem.contact.periodic`) a contact can touch the image of its
body B translated by t = s∘L (the ContactSet's ``image``); its points lie in that image,
so the lever arm of B is p − (x_B + t).  The step's parts take one position per body, so each
such contact gets an **image body**: an extra particle G after the N particles (the walls
follow them), a copy of B at x_B + t with B's velocity, angular momentum, mass and inertia
(:class:`ImageBodies`).  The contact part's loads on an image are added to its owner
(the moment about the image's centroid is the moment about the owner's: the same arm), and
a half kick gives each image its owner's summed loads, so that image and owner stay equal to
the bit and the exact discrete work of the kick's impulses (paper §2.3, the energy ledger)
sees the contact's true relative velocity.  Units: SI.
"""
from __future__ import annotations

import numpy as np

from ..jit import internal

#: the fields of the step's constants (:class:`~nurbsdem.dynamics.step.BodyConst`) over the
#: particles, and over all bodies (particles then walls)
_PARTICLE_FIELDS = ("mass", "inv_mass", "inv_I", "P", "centroid", "ell", "alt_floor_x",
                    "alt_floor_L", "sq_m", "sq_I")
_BODY_FIELDS = ("inv_mass_all", "material")


class ImageBodies:
    """The image bodies of the contacts (a, b) whose B is a particle's image translated by
    ``image`` (K,3) m (rows of zeros: B itself), in a system of n particles."""

    def __init__(self, n: int, b: np.ndarray, image: np.ndarray) -> None:
        idx = np.flatnonzero(np.any(image != 0.0, axis=1) & (b < n))
        self.n = int(n)
        self.own = np.ascontiguousarray(b[idx], np.int64)
        self.offset = np.ascontiguousarray(image[idx], float)
        self.G = int(idx.shape[0])
        b_ext = np.where(b >= n, b + self.G, b)
        b_ext[idx] = n + np.arange(self.G)
        #: body B of each contact in the extended numbering
        self.b = np.ascontiguousarray(b_ext, np.int64)

    @staticmethod
    def of(n: int, b: np.ndarray, image: np.ndarray) -> "ImageBodies | None":
        """The image bodies of the contacts, None when no contact touches an image."""
        if image.shape[0] == 0 or not np.any(image != 0.0):
            return None
        return ImageBodies(n, b, image)

    def particles(self, arr: np.ndarray) -> np.ndarray:
        """A particle array (N, ...) with its images' rows after it."""
        return np.ascontiguousarray(np.concatenate((arr, arr[self.own])))

    def positions(self, x: np.ndarray) -> np.ndarray:
        """Centroids (N,3) m with the images' after them."""
        return np.ascontiguousarray(np.concatenate((x, x[self.own] + self.offset)))

    def bodies(self, arr: np.ndarray, positions: bool = False) -> np.ndarray:
        """An array over all bodies (N+W, ...) with the images' rows between the particles
        and the walls (``positions``: translated to the images)."""
        n = self.n
        img = arr[self.own] + self.offset if positions else arr[self.own]
        return np.ascontiguousarray(np.concatenate((arr[:n], img, arr[n:])))

    def const(self, bc):
        """The step's constants with the image bodies' rows."""
        fields = {f: self.particles(getattr(bc, f)) for f in _PARTICLE_FIELDS}
        fields.update({f: self.bodies(getattr(bc, f)) for f in _BODY_FIELDS})
        return bc._replace(**fields)

    def fold(self, loads: np.ndarray) -> np.ndarray:
        """Loads (N+G+W, 3) of the extended bodies as loads (N+W, 3): each image's added to
        its owner's."""
        n, G = self.n, self.G
        out = np.concatenate((loads[:n], loads[n + G:]))
        np.add.at(out, self.own, loads[n:n + G])
        return out


@internal
def image_particles(arr, own):
    """A particle array with the rows of the images of the particles ``own`` (G,) after it
    (compiled :meth:`ImageBodies.particles`)."""
    return np.concatenate((arr, arr[own]))


@internal
def image_positions(x, own, offset):
    """Centroids (N,3) m with the images' after them, translated by ``offset`` (G,3) m."""
    return np.concatenate((x, x[own] + offset))


@internal
def image_rows(arr, own, n: int):
    """An array over all bodies (N+W, ...) with the images' rows between the n particles and
    the walls (compiled :meth:`ImageBodies.bodies`)."""
    return np.concatenate((arr[:n], arr[own], arr[n:]))


@internal
def fold_images(loads, own, n: int):
    """Loads (N+G+W, 3) of the extended bodies as loads (N+W, 3): each image's added to its
    owner's, in image order (compiled :meth:`ImageBodies.fold`, the same bits)."""
    G = own.shape[0]
    out = np.concatenate((loads[:n], loads[n + G:]))
    for g in range(G):
        for k in range(3):
            out[own[g], k] += loads[n + g, k]
    return out

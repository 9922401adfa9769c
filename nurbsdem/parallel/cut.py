"""The cut of the particles over MPI ranks and the contact work it balances
(:class:`~nurbsdem.parallel.Domain` re-cuts by it; the module docstring of
:mod:`nurbsdem.parallel.domain` says when).

The cut is a recursive coordinate bisection of the centroids (:func:`decompose`): equal
particle counts, or equal weights where each particle weighs its counted contact work
(:class:`ContactWork`): every solve of a listed pair at its solver's :data:`SOLVE_COST`, to
both its particles, plus :data:`BODY_COST` per particle and evaluation.  The weights are
integers, summed over the ranks exactly, so every rank computes the same cut.
"""
from __future__ import annotations

import numpy as np

from ..contact.kinds import (CLOSED_FORM, FLAT_WALL, LCP, NURBS_PARTICLE, PAIR_SOLVER,
                             POINT_SURFACE, SPHERE, WALL_SUPPORT)

#: a re-cut also happens when the most loaded rank's share of the counted work exceeds the
#: even share by more than this fraction and a cut by the work lowers that excess by as much
#: (the imbalance threshold 1.05 of the first example of LAMMPS' and LIGGGHTS' ``fix balance``,
#: where the user sets it)
WORK_IMBALANCE = 0.05
#: what one solve of each pair solver of the scene's list (CLOSED_FORM, POINT_SURFACE, LCP,
#: WALL_SUPPORT of :mod:`nurbsdem.contact.kinds`) costs, in hundredths of a warm LCP of two
#: paper particles: the LCP's and the point solver's warm times in the report's contact
#: benchmarks (about 5 and 1.3 µs), rounded; the others estimated (a closed form is a few
#: lines of arithmetic, the wall's support mapping has three unknowns against the LCP's six).
#: Integers, so that the ranks' sums are exact and every rank computes the same cut.
SOLVE_COST = np.zeros(max(CLOSED_FORM, POINT_SURFACE, LCP, WALL_SUPPORT) + 1, np.int64)
SOLVE_COST[[CLOSED_FORM, POINT_SURFACE, LCP, WALL_SUPPORT]] = 5, 30, 100, 50
#: the work of one particle's integration and loads per evaluation, in the units of
#: :data:`SOLVE_COST` (the step outside the contact problems takes
#: about a third of a warm LCP per particle in the settled packs of the report)
BODY_COST = 30


def decompose(x: np.ndarray, parts: int, weight: np.ndarray | None = None) -> np.ndarray:
    """Owner rank (N,) of each particle: recursive coordinate bisection of the centroids x (N,3)
    m into ``parts`` groups, cut across the longest extent, ties by particle index
    (deterministic).  Without ``weight`` the groups have equal counts (±1); with ``weight``
    (N,) int64 >= 0, equal weights: each cut leaves on its low side the particles, in order
    along the axis, whose running sum stays within the low groups' share, and at least one
    particle per group."""
    owner = np.zeros(x.shape[0], np.int64)
    w = np.ones(x.shape[0], np.int64) if weight is None else np.asarray(weight, np.int64)
    _bisect(x, w, np.arange(x.shape[0]), 0, parts, owner)
    return owner


def _bisect(x: np.ndarray, w: np.ndarray, ids: np.ndarray, first: int, parts: int,
            owner: np.ndarray) -> None:
    if parts == 1 or ids.size == 0:
        owner[ids] = first
        return
    pts = x[ids]
    axis = int(np.argmax(pts.max(axis=0) - pts.min(axis=0)))
    order = ids[np.lexsort((ids, pts[:, axis]))]
    left = parts // 2
    running = np.cumsum(w[order])
    k = int(np.searchsorted(running, (int(running[-1]) * left) // parts, side="right"))
    if ids.size >= parts:
        k = min(max(k, left), ids.size - (parts - left))
    _bisect(x, w, order[:k], first, left, owner)
    _bisect(x, w, order[k:], first + left, parts - left, owner)


def pair_solvers(is_sphere: np.ndarray, a: np.ndarray, b: np.ndarray, n: int,
                 point_surface: bool) -> np.ndarray:
    """The pair solver (:mod:`nurbsdem.contact.kinds`) of each listed pair (a[k], b[k]) of a
    scene, as :func:`~nurbsdem.contact.kinds.pair_solver` picks it: body a is a particle, b a
    particle or a flat wall (index >= n); ``is_sphere`` (n,) which particles are exact
    spheres; ``point_surface``: the scene solves spheres against NURBS particles by the
    point solver."""
    kind_a = np.where(is_sphere[a], SPHERE, NURBS_PARTICLE)
    part = b < n
    kind_b = np.full(b.shape[0], FLAT_WALL, np.int64)
    kind_b[part] = np.where(is_sphere[b[part]], SPHERE, NURBS_PARTICLE)
    solver = PAIR_SOLVER[kind_a, kind_b]
    if not point_surface:
        solver[solver == POINT_SURFACE] = LCP
    return solver


def imbalance(owner: np.ndarray, weight: np.ndarray, parts: int) -> float:
    """How far the most loaded of ``parts`` groups is above the even share of the total
    ``weight`` (N,) (0: even; 0.1: 10 % above)."""
    loads = np.bincount(owner, weights=weight.astype(float), minlength=parts)
    mean = loads.sum() / parts
    return float(loads.max() / mean - 1.0) if mean > 0 else 0.0


class ContactWork:
    """The contact work of n particles counted on one rank since the last cut.

    :meth:`count` takes each evaluation's due rows of the scene's neighbour list (a count per
    listed pair); :meth:`folded` turns the counts into the particles' work when the list
    changes and before a cut is weighed; :meth:`weights` adds the particles' own work to the
    ranks' sum of it."""

    def __init__(self, owned: np.ndarray, scene) -> None:
        """``owned`` (n,) bool: the rank's particles (it counts the pairs whose body A it
        owns, so that the ranks' work summed has each pair once); ``scene``: the
        :class:`~nurbsdem.contact.scene.SceneContacts` whose list is counted (its
        ``is_sphere`` and ``point_surface`` name each pair's solver)."""
        self.n = int(owned.shape[0])
        self._owned = owned
        self._scene = scene
        #: each particle's counted contact work (SOLVE_COST units)
        self.work = np.zeros(self.n, np.int64)
        #: evaluations counted
        self.evaluations = 0
        #: (a, b, solves) of the list whose solves are being counted
        self._hits: tuple | None = None

    def count(self, a: np.ndarray, b: np.ndarray, due: np.ndarray) -> None:
        """Count an evaluation's solves: the rows ``due`` of the list (a, b) (b may be a flat
        wall).  A list other than the last one's (a rebuild, a restored deck step) folds the
        last list's counts first."""
        if self._hits is None or self._hits[0] is not a:
            self._fold()
            self._hits = (a, b, np.zeros(a.shape[0], np.int64))
        self._hits[2][due] += 1
        self.evaluations += 1

    def folded(self) -> np.ndarray:
        """The work (n,) with the counts folded in."""
        self._fold()
        return self.work

    def weights(self, total: np.ndarray) -> np.ndarray:
        """The cut's weights (n,) from the ranks' work summed: plus :data:`BODY_COST` per
        evaluation (twice, as a pair's cost goes to both its particles)."""
        return total + 2 * BODY_COST * self.evaluations

    def _fold(self) -> None:
        """Add the counted solves to the particles' work: each at its solver's
        :data:`SOLVE_COST`, to both particles (a wall pair's twice to its particle)."""
        if self._hits is None:
            return
        a, b, hits = self._hits
        self._hits = None
        sel = self._owned[a] & (hits > 0)
        a, b, hits = a[sel], b[sel], hits[sel]
        sc = self._scene
        cost = hits * SOLVE_COST[pair_solvers(sc.is_sphere, a, b, self.n, sc.point_surface)]
        part = b < self.n
        self.work += np.bincount(a, weights=np.where(part, cost, 2 * cost),
                                 minlength=self.n).astype(np.int64)
        self.work += np.bincount(b[part], weights=cost[part], minlength=self.n).astype(np.int64)

"""Support function of a point set, h(n) = max_b n . x_b, for many directions at once.

The convexity measure (:func:`nurbsdem.geometry.connectivity.measure_convexity`) needs, for
every sampled tangent plane (point x_a, unit normal n_a), the largest height of the other
samples above it: max_b n_a . (x_b - x_a) = h(n_a) - n_a . x_a. Comparing all pairs costs
N^2 (2e9 products for the 42 000 samples of a 78 x 78 control net per patch); here the
maximum is found on the convex hull of the samples (``scipy.spatial.ConvexHull``, Qhull,
N log N): a linear function on a convex polytope has its maximum at a vertex, and from any
vertex that is not the maximum an edge of the polytope leads uphill, so a walk from vertex
to better neighbour ends at the maximum (the simplex method's argument). Each walk starts at
the vertex whose direction from the centre is nearest the query's (a k-d tree), which for a
smooth convex surface is at or near the maximum, so a walk takes a few steps.

The result equals the all-pairs maximum up to Qhull's precision (points it leaves off the
hull as coplanar lie within ~1e-13 of the size of it); degenerate sets (all points in one
plane, fewer than 5 points) fall back to all pairs.
"""
from __future__ import annotations

import numpy as np

#: Directions handled per block (memory: block x max degree x 3 floats).
BLOCK = 4096


class Support:
    """The support function of the points ``X`` (N, 3) (m).

    ``query(N)`` returns (h, index): h[k] = max_b N[k] . X[b] and the maximising b (an index
    into ``X``). ``walk_steps`` counts the uphill steps the queries took (a measure of the
    work that does not grow with N for smooth surfaces; tests read it). The values are
    computed relative to the points' mean ``centre`` (h - N . centre is what
    :func:`max_height` uses), so that round-off scales with the size of the set, not with
    its distance from the origin.
    """

    def __init__(self, X: np.ndarray) -> None:
        X = np.asarray(X, float)
        self.centre = X.mean(axis=0) if len(X) else np.zeros(3)
        self.X = np.ascontiguousarray(X - self.centre)
        self.walk_steps = 0
        self.vertices = None
        if len(self.X) >= 5:
            try:
                from scipy.spatial import ConvexHull
                hull = ConvexHull(self.X)
            except Exception:   # QhullError: a flat or degenerate set; all pairs below
                hull = None
            if hull is not None:
                self._build(hull)

    def _build(self, hull) -> None:
        """Hull vertices, their coordinates and the padded neighbour table of the hull's
        triangulated surface (a vertex pads its row with itself)."""
        verts = np.asarray(hull.vertices, np.int64)
        local = np.full(len(self.X), -1, np.int64)
        local[verts] = np.arange(len(verts))
        tri = local[np.asarray(hull.simplices, np.int64)]
        edges = np.concatenate([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [2, 0]]])
        edges = np.concatenate([edges, edges[:, ::-1]])
        key = np.unique(edges[:, 0] * len(verts) + edges[:, 1])      # sorted by first vertex
        edges = np.stack([key // len(verts), key % len(verts)], axis=1)
        counts = np.bincount(edges[:, 0], minlength=len(verts))
        deg = int(counts.max())
        start = np.concatenate([[0], np.cumsum(counts)[:-1]])
        slot = np.arange(len(edges)) - start[edges[:, 0]]
        nb = np.repeat(np.arange(len(verts))[:, None], deg, axis=1)
        nb[edges[:, 0], slot] = edges[:, 1]
        self.vertices = verts
        self.V = self.X[verts]
        self.neighbours = nb
        from scipy.spatial import cKDTree
        r = np.linalg.norm(self.V, axis=1, keepdims=True)
        self.directions = cKDTree(self.V / np.where(r > 0, r, 1.0))

    def query(self, N: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(h - N . centre, index) for the directions N (M, 3) (zero rows give 0)."""
        N = np.asarray(N, float)
        h = np.empty(len(N))
        idx = np.empty(len(N), np.int64)
        for s in range(0, len(N), BLOCK):
            part = N[s:s + BLOCK]
            if self.vertices is None:
                D = part @ self.X.T
                k = np.argmax(D, axis=1)
                h[s:s + BLOCK], idx[s:s + BLOCK] = D[np.arange(len(part)), k], k
            else:
                v, val = self._walk(part)
                h[s:s + BLOCK], idx[s:s + BLOCK] = val, self.vertices[v]
        return h, idx

    def _walk(self, N: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Hull vertex maximising each direction's value, and the value: from the vertex in
        the direction nearest the query's, move to the best neighbour while it is strictly
        better."""
        r = np.linalg.norm(N, axis=1, keepdims=True)
        cur = np.asarray(self.directions.query(N / np.where(r > 0, r, 1.0))[1], np.int64)
        val = np.einsum("kj,kj->k", self.V[cur], N)
        active = np.arange(len(N))
        while len(active):
            nb = self.neighbours[cur[active]]                    # (k, deg)
            vals = np.einsum("kdj,kj->kd", self.V[nb], N[active])
            j = np.argmax(vals, axis=1)
            best = vals[np.arange(len(active)), j]
            up = best > val[active]
            moved = active[up]
            cur[moved] = nb[up, j[up]]
            val[moved] = best[up]
            self.walk_steps += int(up.sum())
            active = moved
        return cur, val


def max_height(Xa: np.ndarray, Na: np.ndarray, support: Support,
               extra: np.ndarray | None = None) -> tuple[float, int, int]:
    """max over a, b of Na[a] . (Xb[b] - Xa[a]) (m), with the maximising (a, b), where the
    points Xb are ``extra`` (a few, compared pairwise; indices first) followed by the points
    of ``support``."""
    base = np.einsum("ij,ij->i", Na, np.asarray(Xa, float) - support.centre)
    h, ib = support.query(Na)
    off = 0
    if extra is not None and len(extra):
        off = len(extra)
        E = Na @ (np.asarray(extra, float) - support.centre).T
        ke = np.argmax(E, axis=1)
        he = E[np.arange(len(Na)), ke]
        better = he >= h
        h = np.where(better, he, h)
        ib = np.where(better, ke, ib + off)
    else:
        ib = ib + off
    D = h - base
    a = int(np.argmax(D))
    return float(D[a]), a, int(ib[a])


__all__ = ["Support", "max_height"]

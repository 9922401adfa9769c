"""A sphere swept along a straight line against a triangle mesh, in closed form: where it
first comes within a distance of the mesh (``MoveWall … ToContact`` of a mesh wall).

The centre moves as c(s) = c0 − s d (d unit, s m: the travel of the wall along d, seen from
the mesh's frame).  The points within ρ of one triangle T form a convex set (T ⊕ ball(ρ)),
whose boundary is made of

* the two caps: the triangle's plane moved by ±ρ along its normal n, over the triangle;
* the three edges' cylinders of radius ρ, over the length of each edge;
* the three vertices' spheres of radius ρ.

Before its first point in that set the line is outside every part, so its first point lies
on one of these pieces, where the line enters that piece's plane, cylinder or sphere (the
smaller root of its linear or quadratic equation) at a point that passes the piece's test
(inside the triangle, between the edge's ends); every such entry lies in the set.  The first
entry is therefore the least of the pieces' valid entries, and over the mesh the least over
its triangles: the first s with dist(c(s), mesh) = ρ.  On a two-sided mesh both sides of
each triangle count (the distance to the mesh's surface); on a one-sided mesh only entries in
front of the triangle's plane (the side its normal points to), as the mesh's contacts count
only spheres whose centre is in front: a triangle met from behind lets the sphere through.

Lengths in metres.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

#: relative slack (of ρ and of the triangle's size) of the pieces' tests: an entry exactly on
#: a piece's border is kept by one of its neighbours too, so the slack only keeps round-off
#: from losing both
SLACK = 1e-12


@njit(cache=True, inline="always")
def _sphere_entry(w0, w1, w2, d0, d1, d2, rho):
    """Smaller s with |w − s d| = ρ (w = c0 − centre, d unit); inf if the line misses."""
    b = w0 * d0 + w1 * d1 + w2 * d2
    disc = b * b - (w0 * w0 + w1 * w1 + w2 * w2) + rho * rho
    if disc < 0.0:
        return math.inf
    return b - math.sqrt(disc)


@njit(cache=True)
def _edge_entry(c, d, p, q, rho):
    """First s at which c − s d enters the cylinder of radius ρ about segment (p, q), at a
    point between the segment's ends; inf if none."""
    e0, e1, e2 = q[0] - p[0], q[1] - p[1], q[2] - p[2]
    length = math.sqrt(e0 * e0 + e1 * e1 + e2 * e2)
    e0, e1, e2 = e0 / length, e1 / length, e2 / length
    w0, w1, w2 = c[0] - p[0], c[1] - p[1], c[2] - p[2]
    we = w0 * e0 + w1 * e1 + w2 * e2
    de = d[0] * e0 + d[1] * e1 + d[2] * e2
    u0, u1, u2 = w0 - we * e0, w1 - we * e1, w2 - we * e2        # perpendicular parts
    v0, v1, v2 = d[0] - de * e0, d[1] - de * e1, d[2] - de * e2
    a = v0 * v0 + v1 * v1 + v2 * v2
    if a < 1e-24:
        return math.inf                   # along the edge: the vertices' spheres hold it
    b = u0 * v0 + u1 * v1 + u2 * v2
    disc = b * b - a * (u0 * u0 + u1 * u1 + u2 * u2 - rho * rho)
    if disc < 0.0:
        return math.inf
    s = (b - math.sqrt(disc)) / a
    along = we - s * de
    if along < -SLACK * length or along > length * (1.0 + SLACK):
        return math.inf
    return s


@njit(cache=True)
def _cap_entry(c, d, a, b, cc, n, rho):
    """First s at which c − s d crosses the triangle's plane moved by ρ towards the side it
    comes from, at a point over the triangle; inf if none."""
    nd = n[0] * d[0] + n[1] * d[1] + n[2] * d[2]
    if abs(nd) < 1e-15:
        return math.inf
    nw = n[0] * (c[0] - a[0]) + n[1] * (c[1] - a[1]) + n[2] * (c[2] - a[2])
    s = (nw - (rho if nd > 0.0 else -rho)) / nd
    x = np.empty(3)
    for k in range(3):
        x[k] = c[k] - s * d[k]
    # inside the triangle: x on the inner side of each edge (in the plane's normal sense)
    size = 0.0
    for k in range(3):
        size = max(size, abs(b[k] - a[k]), abs(cc[k] - a[k]))
    for p, q in ((a, b), (b, cc), (cc, a)):
        t0, t1, t2 = q[0] - p[0], q[1] - p[1], q[2] - p[2]
        m0 = t1 * n[2] - t2 * n[1]
        m1 = t2 * n[0] - t0 * n[2]
        m2 = t0 * n[1] - t1 * n[0]                   # t × n: outward in the plane
        out = (m0 * (x[0] - p[0]) + m1 * (x[1] - p[1]) + m2 * (x[2] - p[2]))
        if out > SLACK * size * math.sqrt(m0 * m0 + m1 * m1 + m2 * m2):
            return math.inf
    return s


@njit(cache=True, inline="always")
def _in_front(s, c, d, a, n, rho, two_sided):
    """s, or inf where the mesh is one-sided and the entry point c − s d lies behind the
    triangle's plane (through a, normal n), by more than round-off of ρ."""
    if two_sided or not s < math.inf:
        return s
    side = (n[0] * (c[0] - s * d[0] - a[0]) + n[1] * (c[1] - s * d[1] - a[1])
            + n[2] * (c[2] - s * d[2] - a[2]))
    return s if side >= -SLACK * rho else math.inf


@njit(cache=True)
def triangle_entry(c, d, a, b, cc, n, rho, two_sided=True):
    """First s (m) at which the point c − s d (c (3,) m, d (3,) unit) comes within ρ (m) of
    the triangle (a, b, cc) with unit normal n (module docstring); inf if it never does.  Not
    ``two_sided``: only entries in front of the triangle (the side n points to)."""
    s = _in_front(_cap_entry(c, d, a, b, cc, n, rho), c, d, a, n, rho, two_sided)
    for p, q in ((a, b), (b, cc), (cc, a)):
        s = min(s, _in_front(_edge_entry(c, d, p, q, rho), c, d, a, n, rho, two_sided))
    for v in (a, b, cc):
        s = min(s, _in_front(_sphere_entry(c[0] - v[0], c[1] - v[1], c[2] - v[2], d[0], d[1],
                                           d[2], rho), c, d, a, n, rho, two_sided))
    return s


@njit(cache=True)
def sweep_entries(centres, rho, d, vertices, faces, normals, two_sided=True):
    """(N,) first travel s (m) at which each point c − s d comes within rho[i] (m) of the mesh
    (vertices (V,3), faces (T,3), unit normals (T,3); centres (N,3) and d (3,) unit in the
    mesh's frame); inf where the line never does.  Not ``two_sided``: from the front of the
    triangles only (module docstring)."""
    T = faces.shape[0]
    ball = np.empty((T, 4))              # each triangle's bounding ball: centre, radius
    for t in range(T):
        for k in range(3):
            ball[t, k] = (vertices[faces[t, 0], k] + vertices[faces[t, 1], k]
                          + vertices[faces[t, 2], k]) / 3.0
        r2 = 0.0
        for j in range(3):
            v = vertices[faces[t, j]]
            r2 = max(r2, (v[0] - ball[t, 0]) ** 2 + (v[1] - ball[t, 1]) ** 2
                     + (v[2] - ball[t, 2]) ** 2)
        ball[t, 3] = math.sqrt(r2) * (1.0 + 1e-9)
    out = np.full(centres.shape[0], np.inf)
    for i in range(centres.shape[0]):
        c = centres[i]
        best = math.inf
        for t in range(T):
            # the line passes farther than ρ from the triangle's ball: no entry
            w0, w1, w2 = c[0] - ball[t, 0], c[1] - ball[t, 1], c[2] - ball[t, 2]
            wd = w0 * d[0] + w1 * d[1] + w2 * d[2]
            reach = rho[i] + ball[t, 3]
            if w0 * w0 + w1 * w1 + w2 * w2 - wd * wd > reach * reach * (1.0 + 1e-9):
                continue
            best = min(best, triangle_entry(c, d, vertices[faces[t, 0]], vertices[faces[t, 1]],
                                            vertices[faces[t, 2]], normals[t], rho[i],
                                            two_sided))
        out[i] = best
    return out

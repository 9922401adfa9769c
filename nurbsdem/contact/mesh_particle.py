"""A convex NURBS particle against a triangle-mesh wall, per triangle, edge and vertex.

The particle A is given by its support mapping p_A(d) (the point of its surface farthest
along the unit direction d, paper Eq. 8–9) and h_A(d) = d · p_A(d), its support function,
asked through :class:`~nurbsdem.contact.support_oracle.SupportOracle` (the flat-wall
kernel's support mapping, with dp/dd, paper Eq. 14–15).  Everything is solved in the mesh's
own frame (:mod:`nurbsdem.contact.mesh_wall`: the particle's pose is brought there).

For a convex A and a convex feature X of the mesh (a triangle's face, an edge, a vertex) the
signed distance (negative: the penetration depth) is

    sd = − min over unit d of [ h_A(d) + h_X(−d) ],

d being the contact normal from the particle towards the wall.  Each mesh feature has its
own region of normals, in which the minimum is a contact of that feature:

* **face** of a triangle with unit normal n facing the particle (the side of its centroid):
  d = −n, the deepest point p = p_A(−n), sd = n · (p − a) (a: a vertex), the wall's point the
  projection of p on the plane; a contact when that projection lies in the triangle.  This is
  the flat wall of :mod:`nurbsdem.contact.flat_wall` (the same kernel: a flat wall's numbers to
  round-off, whichever triangle of a plane holds the contact);
* **edge** (P0, P1) with unit direction t: d ⊥ t, h_X(−d) = −d · P0, so f(θ) = h_A(d(θ)) −
  d(θ) · P0 over the circle of directions normal to the edge; f'(θ) = (p_A − P0) · d' and
  f'' = d'ᵀ (dp/dd) d' − (p_A − P0) · d.  The edge's normal cone is where every triangle
  around it has the edge as its farthest feature along −d (d · w ≥ 0, w the triangle's
  in-plane normal from the edge inwards): an arc, empty of interior on a flat internal edge
  (there the faces hold every contact).  A safeguarded Newton on f' = 0 inside the arc; a
  contact when the root's point q = P0 + ((p − P0) · t) t lies on the segment.  Where the
  particle may reach over the edge's line (f > 0 at both ends of the arc) the arc is also
  sampled, and the least of its minima is the contact: deep in a tilted, elongated particle
  the arc holds two, one on either side of the mesh;
* **vertex** V: h_X(−d) = −d · V, stationary where p_A(d) − V ∥ d, a Newton on the tangent
  components with the Jacobian (dp/dd)_t − λ I (λ = d · (p_A − V)): the point-to-surface
  problem of :mod:`nurbsdem.contact.sphere` in the support-function form (it holds
  with V inside A; where h_A(d) − d · V is not convex, steepest-descent turns of d lead
  Newton in); a contact when d lies in the vertex's normal cone (d · (x − V) ≥ 0 for every
  vertex x of the triangles around V), or when V is the deepest point of a boundary edge at
  V (d · (X − V) ≥ 0 along the edge (V, X), with d in that edge's arc): at a reflex corner
  of the boundary (a vertex of an orifice's polygon) the cone is the plane's normal alone,
  and the rim's corner holds the contact of the edge whose own root lies beyond it.

**One contact per flat or convex region** (the rule of :mod:`nurbsdem.contact.mesh_wall`): a
face contact always counts; an edge or vertex contact counts only with its normal in the
feature's normal cone over all triangles around it, on the particle's side (against the sum
of its triangles' normals facing the particle's centroid), so a convex fold gives one edge
contact between the two face regions and a concave fold none (one per face there).  An edge
of the mesh's boundary (one triangle: the rim of an orifice, the end of a chute) has no
other side: its arc reaches round the edge from face to face, and a particle whose end
dipped past the plane touches it from whichever side its least penetration lies on.  A face
contact needs the particle to pass the plane inside the triangle's region: when the segment
from the centroid to the deepest point crosses the plane beyond a boundary edge (a tilted
particle through an orifice, its end under the rim), the part under the triangle came round
the rim, and the face holds no contact.
Contacts at the same point (within 1e-12 of the mesh size, or 1e-9 for an edge or vertex
contact, whose point comes from an iteration) are one, the face's first.  The cone and the face tests
meet at their borders (the deepest point projecting onto an edge or vertex), where the two
contacts are the same: the contact passes from one feature to the next continuously.

One-sided meshes ignore the triangles whose front face the particle's centroid is behind.
Lengths in metres; rows in the layout of :mod:`nurbsdem.contact.lcp` (``I_PB``: a triangle
of the feature; ``I_PA``: −1).
"""
from __future__ import annotations

import math

import numpy as np

from .lcp import F_N, F_PA, F_PAR, F_PB, F_SD, I_ACTIVE, I_IT, I_PA, I_PB, I_VALID, NF, NI
from .mesh_wall import (EDGE_AB, FACE, TIE, VERTEX_A, MeshWall, _triangle_candidates,
                        triangles_near)
from .mesh_topology import inward, topology
from .support_oracle import SupportOracle

#: Newton iterations of an edge or vertex contact before it counts as not converged
MAX_IT = 40
#: convergence: the stationarity residual below this × the particle's bounding radius
TOL = 1e-13
#: relative tie of an iterated contact's point (edge or vertex) with another contact's
ITERATED_TIE = 1e-9
#: an edge's normal arc narrower than this (rad) has no interior (a flat internal edge)
MIN_ARC = 1e-12
#: the largest turn (rad) of a vertex contact's normal per Newton step
MAX_TURN = 0.5
#: intervals of an edge's normal arc sampled for its least penetration when the particle may
#: reach over the edge's line (the edge's line deep in a tilted, elongated particle: two
#: local minima, on either side of the mesh)
ARC_SAMPLES = 8
#: a sample of the arc is another minimum's when it is less than the root's f by this × the
#: bounding radius (not round-off about the same root)
DEEPER = 1e-9

__all__ = ["particle_mesh_contacts", "FACE", "EDGE_AB", "VERTEX_A"]


def _to_mesh(R: np.ndarray, t: np.ndarray, pos: np.ndarray, Rb: np.ndarray):
    """The body pose (pos, Rb) (world) in the mesh frame of the wall at (R, t)."""
    return R.T @ (np.asarray(pos, float) - t), R.T @ np.asarray(Rb, float)


def _near_triangles(mesh: MeshWall, c: np.ndarray, reach: float, work) -> np.ndarray:
    """The triangles within ``reach`` (m) of the point c (mesh frame): the grid broad phase
    and the exact closest point of each (:mod:`nurbsdem.contact.mesh_wall`)."""
    stamp, tris, cand_q, cand_d, cand_f = work
    mark = min(int(stamp.min()), -1) - 1     # below the sphere kernel's marks (from 0 up)
    n = triangles_near(c, reach, mesh.grid_origin, mesh.grid_cell, mesh.grid_dims,
                       mesh.cell_start, mesh.cell_tris, stamp, mark, tris)
    n = _triangle_candidates(c, reach, mesh.vertices, mesh.faces, mesh.normals, True, tris,
                             min(n, len(tris)), cand_q, cand_d, cand_f)
    near = tris[:n].copy()
    if not mesh.two_sided:
        a = mesh.vertices[mesh.faces[near, 0]]
        front = np.einsum("ij,ij->i", c - a, mesh.normals[near]) >= 0.0
        near = near[front]
    return near


# ---------------------------------------------------------------------------- features


def _may_hold(oracle: SupportOracle, mesh: MeshWall, near: np.ndarray) -> np.ndarray:
    """(T,) bool: whether the deepest point below each triangle's plane may project into it:
    the support point along its normal facing the particle (one per distinct normal, within
    1e-9) projects within 1e-8 of the mesh size of the triangle (the face contact is then
    solved exactly, :func:`_face`)."""
    if len(near) == 0:
        return np.zeros(0, bool)
    tri = mesh.vertices[mesh.faces[near]]                          # (T, 3, 3)
    n = mesh.normals[near]
    n = n * np.where(np.einsum("ij,ij->i", oracle.centroid - tri[:, 0], n) >= 0.0,
                     1.0, -1.0)[:, None]
    keys, inverse = np.unique(np.round(n * 1e9), axis=0, return_inverse=True)
    deepest = np.array([oracle.point(-n[np.flatnonzero(inverse.ravel() == k)[0]])[0]
                        for k in range(len(keys))])
    p = deepest[inverse.ravel()]
    margin = 1e-8 * mesh.size
    ok = np.ones(len(near), bool)
    for k in range(3):
        x, y, z = tri[:, k], tri[:, (k + 1) % 3], tri[:, (k + 2) % 3]
        w = np.cross(n, y - x)                  # in-plane, normal to edge (x, y)
        w *= np.where(np.einsum("ij,ij->i", w, z - x) > 0.0, 1.0, -1.0)[:, None]
        ok &= np.einsum("ij,ij->i", p - x, w) >= -margin * np.linalg.norm(w, axis=1)
    return ok


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """a × b for 3-vectors (without numpy's general-axis overhead)."""
    return np.array([a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2],
                     a[0] * b[1] - a[1] * b[0]])


def _face(oracle: SupportOracle, mesh: MeshWall, tri: int):
    """(sd, p, q, d) of the face contact of triangle ``tri`` (module docstring), None when
    the deepest point projects outside it, or when the particle passes the triangle's plane
    beyond one of its border edges (:func:`_crosses_beyond_border`)."""
    a, b, c = (mesh.vertices[mesh.faces[tri, k]] for k in range(3))
    n = mesh.normals[tri]
    if np.dot(oracle.centroid - a, n) >= 0.0:
        ea, eb = b - a, c - a
    else:                                   # the back face: its normal towards the body
        ea, eb = c - a, b - a
    rf, ri = oracle.plane(a, ea, eb)
    al, be = rf[F_PAR + 2], rf[F_PAR + 3]
    if not (ri[I_VALID] == 1 and al >= 0.0 and be >= 0.0 and al + be <= 1.0):
        return None
    p = rf[F_PA:F_PA + 3].copy()
    if _crosses_beyond_border(mesh, tri, oracle.centroid, p):
        return None
    return float(rf[F_SD]), p, rf[F_PB:F_PB + 3].copy(), rf[F_N:F_N + 3].copy()


def _crosses_beyond_border(mesh: MeshWall, tri: int, c: np.ndarray, p: np.ndarray) -> bool:
    """Whether the segment from the particle's centroid c to its deepest point p below the
    plane of triangle ``tri`` crosses that plane beyond a border edge of the triangle (an
    edge of the mesh's boundary, :func:`~nurbsdem.contact.mesh_topology.topology`): then the
    particle passes the plane outside the mesh (a tilted particle whose end reaches under the
    rim of an orifice), the segment between c and p lies in it, and the part of it under the
    triangle came round the rim, not through the triangle: the face holds no contact (the
    rim's edge does, where the particle reaches it)."""
    f = mesh.faces[tri].tolist()
    n = mesh.normals[tri]
    a = mesh.vertices[f[0]]
    sc, sp = float(n @ (c - a)), float(n @ (p - a))
    if not sc * sp < 0.0:
        return False
    r = c + (sc / (sc - sp)) * (p - c)
    border = topology(mesh)[0]
    for k in range(3):
        i, j = f[k], f[(k + 1) % 3]
        if len(border.get((min(i, j), max(i, j)), ())) != 1:
            continue
        x, y, z = mesh.vertices[i], mesh.vertices[j], mesh.vertices[f[(k + 2) % 3]]
        w = np.cross(n, y - x)
        if float(w @ (z - x)) < 0.0:
            w = -w
        if float(w @ (r - x)) < 0.0:
            return True
    return False


def _edge_arc(t: np.ndarray, inward: list) -> tuple[np.ndarray, np.ndarray, float, float]:
    """(e1, e2, lo, hi): a basis of the plane normal to the edge direction t and the arc
    [lo, hi] (rad) of the directions d = cos θ e1 + sin θ e2 with d · w ≥ 0 for each in-plane
    inward normal w of ``inward`` (the edge's normal cone)."""
    e1 = inward[0]
    e2 = _cross(t, e1)
    lo, hi = -0.5 * math.pi, 0.5 * math.pi
    for w in inward[1:]:
        phi = math.atan2(float(w @ e2), float(w @ e1))
        lo, hi = max(lo, phi - 0.5 * math.pi), min(hi, phi + 0.5 * math.pi)
    return e1, e2, lo, hi


def _edge(oracle: SupportOracle, p0: np.ndarray, p1: np.ndarray, inward: list,
          active_only: bool = False):
    """(sd, p, q, d, iterations) of the edge contact of segment (p0, p1) whose triangles
    have the in-plane inward normals ``inward`` (module docstring), None when the minimum
    over its normal arc is not inside the arc or its point is off the segment (or, with
    ``active_only``, when a support plane separates the segment from the particle).  Where
    the particle may reach over the edge's line (f > 0 at both ends of the arc) the arc is
    also sampled (:data:`ARC_SAMPLES`): deep in a tilted, elongated particle the arc holds
    two local minima, on either side of the mesh, and the least is the contact."""
    L = float(np.linalg.norm(p1 - p0))
    t = (p1 - p0) / L
    e1, e2, lo, hi = _edge_arc(t, inward)
    if hi - lo < MIN_ARC:
        return None
    mid = 0.5 * (lo + hi)
    if active_only and _separated(oracle, math.cos(mid) * e1 + math.sin(mid) * e2, (p0, p1)):
        return None

    def slope(th):
        d = math.cos(th) * e1 + math.sin(th) * e2
        dd = -math.sin(th) * e1 + math.cos(th) * e2
        p, M, ok = oracle.point(d)
        r = p - p0
        return float(r @ dd), float(dd @ M @ dd - r @ d), p, d, ok

    g_lo, _, p_lo, d_lo, _ = slope(lo)
    g_hi, _, p_hi, d_hi, _ = slope(hi)
    tol = TOL * oracle.radius
    root = _edge_root(slope, lo, hi, tol) if g_lo < 0.0 < g_hi else None
    if float(d_lo @ (p_lo - p0)) > 0.0 and float(d_hi @ (p_hi - p0)) > 0.0:
        samples = [slope(lo + k * (hi - lo) / ARC_SAMPLES) for k in range(ARC_SAMPLES + 1)]
        f = [float(d @ (p - p0)) for _, _, p, d, _ in samples]
        k = int(np.argmin(f))
        a, b = max(k - 1, 0), min(k + 1, ARC_SAMPLES)
        least = None if root is None else float(root[2] @ (root[1] - p0)) - DEEPER * oracle.radius
        if samples[a][0] < 0.0 < samples[b][0] and (least is None or f[k] < least):
            other = _edge_root(slope, lo + a * (hi - lo) / ARC_SAMPLES,
                               lo + b * (hi - lo) / ARC_SAMPLES, tol)
            if other is not None and (root is None or float(other[2] @ (other[1] - p0))
                                      < float(root[2] @ (root[1] - p0))):
                root = other
    if root is None:
        return None
    _, p, d, it = root
    s = float((p - p0) @ t)
    if s < 0.0 or s > L:
        return None
    q = p0 + s * t
    return float(d @ (q - p)), p, q, d, it


def _edge_root(slope, lo: float, hi: float, tol: float):
    """(θ, p, d, iterations) of the safeguarded Newton on f'(θ) = 0 in [lo, hi], where f'
    changes sign from − to + (``slope``: θ → (f', f'', p, d, ok)); None when it fails."""
    th = 0.5 * (lo + hi)
    for it in range(MAX_IT):
        g, h, p, d, ok = slope(th)
        if not ok:
            return None
        if abs(g) <= tol:
            break
        if g < 0.0:
            lo = th
        else:
            hi = th
        step = th - g / h if h > 0.0 else 0.5 * (lo + hi)
        th = step if lo < step < hi else 0.5 * (lo + hi)
        if hi - lo < 1e-15:
            break
    else:
        return None
    return th, p, d, it


def _tangent_basis(d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two unit vectors completing the unit vector d to an orthonormal basis."""
    k = int(np.argmin(np.abs(d)))
    e = np.zeros(3)
    e[k] = 1.0
    u1 = e - d * d[k]
    u1 /= np.linalg.norm(u1)
    return u1, _cross(d, u1)


def _vertex(oracle: SupportOracle, V: np.ndarray, d0: np.ndarray):
    """(sd, p, q, d, iterations) of the point V against the particle (module docstring),
    Newton from the normal d0 (steepest-descent turns where the Jacobian is not positive
    definite); None when it does not converge to a minimum."""
    d = d0 / np.linalg.norm(d0)
    tol = TOL * oracle.radius
    for it in range(MAX_IT):
        p, M, ok = oracle.point(d)
        if not ok:
            return None
        r = p - V
        lam = float(d @ r)
        u1, u2 = _tangent_basis(d)
        F = np.array([u1 @ r, u2 @ r])
        J = np.array([[u1 @ M @ u1, u1 @ M @ u2], [u2 @ M @ u1, u2 @ M @ u2]]) - lam * np.eye(2)
        J = 0.5 * (J + J.T)
        convex = np.linalg.eigvalsh(J)[0] > 0.0
        if abs(F[0]) <= tol and abs(F[1]) <= tol:
            if not convex:
                return None                      # not a minimum of h_A(d) − d · V
            return -lam, p, V.copy(), d, it
        # where h_A(d) − d · V is not convex (V deep in the particle, d far from the
        # minimum), a steepest-descent turn of the normal (its gradient F over the support
        # distance λ) until Newton can take over
        step = -np.linalg.solve(J, F) if convex else -F / max(abs(lam), tol)
        size = float(np.linalg.norm(step))
        if size > MAX_TURN:
            step *= MAX_TURN / size
        d = d + step[0] * u1 + step[1] * u2
        d /= np.linalg.norm(d)
    return None


# ---------------------------------------------------------------------------- the mesh


def _features(mesh: MeshWall, near: np.ndarray) -> tuple[dict, dict]:
    """The edges {(i, j): [triangles]} and vertices {i: [triangles]} of the triangles
    ``near`` that are not flat (:func:`~nurbsdem.contact.mesh_topology.topology`)."""
    sharp, corners, tri_edges, tri_verts = topology(mesh)
    edges = {e: sharp[e] for tri in near.tolist() for e in tri_edges[tri]}
    verts = {v: corners[v] for tri in near.tolist() for v in tri_verts[tri]}
    return edges, verts


def _facing(oracle: SupportOracle, mesh: MeshWall, tri: int) -> np.ndarray:
    """The unit normal of triangle ``tri`` on the side of the particle's centroid."""
    n = mesh.normals[tri]
    a = mesh.vertices[mesh.faces[tri, 0]]
    return n if np.dot(oracle.centroid - a, n) >= 0.0 else -n


def _in_vertex_cone(mesh: MeshWall, V_id: int, tris: list, d: np.ndarray) -> bool:
    """Whether V is the farthest point along −d of every triangle of ``tris`` around it."""
    V = mesh.vertices[V_id]
    tol = 1e-12 * mesh.size
    for tri in tris:
        for k in mesh.faces[tri].tolist():
            if k != V_id and float(d @ (mesh.vertices[k] - V)) < -tol:
                return False
    return True


def _deepest_of_a_border_edge(mesh: MeshWall, V_id: int, tris: list, d: np.ndarray) -> bool:
    """Whether the vertex V with the contact normal d is the deepest point of an edge of the
    mesh's boundary at V: d · (X − V) ≥ 0 along the edge (V, X), so that the edge's line is
    deepest beyond V and its own contact is off the segment, with d in that edge's normal arc
    (d · w ≥ 0, w its triangle's in-plane normal from the edge inwards: the particle beside
    the rim, not over the face).  At a reflex corner of a boundary (a vertex of an orifice's
    polygon, where the mesh turns by more than half a turn) the vertex's normal cone is the
    plane's normal alone, and this is the contact of the rim's corner."""
    border = topology(mesh)[0]
    V = mesh.vertices[V_id]
    for tri in tris:
        for k in mesh.faces[tri].tolist():
            if k == V_id or len(border.get((min(k, V_id), max(k, V_id)), ())) != 1:
                continue
            if (float(d @ (mesh.vertices[k] - V)) >= 0.0
                    and float(d @ inward(mesh, tri, V_id, k)) >= 0.0):
                return True
    return False


def _segment_distance(c: np.ndarray, p0: np.ndarray, p1: np.ndarray) -> float:
    """Distance (m) from the point c to the segment (p0, p1)."""
    e = p1 - p0
    s = min(max(float((c - p0) @ e) / float(e @ e), 0.0), 1.0)
    return float(np.linalg.norm(c - p0 - s * e))


def _on_particle_side(oracle: SupportOracle, mesh: MeshWall, tris: list,
                      d: np.ndarray) -> bool:
    """Whether the contact normal d (from the particle to the wall) of an edge or vertex
    contact points against the sum of its triangles' normals facing the particle: the
    feature's normal cone on the particle's side (a fold concave towards the particle has its
    cone on the other side of a two-sided mesh, where the fold is convex)."""
    facing = sum(_facing(oracle, mesh, tri) for tri in tris)
    return float(d @ facing) < 0.0


def _separated(oracle: SupportOracle, d: np.ndarray, points) -> bool:
    """Whether the plane of the particle's support point along the unit d has all ``points``
    beyond it (then none of them is inside the particle)."""
    p, _, ok = oracle.point(d)
    h = float(d @ p)
    return ok and all(float(d @ x) > h for x in points)


def _candidates(oracle: SupportOracle, mesh: MeshWall, near: np.ndarray,
                active_only: bool, reach: float) -> list:
    """The contacts [(sd, p, q, d, feature, triangle, iterations)] of the particle with the
    triangles ``near`` (module docstring), before the ties; ``active_only``: features the
    particle does not reach (a support plane separates them) are left out; edges and
    vertices farther than ``reach`` (m) from the centroid are not solved."""
    out = []
    for tri in near[_may_hold(oracle, mesh, near)].tolist():
        face = _face(oracle, mesh, tri)
        if face is not None:
            out.append(face + (FACE, tri, 1))
    edges, verts = _features(mesh, near)
    c = oracle.centroid
    for (i, j), tris in edges.items():
        p0, p1 = mesh.vertices[i], mesh.vertices[j]
        if _segment_distance(c, p0, p1) > reach:
            continue
        normals_in = [inward(mesh, tri, i, j) for tri in tris]
        e = _edge(oracle, p0, p1, normals_in, active_only)
        if e is not None and (len(tris) == 1 or _on_particle_side(oracle, mesh, tris, e[3])):
            out.append(e[:4] + (EDGE_AB, tris[0], e[4]))
    for v, tris in verts.items():
        V = mesh.vertices[v]
        if np.linalg.norm(V - c) > reach:
            continue
        d0 = -sum(_facing(oracle, mesh, tri) for tri in tris)
        if not np.linalg.norm(d0) > 1e-9:
            continue
        d0 = d0 / np.linalg.norm(d0)
        if active_only and _separated(oracle, d0, [V]):
            continue
        hit = _vertex(oracle, V, d0)
        if hit is not None and ((_in_vertex_cone(mesh, v, tris, hit[3])
                                 and _on_particle_side(oracle, mesh, tris, hit[3]))
                                or _deepest_of_a_border_edge(mesh, v, tris, hit[3])):
            out.append(hit[:4] + (VERTEX_A, tris[0], hit[4]))
    return out


def _distinct(cands: list, size: float) -> list:
    """The contacts of ``cands`` with those at the same point as an earlier one (a face's
    first) left out (module docstring)."""
    order = sorted(range(len(cands)), key=lambda k: (cands[k][4] != FACE, k))
    kept = []
    for k in order:
        q, feat = cands[k][2], cands[k][4]
        same = False
        for m in kept:
            tie = (TIE if feat == FACE and cands[m][4] == FACE else ITERATED_TIE) * size
            if np.linalg.norm(cands[m][2] - q) <= tie:
                same = True
                break
        if not same:
            kept.append(k)
    return [cands[k] for k in sorted(kept)]


def particle_mesh_contacts(table, shape: int, pos: np.ndarray, Rb: np.ndarray,
                           mesh: MeshWall, R: np.ndarray | None = None,
                           t: np.ndarray | None = None, work=None,
                           active_only: bool = True,
                           reach: float | None = None) -> tuple[np.ndarray, np.ndarray]:
    """The contact rows (rows_f (K,NF), rows_i (K,NI), world frame, normal from the particle
    to the wall) of the NURBS particle of shape ``shape`` of ``table`` (a
    :class:`~nurbsdem.contact.detect.ContactTable`) at the pose (pos (3,) m, Rb (3,3):
    ``x = pos + Rb x_file``) with ``mesh`` at the pose (R, t) (identity by default); only
    those with sd < 0 unless ``active_only`` is False.  ``work``: the mesh's
    :func:`~nurbsdem.contact.mesh_wall.make_workspace` (made when None).  ``reach`` (m): the
    features within it of the centroid are solved (None: the bounding radius; a larger one
    gives the separated features' exact distances, ``MoveWall … ToContact``)."""
    from .mesh_wall import make_workspace
    R = np.eye(3) if R is None else np.asarray(R, float)
    t = np.zeros(3) if t is None else np.asarray(t, float)
    work = make_workspace(mesh) if work is None else work
    pm, Rm = _to_mesh(R, t, pos, Rb)
    oracle = SupportOracle(table, shape, pm, Rm)
    if reach is not None and reach > oracle.radius:
        oracle.radius = float(reach)        # the flat-wall solve's early exit beyond it too
    near = _near_triangles(mesh, oracle.centroid, oracle.radius, work)
    cands = _distinct(_candidates(oracle, mesh, near, active_only, oracle.radius), mesh.size)
    if active_only:
        cands = [c for c in cands if c[0] < 0.0]
    rows_f = np.zeros((len(cands), NF))
    rows_i = np.zeros((len(cands), NI), np.int64)
    for k, (sd, p, q, d, feat, tri, it) in enumerate(cands):
        rows_f[k, F_SD] = sd
        rows_f[k, F_N:F_N + 3] = R @ d
        rows_f[k, F_PA:F_PA + 3] = R @ p + t
        rows_f[k, F_PB:F_PB + 3] = R @ q + t
        rows_i[k, I_PA] = -1
        rows_i[k, I_PB] = tri
        rows_i[k, I_IT] = it
        rows_i[k, I_VALID] = 1
        rows_i[k, I_ACTIVE] = 1 if sd < 0.0 else 0
    return rows_f, rows_i

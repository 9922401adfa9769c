"""Patch connectivity of a closed multi-patch NURBS surface, and the shape checks.

Connectivity (paper Sec. 3.2.2: "connectivity stored per particle, 4 neighbours per
rectangular patch") is found automatically from the geometry: every edge of every patch is
sampled at a few points and compared with every other edge, forward and reversed, within a
tolerance relative to the particle size. Conventions (see ``docs/DEVNOTES.md``):

* edge index e: 0 = u_min, 1 = u_max, 2 = v_min, 3 = v_max;
* the edge parameter s in [0, 1] runs along increasing v on edges 0/1 and along increasing
  u on edges 2/3;
* ``neighbours[i, e] = (j, f, rev)``: edge e of patch i coincides with edge f of patch j,
  s maps to s (rev = 0) or to 1 - s (rev = 1) on edge f;
* j = -2: the edge is collapsed to a point (a pole), f = rev = -1;
* j = -1: open edge (only in shapes built with ``check=False``);
* a seam (an edge coinciding with another edge of the same patch, e.g. the single-patch
  sphere) has j = i.

The neighbour's parametrisation of a shared edge must be the same as this patch's up to
the affine map s -> s or 1 - s (true for edges that share their control points and weights,
which is how CAD tools join patches); an edge that coincides with another only as a point
set but with a different parametrisation is reported as a gap.

Corners (nodes where three or more patches meet, paper Eq. 10–15: the degeneration with
no free parameter) are listed in :attr:`Connectivity.corners`.

:func:`check_shape` rejects shapes that are not closed, not consistently outward oriented or
not convex, with a :class:`~nurbsdem.errors.GeometryError` naming the file, the patch and
the edge or parameters where the check fails. Lengths in metres.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Sequence

import numpy as np
from numba import njit

from ..errors import GeometryError
from .nurbs import Patch

#: Edge names by edge index.
EDGE_NAMES = ("u_min", "u_max", "v_min", "v_max")
#: Direction of the counter-clockwise boundary traversal of the parameter rectangle in terms
#: of the edge parameter s (+1: increasing s). A consistently oriented surface traverses a
#: shared edge in opposite directions from its two sides.
EDGE_SENSE = np.array([-1, 1, 1, -1], np.int64)
#: Patch corners k = 0..3 as (edge along u side, edge along v side): (u_min|u_max, v_min|v_max).
CORNER_UV = ((0, 0), (1, 0), (0, 1), (1, 1))

POLE = -2
OPEN = -1


# ---------------------------------------------------------------------- edge parameters
def edge_uv(dom, e: int, s):
    """(u, v) of the point with edge parameter s (scalar or array) on edge e of a patch with
    parameter rectangle ``dom = (u_min, u_max, v_min, v_max)``."""
    u0, u1, v0, v1 = dom
    s = np.asarray(s, dtype=float)
    if e == 0:
        return np.full_like(s, u0), v0 + s * (v1 - v0)
    if e == 1:
        return np.full_like(s, u1), v0 + s * (v1 - v0)
    if e == 2:
        return u0 + s * (u1 - u0), np.full_like(s, v0)
    if e == 3:
        return u0 + s * (u1 - u0), np.full_like(s, v1)
    raise ValueError(f"edge index must be 0..3, got {e}")


@njit(cache=True)
def edge_uv_nb(dom, ip, e, s):
    """Compiled :func:`edge_uv` for patch ``ip`` of a pool's ``dom`` array: returns (u, v)."""
    u0 = dom[ip, 0]
    u1 = dom[ip, 1]
    v0 = dom[ip, 2]
    v1 = dom[ip, 3]
    if e == 0:
        return u0, v0 + s * (v1 - v0)
    if e == 1:
        return u1, v0 + s * (v1 - v0)
    if e == 2:
        return u0 + s * (u1 - u0), v0
    return u0 + s * (u1 - u0), v1


@njit(cache=True)
def map_to_neighbour_nb(nbr, dom, i, e, s):
    """Compiled :meth:`Connectivity.map_to_neighbour` over the packed arrays
    ``nbr`` (P, 4, 3) int64 and ``dom`` (P, 4): returns (j, u, v).

    For a pole (j = -2) or an open edge (j = -1) (u, v) are the parameters of the point on
    patch i itself."""
    j = nbr[i, e, 0]
    if j < 0:
        u, v = edge_uv_nb(dom, i, e, s)
        return j, u, v
    f = nbr[i, e, 1]
    t = 1.0 - s if nbr[i, e, 2] == 1 else s
    u, v = edge_uv_nb(dom, j, f, t)
    return j, u, v


# ---------------------------------------------------------------------- data
@dataclass
class Corner:
    """A node where three or more patches meet.

    position: the point (m, file frame).
    members: the (patch, u, v) at that node, one per patch corner that lies there (a patch
        with a collapsed edge may appear twice with different parameters).
    """

    position: np.ndarray
    members: list[tuple[int, float, float]]

    @property
    def patches(self) -> list[int]:
        """Distinct patches meeting at the node, in order of appearance."""
        return list(dict.fromkeys(m[0] for m in self.members))


@dataclass
class Connectivity:
    """Edge neighbours and corner nodes of a multi-patch surface (module docstring).

    Attributes
    ----------
    neighbours: int64 (P, 4, 3), ``(j, f, rev)`` per patch edge; already a packed array for
        compiled code (:func:`map_to_neighbour_nb`).
    dom: float (P, 4) parameter rectangles (u_min, u_max, v_min, v_max).
    corners: list of :class:`Corner` (nodes with 3+ patches).
    corner_index: int64 (P, 4): for patch corner k (0: (u_min, v_min), 1: (u_max, v_min),
        2: (u_min, v_max), 3: (u_max, v_max)) the index of its node in ``corners``, or -1.
    corner_patch: int64 (C, K) the members' patches of each corner, padded with -1.
    corner_uv: float (C, K, 2) the members' parameters, padded with NaN.
    corner_pos: float (C, 3) the corner positions.
    tol: the matching tolerance used (m).
    open_edges: (patch, edge) pairs that match no other edge.
    overlaps: (patch, edge, [(j, f, rev), ...]) for edges that match two or more edges.
    mismatched: (patch, edge, j, f, distance) for edges whose end points match another edge
        but whose interior points at equal s do not (different parametrisations).
    """

    neighbours: np.ndarray
    dom: np.ndarray
    corners: list[Corner] = field(default_factory=list)
    corner_index: np.ndarray | None = None
    tol: float = 0.0
    open_edges: list[tuple[int, int]] = field(default_factory=list)
    overlaps: list[tuple[int, int, list[tuple[int, int, int]]]] = field(default_factory=list)
    mismatched: list[tuple[int, int, int, int, float]] = field(default_factory=list)

    def __post_init__(self) -> None:
        self.neighbours = np.ascontiguousarray(self.neighbours, dtype=np.int64)
        self.dom = np.ascontiguousarray(self.dom, dtype=float)
        P = self.neighbours.shape[0]
        if self.corner_index is None:
            self.corner_index = np.full((P, 4), -1, np.int64)
        K = max((len(c.members) for c in self.corners), default=0)
        C = len(self.corners)
        self.corner_patch = np.full((C, K), -1, np.int64)
        self.corner_uv = np.full((C, K, 2), np.nan)
        self.corner_pos = np.zeros((C, 3))
        for c, cn in enumerate(self.corners):
            self.corner_pos[c] = cn.position
            for k, (ip, u, v) in enumerate(cn.members):
                self.corner_patch[c, k] = ip
                self.corner_uv[c, k] = u, v

    @property
    def nbr(self) -> np.ndarray:
        """Alias of :attr:`neighbours` (int64 (P, 4, 3)) for compiled code."""
        return self.neighbours

    @property
    def arrays(self) -> tuple[np.ndarray, np.ndarray]:
        """(neighbours, dom): the arguments of :func:`map_to_neighbour_nb`."""
        return self.neighbours, self.dom

    @property
    def closed(self) -> bool:
        """True when every edge has a neighbour or is a pole, and no edge is ambiguous."""
        return (not self.open_edges and not self.overlaps
                and not np.any(self.neighbours[:, :, 0] == OPEN))

    def map_to_neighbour(self, i: int, e: int, s: float) -> tuple[int, float, float]:
        """The neighbour across edge e of patch i and its parameters (u, v) of the point with
        edge parameter s. For a pole (j = -2) or an open edge (j = -1), (u, v) are the
        parameters of the point on patch i itself."""
        j, u, v = map_to_neighbour_nb(self.neighbours, self.dom, int(i), int(e), float(s))
        return int(j), float(u), float(v)

    def __repr__(self) -> str:
        P = self.neighbours.shape[0]
        npole = int(np.sum(self.neighbours[:, :, 0] == POLE))
        return (f"Connectivity(patches={P}, poles={npole}, corners={len(self.corners)}, "
                f"open={len(self.open_edges)}, tol={self.tol:.3g} m)")


# ---------------------------------------------------------------------- detection
def _size(patches: Sequence[Patch]) -> float:
    pts = np.concatenate([p.control_points.reshape(-1, 3) for p in patches])
    return float(np.linalg.norm(pts.max(0) - pts.min(0)))


def _edge_samples(patches: Sequence[Patch], n: int) -> np.ndarray:
    """Points of every edge at n equally spaced edge parameters: array (P, 4, n, 3)."""
    s = np.linspace(0.0, 1.0, n)
    out = np.empty((len(patches), 4, n, 3))
    for i, p in enumerate(patches):
        dom = p.domain
        for e in range(4):
            u, v = edge_uv(dom, e, s)
            out[i, e] = p.points(u, v)
    return out


def find_connectivity(patches: Sequence[Patch], source: str | None = None,
                      rel_tol: float = 1e-6, n_samples: int = 7) -> Connectivity:
    """Find each patch edge's neighbour edge, poles and 3+-patch corner nodes.

    Parameters
    ----------
    patches: validated patches.
    source: file name (kept for messages; this function never raises for bad topology —
        :func:`check_shape` does).
    rel_tol: matching tolerance relative to the diagonal of the control points' bounding box.
    n_samples: points per edge compared.

    Returns
    -------
    :class:`Connectivity`; unmatched edges get j = -1 and are listed in ``open_edges``,
    edges matching several others keep the first match and are listed in ``overlaps``.
    """
    P = len(patches)
    size = _size(patches) if P else 0.0
    tol = rel_tol * size
    dom = np.array([p.domain for p in patches], dtype=float).reshape(P, 4)
    nbr = np.full((P, 4, 3), -1, np.int64)
    conn_kw: dict = {}
    if P == 0:
        return Connectivity(nbr, dom, tol=tol)
    S = _edge_samples(patches, n_samples)                      # (P, 4, n, 3)
    E = S.reshape(P * 4, n_samples, 3)
    # collapsed edges: all samples at one point
    spread = np.linalg.norm(E - E[:, :1], axis=-1).max(-1)    # (4P,)
    pole = spread <= tol
    # pairwise max distance at equal s, forward and reversed
    fwd = np.zeros((4 * P, 4 * P))
    rev = np.zeros((4 * P, 4 * P))
    for k in range(n_samples):
        a = E[:, k]
        fwd = np.maximum(fwd, np.linalg.norm(a[:, None] - E[None, :, k], axis=-1))
        rev = np.maximum(rev, np.linalg.norm(a[:, None] - E[None, :, n_samples - 1 - k], axis=-1))
    idx = np.arange(4 * P)
    for m in (fwd, rev):
        m[idx, idx] = np.inf
        m[pole, :] = np.inf
        m[:, pole] = np.inf
    open_edges, overlaps, mismatched = [], [], []
    for a in range(4 * P):
        i, e = divmod(a, 4)
        if pole[a]:
            nbr[i, e] = (POLE, -1, -1)
            continue
        matches = [(b, 0) for b in np.flatnonzero(fwd[a] <= tol)] + \
                  [(b, 1) for b in np.flatnonzero(rev[a] <= tol)]
        # an edge may match the same edge both ways only if it is degenerate (handled above)
        if not matches:
            open_edges.append((i, e))
            # end points coincide but interior points do not: a parametrisation mismatch
            ends_f = np.maximum(np.linalg.norm(E[a, 0] - E[:, 0], axis=-1),
                                np.linalg.norm(E[a, -1] - E[:, -1], axis=-1))
            ends_r = np.maximum(np.linalg.norm(E[a, 0] - E[:, -1], axis=-1),
                                np.linalg.norm(E[a, -1] - E[:, 0], axis=-1))
            for b in np.flatnonzero((np.minimum(ends_f, ends_r) <= tol) & ~pole & (idx != a)):
                d = fwd[a, b] if ends_f[b] <= tol else rev[a, b]
                mismatched.append((i, e, int(b // 4), int(b % 4), float(d)))
            continue
        b, r = matches[0]
        nbr[i, e] = (b // 4, b % 4, r)
        if len(matches) > 1:
            overlaps.append((i, e, [(int(b // 4), int(b % 4), int(r)) for b, r in matches]))
    corners, corner_index = _find_corners(patches, dom, tol)
    conn_kw.update(corners=corners, corner_index=corner_index, tol=tol, open_edges=open_edges,
                   overlaps=overlaps, mismatched=mismatched)
    return Connectivity(nbr, dom, **conn_kw)


def _find_corners(patches: Sequence[Patch], dom: np.ndarray, tol: float):
    """Cluster the patch corners by position; keep the nodes shared by 3+ distinct patches."""
    P = len(patches)
    members = []   # (patch, k, u, v)
    pts = []
    for i, p in enumerate(patches):
        u0, u1, v0, v1 = dom[i]
        for k, (a, b) in enumerate(CORNER_UV):
            u = (u0, u1)[a]
            v = (v0, v1)[b]
            members.append((i, k, float(u), float(v)))
            pts.append(p.points(np.array([u]), np.array([v]))[0])
    pts = np.array(pts)
    D = np.linalg.norm(pts[:, None] - pts[None], axis=-1)
    label = np.full(len(pts), -1)
    nl = 0
    for a in range(len(pts)):
        if label[a] >= 0:
            continue
        # grow the cluster transitively
        stack = [a]
        label[a] = nl
        while stack:
            c = stack.pop()
            for b in np.flatnonzero((D[c] <= tol) & (label < 0)):
                label[b] = nl
                stack.append(b)
        nl += 1
    corners: list[Corner] = []
    corner_index = np.full((P, 4), -1, np.int64)
    for lab in range(nl):
        sel = np.flatnonzero(label == lab)
        if len({members[s][0] for s in sel}) < 3:
            continue
        for s in sel:
            corner_index[members[s][0], members[s][1]] = len(corners)
        corners.append(Corner(pts[sel].mean(0), [(members[s][0], members[s][2], members[s][3])
                                                 for s in sel]))
    return corners, corner_index


# ---------------------------------------------------------------------- checks
def _where(i: int, e: int | None = None) -> str:
    w = f"patch {i}"
    if e is not None:
        w += f", edge {e} ({EDGE_NAMES[e]})"
    return w


def _sample_params(knots: np.ndarray, degree: int, n: int = 9) -> np.ndarray:
    """n equally spaced parameters over the domain plus the interior knots."""
    lo, hi = knots[degree], knots[-degree - 1]
    t = np.concatenate([np.linspace(lo, hi, n), knots[(knots > lo) & (knots < hi)]])
    return np.unique(t)


def _fmt(x: float) -> str:
    return f"{x:.6g}"


def check_topology(conn: Connectivity, source: str | None = None) -> None:
    """Raise :class:`GeometryError` for an open, overlapping or inconsistently oriented
    patch structure (see :func:`check_shape`)."""
    for i, e in conn.open_edges:
        mism = [m for m in conn.mismatched if m[0] == i and m[1] == e]
        if mism:
            _, _, j, f, d = mism[0]
            raise GeometryError(
                f"edge has the end points of patch {j} edge {f} ({EDGE_NAMES[f]}) but the two "
                f"parametrisations differ (points at equal edge parameter are {d:.3g} m apart); "
                f"shared edges must have the same control points and weights", path=source,
                where=_where(i, e))
        raise GeometryError("the surface is not closed: this edge coincides with no other patch "
                            f"edge (gap, or a T-junction, which is not supported; tolerance "
                            f"{conn.tol:.3g} m)", path=source, where=_where(i, e))
    for i, e, ms in conn.overlaps:
        lst = ", ".join(f"patch {j} edge {f} ({EDGE_NAMES[f]})" for j, f, _ in ms)
        raise GeometryError(f"overlapping or non-manifold surface: this edge coincides with "
                            f"{len(ms)} edges ({lst})", path=source, where=_where(i, e))
    nbr = conn.neighbours
    P = nbr.shape[0]
    for i in range(P):
        for e in range(4):
            j, f, r = nbr[i, e]
            if j < 0:
                continue
            sign = EDGE_SENSE[e] * EDGE_SENSE[f] * (-1 if r else 1)
            if sign > 0:
                raise GeometryError(
                    f"inconsistent orientation: the shared edge with patch {j} edge {f} "
                    f"({EDGE_NAMES[f]}) runs the same way on both sides, so the normals "
                    f"S_u x S_v of patches {i} and {j} point to opposite sides (swap u and v "
                    f"of one of them)", path=source, where=_where(i, e))


def check_shape(shape, source: str | None = None, rel_tol: float = 1e-9) -> None:
    """Reject a shape that is not a closed, outward-oriented, convex surface.

    Checks, in order (the first failure raises :class:`~nurbsdem.errors.GeometryError`
    naming the file, patch and edge or parameters):

    1. closed: every edge coincides with exactly one other edge (or is a pole);
    2. consistently oriented: every shared edge is traversed in opposite directions from
       its two sides;
    3. outward: on every patch the normals S_u x S_v point away from the interior (the mean
       of the sampled surface points), and the volume is positive;
    4. convex: on a grid of at least 9 x 9 parameters per patch (plus the knots), every
       sampled surface point lies on the inner side of every sampled tangent plane, up to
       ``rel_tol`` x size, and no sampled normal curvature is concave.

    Parameters
    ----------
    shape: a :class:`~nurbsdem.geometry.shape.Shape` (uses ``patches``, ``connectivity``,
        ``volume``).
    source: file name for messages (default ``shape.source``).
    rel_tol: tolerance of the tangent-plane test relative to the size of the body.
    """
    if source is None:
        source = getattr(shape, "source", None)
    patches = shape.patches
    conn = getattr(shape, "connectivity", None)
    if conn is None:
        conn = find_connectivity(patches, source)
    check_topology(conn, source)
    size = _size(patches)
    tol = rel_tol * size

    # ---- samples: points, unit normals, curvature
    X, N, ok, owner, UV, kmax = [], [], [], [], [], []
    for i, p in enumerate(patches):
        tu = _sample_params(p.knots_u, p.degree_u)
        tv = _sample_params(p.knots_v, p.degree_v)
        U, V = np.meshgrid(tu, tv, indexing="ij")
        d = p.evaluate(U.ravel(), V.ravel(), 2)
        Su, Sv = d[:, 1], d[:, 2]
        n = np.cross(Su, Sv)
        nn = np.linalg.norm(n, axis=-1)
        scale = np.linalg.norm(Su, axis=-1) * np.linalg.norm(Sv, axis=-1)
        good = nn > 1e-8 * np.maximum(scale, 1e-300)
        good &= scale > 0
        # a pole (edge collapsed to a point): a derivative vanishes up to round-off and the
        # cross product has no meaningful direction there
        nsu = np.linalg.norm(Su, axis=-1)
        nsv = np.linalg.norm(Sv, axis=-1)
        good &= (nsu > 1e-7 * nsu.max()) & (nsv > 1e-7 * nsv.max())
        nu = n / np.where(good, nn, 1.0)[:, None]
        # shape operator eigenvalues (principal curvatures, n outward: convex => <= 0)
        E_ = np.einsum("ij,ij->i", Su, Su)
        F_ = np.einsum("ij,ij->i", Su, Sv)
        G_ = np.einsum("ij,ij->i", Sv, Sv)
        L_ = np.einsum("ij,ij->i", d[:, 3], nu)
        M_ = np.einsum("ij,ij->i", d[:, 4], nu)
        N_ = np.einsum("ij,ij->i", d[:, 5], nu)
        det1 = np.where(good, E_ * G_ - F_ ** 2, 1.0)
        H = (E_ * N_ - 2 * F_ * M_ + G_ * L_) / (2 * det1)
        K = (L_ * N_ - M_ ** 2) / det1
        k1 = H + np.sqrt(np.maximum(H * H - K, 0.0))
        X.append(d[:, 0])
        N.append(nu)
        ok.append(good)
        owner.append(np.full(len(U.ravel()), i))
        UV.append(np.stack([U.ravel(), V.ravel()], -1))
        kmax.append(np.where(good, k1, -np.inf))
    X = np.concatenate(X)
    N = np.concatenate(N)
    ok = np.concatenate(ok)
    owner = np.concatenate(owner)
    UV = np.concatenate(UV)
    kmax = np.concatenate(kmax)

    # ---- outward orientation per patch
    c = X.mean(0)
    out = np.einsum("ij,ij->i", N, X - c)
    for i in range(len(patches)):
        sel = (owner == i) & ok
        if np.any(sel) and np.mean(np.sign(out[sel])) < 0:
            raise GeometryError("normals S_u x S_v point into the body; they must point "
                                "outward (swap u and v, or reverse one parameter direction)",
                                path=source, where=f"patch {i}")
    vol = getattr(shape, "volume", None)
    if vol is not None and not vol > 0:
        raise GeometryError(f"the enclosed volume {vol:.6g} m^3 is not positive: the "
                            "normals point inward or the surface is degenerate", path=source)

    # ---- convexity: tangent planes (rows) against all points (columns)
    rows = np.flatnonzero(ok)
    for start in range(0, len(rows), 512):
        r = rows[start:start + 512]
        D = np.einsum("rk,rmk->rm", N[r], X[None, :, :] - X[r][:, None, :])
        worst = D.max(1)
        bad = np.flatnonzero(worst > tol)
        if bad.size:
            a = r[bad[np.argmax(worst[bad])]]
            b = int(np.argmax(D[np.flatnonzero(r == a)[0]]))
            raise GeometryError(
                f"not convex: the point of patch {owner[b]} at (u, v) = "
                f"({_fmt(UV[b, 0])}, {_fmt(UV[b, 1])}) lies {worst.max():.3g} m outside the "
                f"tangent plane at (u, v) = ({_fmt(UV[a, 0])}, {_fmt(UV[a, 1])})",
                path=source, where=f"patch {owner[a]}")
    concave = np.flatnonzero(kmax * size > 1e-6)
    if concave.size:
        a = concave[np.argmax(kmax[concave])]
        raise GeometryError(
            f"not convex: the surface curves outward (normal curvature {kmax[a]:.3g} 1/m > 0 "
            f"with the outward normal) at (u, v) = ({_fmt(UV[a, 0])}, {_fmt(UV[a, 1])})",
            path=source, where=f"patch {owner[a]}")

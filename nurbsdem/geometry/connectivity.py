"""Patch connectivity of a closed multi-patch NURBS surface, and the shape checks.

Connectivity (paper Sec. 3.2.2: "connectivity stored per particle, 4 neighbours per
rectangular patch") is found automatically from the geometry: every edge of every patch is
sampled at a few points and compared with every other edge, forward and reversed, within a
tolerance relative to the particle size. Conventions (see ``docs/conventions.md``):

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
not convex within a tolerance, with a :class:`~nurbsdem.errors.GeometryError` naming the file,
the patch and the edge or parameters where the check fails. Non-convexity is measured as a
length (:func:`measure_convexity`: the largest height of the surface above one of its own
tangent planes) relative to the particle size; a shape below the tolerance
(:data:`DEFAULT_CONVEXITY_TOL`, or the caller's) is accepted, and :func:`convexity_warning`
gives the one-line warning that says where and how much. Lengths in metres.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Sequence

import numpy as np


from ..errors import GeometryError
from ..jit import kernel
from .nurbs import Patch
from .support import Support, max_height

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


@kernel
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


@kernel
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


#: Default convexity tolerance: the largest non-convexity accepted, relative to the
#: particle size (see :func:`measure_convexity`). 1e-4 of a 5 cm particle is 5 µm, well below
#: the penetrations of a DEM contact; 0 refuses every measurable non-convexity.
DEFAULT_CONVEXITY_TOL = 1e-4
#: Heights above a tangent plane below this fraction of the size are round-off.
ROUNDOFF_REL = 1e-9
#: Outward normal curvature below this / size (1/m) is round-off.
CURVATURE_REL = 1e-6


@dataclass
class Convexity:
    """How far a closed surface is from convex (:func:`measure_convexity`).

    Attributes
    ----------
    height: m, the largest height of a surface point above the tangent plane at another
        surface point (sampled, then refined to the local maximum) — 0 for a convex surface;
        for a dent about its depth below the convex hull; the largest error in a support
        point that stops at a local optimum.
    size: m, the particle size (diagonal of the control points' bounding box).
    plane: (patch, u, v) of the tangent plane's point.
    above: (patch, u, v) of the point highest above it.
    curvature: 1/m, the largest sampled normal curvature that bends outward (> 0 is a saddle
        or dent; convex surfaces have <= 0); ``-inf`` when none is sampled.
    curvature_at: (patch, u, v) where it is largest.
    """

    height: float
    size: float
    plane: tuple[int, float, float]
    above: tuple[int, float, float]
    curvature: float
    curvature_at: tuple[int, float, float]

    @property
    def relative(self) -> float:
        """Non-convexity relative to the size (dimensionless): height / size."""
        return self.height / self.size if self.size > 0 else 0.0

    @property
    def convex(self) -> bool:
        """True if convex up to round-off (no measurable height, no outward curvature)."""
        return (self.height <= ROUNDOFF_REL * self.size
                and not self.curvature * self.size > CURVATURE_REL)

    def describe(self) -> str:
        """One-line description: how much and where (without the patch prefix)."""
        if self.convex:
            return "convex (non-convexity 0 within round-off)"
        ip, u, v = self.plane
        jp, uj, vj = self.above
        kp, uk, vk = self.curvature_at
        text = (f"the surface rises {self.height:.3g} m ({self.relative:.3g} of the particle "
                f"size {self.size:.3g} m) above its tangent plane at (u, v) = ({_fmt(u)}, "
                f"{_fmt(v)}) (highest point: patch {jp} at (u, v) = ({_fmt(uj)}, {_fmt(vj)}))")
        if self.curvature * self.size > CURVATURE_REL:
            text += (f"; largest outward normal curvature {self.curvature:.3g} 1/m at patch "
                     f"{kp}, (u, v) = ({_fmt(uk)}, {_fmt(vk)})")
        return text

    @property
    def where(self) -> str:
        """The patch that the description refers to ("patch i")."""
        if self.height > ROUNDOFF_REL * self.size or not np.isfinite(self.curvature):
            return f"patch {self.plane[0]}"
        return f"patch {self.curvature_at[0]}"


def _patch_samples(p: Patch, tu: np.ndarray, tv: np.ndarray, order: int):
    """Points, unit normals, max principal curvature (outward normal: convex <= 0), a mask
    of usable normals and the parameters, at the grid tu x tv of one patch."""
    U, V = np.meshgrid(tu, tv, indexing="ij")
    d = p.evaluate(U.ravel(), V.ravel(), order)
    Su, Sv = d[:, 1], d[:, 2]
    n = np.cross(Su, Sv)
    nn = np.linalg.norm(n, axis=-1)
    nsu = np.linalg.norm(Su, axis=-1)
    nsv = np.linalg.norm(Sv, axis=-1)
    scale = nsu * nsv
    good = (scale > 0) & (nn > 1e-8 * np.maximum(scale, 1e-300))
    # a pole (edge collapsed to a point): a derivative vanishes up to round-off and the
    # cross product has no meaningful direction there
    good &= (nsu > 1e-7 * nsu.max()) & (nsv > 1e-7 * nsv.max())
    nu = n / np.where(good, nn, 1.0)[:, None]
    k1 = np.full(len(nu), -np.inf)
    if order >= 2:
        E_ = np.einsum("ij,ij->i", Su, Su)
        F_ = np.einsum("ij,ij->i", Su, Sv)
        G_ = np.einsum("ij,ij->i", Sv, Sv)
        L_ = np.einsum("ij,ij->i", d[:, 3], nu)
        M_ = np.einsum("ij,ij->i", d[:, 4], nu)
        N_ = np.einsum("ij,ij->i", d[:, 5], nu)
        det1 = np.where(good, E_ * G_ - F_ ** 2, 1.0)
        H = (E_ * N_ - 2 * F_ * M_ + G_ * L_) / (2 * det1)
        K = (L_ * N_ - M_ ** 2) / det1
        k1 = np.where(good, H + np.sqrt(np.maximum(H * H - K, 0.0)), -np.inf)
    return d[:, 0], nu, k1, good, np.stack([U.ravel(), V.ravel()], -1)


def measure_convexity(patches: Sequence[Patch], n_coarse: int = 9, n_fine: int = 17,
                      n_seeds: int = 16, n_local: int = 15, n_refine: int = 4) -> Convexity:
    """Measure how far a closed surface is from convex, as a length (:class:`Convexity`).

    1. Coarse: on n_coarse parameters per direction and patch (plus the knots) every point is
       tested against every tangent plane: height = max_ab n_a . (x_b - x_a) (m), found on
       the samples' convex hull (:mod:`nurbsdem.geometry.support`, N log N, the all-pairs
       maximum to round-off).
    2. Fine: the largest principal curvature with the outward normal on n_fine parameters
       (plus the knots); > 0 marks a saddle or dent.
    3. Local: around the n_seeds worst outward-curved fine samples (at most one per patch
       and grid neighbourhood) an n_local x n_local grid spanning +-2 fine cells is tested
       against itself and the coarse points — the height of a small saddle at a patch corner
       (a region far smaller than the coarse grid) is found here.
    4. Refine (only when step 1–3 found a measurable height, > ``ROUNDOFF_REL`` x size): the
       sampled height underestimates the true one by the grid spacing (at the 0.9 mm saddle
       of a 5 cm projected cube, 1.10e-7 m sampled for 1.217e-7 m). From the n_refine best
       distinct sampled pairs (tangent-plane point a, point b above it) the height
       n(a) . (x(b) - x(a)) is maximised over the parameters of both points on their patches
       (:func:`_refine_height`, a pattern search down to 1e-9 of the domain: the height to
       round-off, ~1e-16 m, of the local maximum it converges to). Convex shapes skip it,
       so their figure stays 0 up to round-off.
    The height is zero for a convex surface (up to round-off), and the error a support
    mapping makes when it stops at a local optimum (the supporting direction being a patch
    normal; at a crease, directions between the two patches' normals can give a few per cent
    more).
    """
    size = _size(patches)
    Xc, Nc, OWc, UVc = [], [], [], []
    Kf, OWf, UVf = [], [], []
    for i, p in enumerate(patches):
        tu = _sample_params(p.knots_u, p.degree_u, n_coarse)
        tv = _sample_params(p.knots_v, p.degree_v, n_coarse)
        x, nu, _, good, uv = _patch_samples(p, tu, tv, 1)
        Xc.append(x)
        Nc.append(np.where(good[:, None], nu, 0.0))
        OWc.append(np.full(len(x), i))
        UVc.append(uv)
        tu = _sample_params(p.knots_u, p.degree_u, n_fine)
        tv = _sample_params(p.knots_v, p.degree_v, n_fine)
        _, _, k1, _, uv = _patch_samples(p, tu, tv, 2)
        Kf.append(k1)
        OWf.append(np.full(len(k1), i))
        UVf.append(uv)
    Xc, Nc, OWc, UVc = map(np.concatenate, (Xc, Nc, OWc, UVc))
    Kf, OWf, UVf = map(np.concatenate, (Kf, OWf, UVf))
    support = Support(Xc)
    h, a, b = max_height(Xc, Nc, support)
    plane = (int(OWc[a]), float(UVc[a, 0]), float(UVc[a, 1]))
    above = (int(OWc[b]), float(UVc[b, 0]), float(UVc[b, 1]))
    kk = int(np.argmax(Kf))
    curv = float(Kf[kk])
    curv_at = (int(OWf[kk]), float(UVf[kk, 0]), float(UVf[kk, 1]))
    # candidate pairs for the refinement: (height, (patch, u, v) of a, (patch, u, v) of b)
    cands = [(h, plane, above)]
    for ip, u0, v0 in _seeds(patches, Kf, OWf, UVf, size, n_fine, n_seeds):
        p = patches[ip]
        du0, du1, dv0, dv1 = p.domain
        hu = 2.0 * (du1 - du0) / (n_fine - 1)
        hv = 2.0 * (dv1 - dv0) / (n_fine - 1)
        tu = np.linspace(max(du0, u0 - hu), min(du1, u0 + hu), n_local)
        tv = np.linspace(max(dv0, v0 - hv), min(dv1, v0 + hv), n_local)
        x, nu, _, good, uv = _patch_samples(p, tu, tv, 1)
        xa, na, uva = x[good], nu[good], uv[good]
        if not len(xa):
            continue
        hl, a, b = max_height(xa, na, support, extra=x)
        pl = (ip, float(uva[a, 0]), float(uva[a, 1]))
        ab = (ip, float(uv[b, 0]), float(uv[b, 1])) if b < len(x) else \
            (int(OWc[b - len(x)]), float(UVc[b - len(x), 0]), float(UVc[b - len(x), 1]))
        cands.append((hl, pl, ab))
        if hl > h:
            h, plane, above = hl, pl, ab
    if h > ROUNDOFF_REL * size:
        cands.sort(key=lambda c: -c[0])
        done: list[tuple] = []
        for hc, pl, ab in cands:
            if len(done) >= n_refine:
                break
            if hc <= ROUNDOFF_REL * size or (pl, ab) in done:
                continue
            done.append((pl, ab))
            hr, pl, ab = _refine_height(patches, pl, ab, 2.0 / (n_fine - 1), size)
            if hr > h:
                h, plane, above = hr, pl, ab
    return Convexity(max(h, 0.0), size, plane, above, curv, curv_at)


def _refine_height(patches: Sequence[Patch], plane: tuple[int, float, float],
                   above: tuple[int, float, float], width: float, size: float, m: int = 5,
                   rel_stop: float = 1e-9, max_it: int = 400):
    """Local maximum of the height n(a) . (x(b) - x(a)) over the parameters of a (on patch
    plane[0]) and b (on patch above[0]), from the sampled pair: a pattern search on m x m
    grids around a and around b (all m^4 pairs) of half-width ``width`` x the domain, moving
    to the best pair, halving the width when the best pair is the current one, down to
    ``rel_stop`` x the domain. Normals where a derivative vanishes up to round-off (a pole,
    as in :func:`_patch_samples`) are not used. Returns (height, plane, above) with their
    parameters."""
    pa, pb = patches[plane[0]], patches[above[0]]
    da, db = np.array(pa.domain, float), np.array(pb.domain, float)
    ca = np.array(plane[1:], float)
    cb = np.array(above[1:], float)
    wa = width * np.array([da[1] - da[0], da[3] - da[2]])
    wb = width * np.array([db[1] - db[0], db[3] - db[2]])
    s = np.linspace(-1.0, 1.0, m)
    k0 = (m * m) // 2                       # the grid's centre: the current point

    def grid(c, w, dom):
        u = np.clip(c[0] + w[0] * s, dom[0], dom[1])
        v = np.clip(c[1] + w[1] * s, dom[2], dom[3])
        U, V = np.meshgrid(u, v, indexing="ij")
        return U.ravel(), V.ravel()

    best = -np.inf
    for _ in range(max_it):
        ua, va = grid(ca, wa, da)
        ub, vb = grid(cb, wb, db)
        ea = pa.evaluate(ua, va, 1)
        n = np.cross(ea[:, 1], ea[:, 2])
        nn = np.linalg.norm(n, axis=-1)
        nsu = np.linalg.norm(ea[:, 1], axis=-1)
        nsv = np.linalg.norm(ea[:, 2], axis=-1)
        ok = ((nn > 1e-8 * nsu * nsv) & (nsu * (da[1] - da[0]) > 1e-7 * size)
              & (nsv * (da[3] - da[2]) > 1e-7 * size))
        n = np.where(ok[:, None], n / np.where(ok, nn, 1.0)[:, None], 0.0)
        xb = pb.evaluate(ub, vb, 0)
        xb = xb[:, 0] if xb.ndim == 3 else xb
        D = np.einsum("ak,abk->ab", n, xb[None, :, :] - ea[:, None, 0])
        D[~ok] = -np.inf
        i, j = np.unravel_index(int(np.argmax(D)), D.shape)
        if not D[i, j] > best or (i == k0 and j == k0):
            # no better pair (the centre holds the best): shrink around it
            if D[k0, k0] > best:
                best = float(D[k0, k0])
            wa, wb = 0.5 * wa, 0.5 * wb
            if max(wa.max() / (da[1] - da[0] + da[3] - da[2]),
                   wb.max() / (db[1] - db[0] + db[3] - db[2])) < rel_stop:
                break
            continue
        best = float(D[i, j])
        ca = np.array([ua[i], va[i]])
        cb = np.array([ub[j], vb[j]])
    return best, (plane[0], float(ca[0]), float(ca[1])), (above[0], float(cb[0]), float(cb[1]))


def _seeds(patches, K, owner, UV, size: float, n_fine: int, n_seeds: int):
    """Parameters of the worst outward-curved samples, at least 2 fine cells apart."""
    cand = np.flatnonzero(K * size > CURVATURE_REL)
    cand = cand[np.argsort(-K[cand])]
    out: list[tuple[int, float, float]] = []
    for c in cand:
        ip = int(owner[c])
        du0, du1, dv0, dv1 = patches[ip].domain
        cu = 2.0 * (du1 - du0) / (n_fine - 1)
        cv = 2.0 * (dv1 - dv0) / (n_fine - 1)
        u, v = float(UV[c, 0]), float(UV[c, 1])
        if any(q == ip and abs(u - a) < cu and abs(v - b) < cv for q, a, b in out):
            continue
        out.append((ip, u, v))
        if len(out) >= n_seeds:
            break
    return out


def checked_convexity_tol(tol, source: str | None = None) -> float:
    """The convexity tolerance (None: :data:`DEFAULT_CONVEXITY_TOL`) held to the deck's
    ``ConvexityTolerance`` range (:data:`nurbsdem.ranges.RANGES`); a NaN, an infinity or a
    value out of range is a :class:`GeometryError` (a tolerance of 1e300 would accept any
    dent)."""
    if tol is None:
        return DEFAULT_CONVEXITY_TOL
    from ..ranges import RANGES
    rng = RANGES["ConvexityTolerance"]
    try:
        x = float(tol)
    except (TypeError, ValueError):
        raise GeometryError(f"the convexity tolerance must be a number, got {tol!r}",
                            path=source) from None
    if not (0.0 <= x <= rng.hi):
        raise GeometryError(f"convexity tolerance {tol!r} is out of range: it must be from 0 "
                            f"to {rng.hi:g} of the particle size ({rng.reason})", path=source)
    return x


def check_shape(shape, source: str | None = None, rel_tol: float = 1e-9,
                convexity_tol: float | None = None) -> Convexity:
    """Reject a shape that is not a closed, outward-oriented, convex surface.

    Checks, in order (the first failure raises :class:`~nurbsdem.errors.GeometryError`
    naming the file, patch and edge or parameters):

    1. closed: every edge coincides with exactly one other edge (or is a pole);
    2. consistently oriented: every shared edge is traversed in opposite directions from
       its two sides;
    3. outward: on every patch the normals S_u x S_v point away from the interior (the mean
       of the sampled surface points), and the volume is positive;
    4. convex within a tolerance: the non-convexity of :func:`measure_convexity` (the
       largest height of the surface above one of its own tangent planes, m) must not exceed
       ``convexity_tol`` x size. A shape with a smaller, but measurable, non-convexity (a
       small saddle at a patch corner, as CAD tools make them) is accepted; the returned
       :class:`Convexity` says where and how much (the caller warns).

    Parameters
    ----------
    shape: a :class:`~nurbsdem.geometry.shape.Shape` (uses ``patches``, ``connectivity``,
        ``volume``).
    source: file name for messages (default ``shape.source``).
    rel_tol: heights above a tangent plane up to ``rel_tol`` x size are round-off.
    convexity_tol: accepted non-convexity relative to the size (default
        :data:`DEFAULT_CONVEXITY_TOL`; 0 refuses any measurable non-convexity).

    Returns
    -------
    The :class:`Convexity` measurement.
    """
    if source is None:
        source = getattr(shape, "source", None)
    convexity_tol = checked_convexity_tol(convexity_tol, source)
    patches = shape.patches
    conn = getattr(shape, "connectivity", None)
    if conn is None:
        conn = find_connectivity(patches, source)
    check_topology(conn, source)

    # ---- outward orientation per patch
    X, N, ok, owner = [], [], [], []
    for i, p in enumerate(patches):
        tu = _sample_params(p.knots_u, p.degree_u)
        tv = _sample_params(p.knots_v, p.degree_v)
        x, nu, _, good, _ = _patch_samples(p, tu, tv, 1)
        X.append(x)
        N.append(nu)
        ok.append(good)
        owner.append(np.full(len(x), i))
    X, N, ok, owner = map(np.concatenate, (X, N, ok, owner))
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

    # ---- convexity, measured as a length
    cv = measure_convexity(patches)
    cv.size = _size(patches)
    if cv.height > max(rel_tol, convexity_tol) * cv.size or (
            convexity_tol <= 0 and not cv.convex):
        raise GeometryError(f"not convex: {cv.describe()}; the convexity tolerance is "
                            f"{convexity_tol:g} of the size (option --convexity-tol, deck "
                            f"keyword ConvexityTolerance)", path=source, where=cv.where)
    return cv


def convexity_warning(cv: Convexity, source: str | None = None,
                      convexity_tol: float | None = None) -> str | None:
    """The one-line warning for a shape accepted within the convexity tolerance, or None
    if it is convex up to round-off."""
    if cv.convex:
        return None
    tol = DEFAULT_CONVEXITY_TOL if convexity_tol is None else convexity_tol
    loc = f"{source}: " if source else ""
    return (f"{loc}{cv.where}: nearly convex, accepted: {cv.describe()}; below the convexity "
            f"tolerance {tol:g} of the size (the contact's degeneration handles it)")

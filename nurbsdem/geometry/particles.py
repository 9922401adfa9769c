"""The particles A, B and C of the paper's example (Section 4), as NURBS shapes.

The paper gives, for each particle, only: 6 bicubic patches of 6 × 6 control points, each
parameter in [0, 2], density 2700 kg/m^3, the volume and the inertia tensor about the
centroid (the paper's Table 1). The geometry itself is not
published, so this module *constructs* a convex body with exactly that structure and those
mass properties:

1. **Base body.** A star-shaped, strictly convex surface with the symmetry of the cube,
   radius function (unit direction d)

       r(d) = 1 + ε (d_x^4 + d_y^4 + d_z^4 - 3/5),

   a sphere perturbed by the lowest cubic harmonic; ε < 0 pushes the cube's corners out
   (a slightly "boxy" sphere). Unlike a superellipsoid with exponent > 2 it has no flat
   (zero-curvature) points, so the spline fit does not make it locally concave.
2. **Cube-sphere fit.** Six faces of the cube [-1, 1]^3, each parameter t in [0, 2] mapped to
   the cube coordinate tan(π/4 (t - 1)) (equi-angular), projected radially onto the base
   surface. The distinct control points of the six faces (8 corners, 4 per cube edge, 16 per
   face interior: 152 points) are fitted *together* by linear least squares to samples of
   the base surface, bicubic with knots [0,0,0,0,2/3,4/3,2,2,2,2] both ways, subject to
   linear smoothness constraints (C1 across the middle span of every edge, a common tangent
   plane at every corner; see :func:`_constraints`). Every control
   point is computed once, in one table, and the faces index into it, so patches that share
   an edge share bit-identical boundary control points and the edges coincide exactly.
   Face orientation: face with outward normal n uses cube tangents a (along u) and b (along
   v) with a × b = n, so S_u × S_v points outward.
3. **Affine map.** The second-moment matrix M2 = ∫ x xᵀ dV (m^5) of an affine image x -> L x
   is det(L) L M2_base Lᵀ, and the volume det(L) V_base. With B = M2_base^(1/2) and the
   target T = ½ tr(J) I - J (J the volume inertia, m^5), L = c T^(1/2) B^(-1) with
   c^5 = det(B) / det(T)^(1/2) reproduces M2 exactly. The affine invariant
   det(M2) / V^5 of the target fixes ε (tuned once by :func:`tune_epsilon`, stored in
   :data:`EPSILON`); then the volume comes out right as well. An affine image of a convex
   body is convex. Finally the body is translated so that its centroid is the file origin.
4. **B and C** are A scaled by 0.8 and 0.6 about the centroid (the paper's Table 1 values are
   consistent with that to its printed digits).

The result is a slightly irregular, roughly ellipsoidal, strictly convex body (principal
curvature radii below ~9 cm) about 5.7 × 4.7 × 5.8 cm across. The patches meet with exact
positional continuity (bit-identical shared control points), tangent-plane continuity on
the middle third of every edge and at the corners, and small convex kinks (at most ~3.4°
between the two patches' normals) on the end spans of the edges next to the corners: a
valence-3 corner admits no C1 bicubic joint of this simple kind. (An unconstrained fit has
kinks that are *concave* in places; the opposite sign of ε gives smaller kinks but nearly
flat spots.)
"""
from __future__ import annotations

from functools import lru_cache
from pathlib import Path

import numpy as np

from .nurbs import Patch, basis_functions_derivs

#: Density of the paper's particles, kg/m^3.
DENSITY = 2700.0
#: Volume of particle A (paper Table 1), m^3.
VOLUME_A = 98.57e-6
#: Mass inertia tensor of particle A about its centroid (paper Table 1), kg m^2.
INERTIA_A = np.array([[84.951, 0.945, -5.413],
                      [0.945, 101.026, 0.000873],
                      [-5.413, 0.000873, 83.349]]) * 1e-2 * 1e-4
#: Scale factors of the particles relative to A.
SCALES = {"A": 1.0, "B": 0.8, "C": 0.6}
#: The paper's Table 1 for every particle: (volume m^3, mass inertia kg m^2 about centroid).
TABLE1 = {
    "A": (98.57e-6, INERTIA_A),
    "B": (50.47e-6, np.array([[27.837, 0.310, -1.774], [0.310, 33.104, 0.000286],
                              [-1.774, 0.000286, 27.312]]) * 1e-6),
    "C": (21.29e-6, np.array([[6.606, 0.0735, -0.421], [0.0735, 7.856, 0.0000679],
                              [-0.421, 0.0000679, 6.481]]) * 1e-6),
}
#: Cubic-harmonic amplitude of the base body (dimensionless), tuned by :func:`tune_epsilon`
#: so that det(M2) / V^5 of the fitted NURBS equals that of particle A.
EPSILON = -0.18632821568495775

DEGREE = 3
N_CP = 6
KNOTS = np.array([0.0, 0.0, 0.0, 0.0, 2.0 / 3.0, 4.0 / 3.0, 2.0, 2.0, 2.0, 2.0])
#: Samples per face and direction of the least-squares fit.
N_FIT = 31

#: Faces: (outward normal n, tangent a along u, tangent b along v), a × b = n.
_FACES = (
    ((1, 0, 0), (0, 1, 0), (0, 0, 1)),
    ((-1, 0, 0), (0, 0, 1), (0, 1, 0)),
    ((0, 1, 0), (0, 0, 1), (1, 0, 0)),
    ((0, -1, 0), (1, 0, 0), (0, 0, 1)),
    ((0, 0, 1), (1, 0, 0), (0, 1, 0)),
    ((0, 0, -1), (0, 1, 0), (1, 0, 0)),
)


# ---------------------------------------------------------------------- topology
@lru_cache(maxsize=8)
def _control_point_table(n_cp: int = N_CP) -> tuple[np.ndarray, np.ndarray]:
    """Global ids of the control points of the six faces (n_cp x n_cp control points each;
    also used by :mod:`nurbsdem.geometry.fit` with other net sizes).

    Returns
    -------
    ids: int array (6, n_cp, n_cp): ids[f, i, j] is the global id of control point (i, j) of
        face f.
    keys: int array (N, 3): the cube-lattice position of each global point (coordinates in
        {-(n_cp-1), ..., -1, 1, ..., n_cp-1} in steps of 2, e.g. {-5, -3, -1, 1, 3, 5} for
        n_cp = 6; ±(n_cp-1) on the cube's surface planes).
    """
    lat = 2 * np.arange(n_cp) - (n_cp - 1)  # -5 .. 5
    index: dict[tuple[int, int, int], int] = {}
    ids = np.zeros((6, n_cp, n_cp), dtype=np.int64)
    for f, (n, a, b) in enumerate(_FACES):
        n, a, b = np.array(n), np.array(a), np.array(b)
        for i in range(n_cp):
            for j in range(n_cp):
                key = tuple(int(k) for k in (n_cp - 1) * n + lat[i] * a + lat[j] * b)
                ids[f, i, j] = index.setdefault(key, len(index))
    keys = np.array(sorted(index, key=index.get))
    return ids, keys


def _cube_coordinate(t: np.ndarray) -> np.ndarray:
    """Equi-angular map of a patch parameter t in [0, 2] to a cube coordinate in [-1, 1]."""
    return np.tan(0.25 * np.pi * (np.asarray(t, float) - 1.0))


def _base_surface(d: np.ndarray, epsilon: float) -> np.ndarray:
    """Points of the base body in the directions d (..., 3) (need not be unit)."""
    d = d / np.linalg.norm(d, axis=-1, keepdims=True)
    r = 1.0 + epsilon * ((d ** 4).sum(-1) - 0.6)
    return r[..., None] * d


# ---------------------------------------------------------------------- fitting
def _fit_matrix() -> tuple[np.ndarray, np.ndarray]:
    """Design matrix of the global fit and the sample directions on the cube.

    Returns (A (6 m, N), dirs (6 m, 3)) with m = N_FIT^2 samples per face.
    """
    ids, keys = _control_point_table()
    t = np.linspace(0.0, 2.0, N_FIT)
    spans, ders = basis_functions_derivs(KNOTS, DEGREE, t, 0)
    Nt = np.zeros((N_FIT, N_CP))
    for r in range(DEGREE + 1):
        Nt[np.arange(N_FIT), spans - DEGREE + r] = ders[:, 0, r]
    B2 = np.einsum("ui,vj->uvij", Nt, Nt).reshape(N_FIT * N_FIT, N_CP * N_CP)
    s = _cube_coordinate(t)
    A = np.zeros((6 * N_FIT * N_FIT, len(keys)))
    dirs = []
    for f, (n, a, b) in enumerate(_FACES):
        n, a, b = np.array(n, float), np.array(a, float), np.array(b, float)
        rows = slice(f * N_FIT * N_FIT, (f + 1) * N_FIT * N_FIT)
        np.add.at(A[rows], (slice(None), ids[f].ravel()), B2)
        cube = n + s[:, None, None] * a + s[None, :, None] * b
        dirs.append(cube.reshape(-1, 3))
    return A, np.concatenate(dirs)


@lru_cache(maxsize=1)
def _constraints() -> np.ndarray:
    """The smoothness constraints of the paper particles' fit: :func:`cube_sphere_constraints`
    for 6 x 6 control points with the cube diagonals as corner normals."""
    return cube_sphere_constraints(N_CP)


def cube_sphere_constraints(n_cp: int, corner_normals: dict | None = None) -> np.ndarray:
    """Linear constraints C x = 0 on the flattened control-point table x (3 N,) of
    :func:`_control_point_table` (n_cp).

    * Along every cube edge, at the 4 edge points that are not corners: the edge point is the
      midpoint of its two cross-boundary neighbours (one on each face). The cross-boundary
      derivatives of the two patches are then opposite wherever the corner points' basis
      functions vanish (the middle knot span of every edge): the surface is C1 there.
    * At every corner: the three edge points next to it lie in the plane through the corner
      normal to the cube diagonal (the base body's normal there, by symmetry), so the three
      patches share the tangent plane at the corner.

    What is left is a small convex tangent-plane kink on the end spans of each edge
    (a valence-3 corner does not admit C1 bicubic patches with constant ratio).
    ``corner_normals`` maps a corner's sign triple (sx, sy, sz), each ±1, to the unit normal
    of its tangent plane (default: the cube diagonal (sx, sy, sz) / √3).
    """
    ids, keys = _control_point_table(n_cp)
    index = {tuple(k): i for i, k in enumerate(keys.tolist())}
    m = n_cp - 1
    rows = []
    for i, k in enumerate(keys):
        on = np.flatnonzero(np.abs(k) == m)
        if len(on) == 2:  # edge point (not a corner)
            nb = []
            for ax in on:
                kk = k.copy()
                kk[ax] -= 2 * np.sign(k[ax])
                nb.append(index[tuple(kk.tolist())])
            for c in range(3):
                r = np.zeros(3 * len(keys))
                r[3 * i + c] = 2.0
                r[3 * nb[0] + c] -= 1.0
                r[3 * nb[1] + c] -= 1.0
                rows.append(r)
        elif len(on) == 3:  # corner
            normal = np.sign(k) / np.sqrt(3.0)
            if corner_normals is not None:
                normal = np.asarray(corner_normals[tuple(int(x) for x in np.sign(k))], float)
            for ax in range(3):
                kk = k.copy()
                kk[ax] -= 2 * np.sign(k[ax])
                j = index[tuple(kk.tolist())]
                r = np.zeros(3 * len(keys))
                r[3 * j: 3 * j + 3] = normal
                r[3 * i: 3 * i + 3] -= normal
                rows.append(r)
    return np.array(rows)


@lru_cache(maxsize=1)
def _fit_system() -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(Z, Zᵀ G Z, Aᵀ, sample directions): Z a basis of the constraints' null space, G the
    normal matrix of the least-squares fit over the flattened table."""
    from scipy.linalg import null_space

    A, dirs = _fit_matrix()
    Z = null_space(_constraints())
    G = np.kron(A.T @ A, np.eye(3))
    return Z, Z.T @ G @ Z, A.T, dirs


@lru_cache(maxsize=8)
def _base_points(epsilon: float) -> np.ndarray:
    """The control-point table (N, 3) of the base body (dimensionless, radius ~ 1).

    Least-squares fit of :func:`_base_surface` at N_FIT² samples per face, subject to the
    linear smoothness constraints of :func:`_constraints`.
    """
    Z, H, At, dirs = _fit_system()
    rhs = Z.T @ (At @ _base_surface(dirs, epsilon)).ravel()
    y = np.linalg.solve(H, rhs)
    out = (Z @ y).reshape(-1, 3)
    out.setflags(write=False)
    return out


def _patches_from_table(points: np.ndarray) -> list[Patch]:
    """Six bicubic patches indexing the control-point table (shared points stay identical)."""
    ids, _ = _control_point_table()
    return [Patch(DEGREE, DEGREE, KNOTS.copy(), KNOTS.copy(), points[ids[f]].copy())
            for f in range(6)]


def _affine(points: np.ndarray, L: np.ndarray, offset: np.ndarray | None = None) -> np.ndarray:
    """x -> L x + offset, elementwise (no BLAS, so equal inputs give bit-equal outputs)."""
    out = np.empty_like(points)
    for k in range(3):
        out[:, k] = L[k, 0] * points[:, 0] + L[k, 1] * points[:, 1] + L[k, 2] * points[:, 2]
        if offset is not None:
            out[:, k] += offset[k]
    return out


def _sym_sqrt(m: np.ndarray) -> np.ndarray:
    """Symmetric positive square root of a symmetric positive definite matrix."""
    w, q = np.linalg.eigh(0.5 * (m + m.T))
    return (q * np.sqrt(w)) @ q.T


def affine_invariant(volume: float, second_moment: np.ndarray) -> float:
    """det(M2) / V^5, invariant under x -> L x (dimensionless; 4.5595e-4 for ellipsoids)."""
    return float(np.linalg.det(second_moment) / volume ** 5)


def build_particle(epsilon: float = EPSILON, inertia: np.ndarray = INERTIA_A,
                   density: float = DENSITY, scale: float = 1.0) -> list[Patch]:
    """Six bicubic patches of a convex body with second moments matching a target.

    Parameters
    ----------
    epsilon: cubic-harmonic amplitude of the base body (dimensionless, about -0.3 .. 0.1).
    inertia: target mass inertia tensor about the centroid, kg m^2 (file frame); it fixes
        L, and the volume follows from ε (right when ε comes from :func:`tune_epsilon`).
    density: kg/m^3.
    scale: final uniform scale about the centroid (B = 0.8, C = 0.6).

    Returns
    -------
    Six outward-oriented patches with the centroid at the origin (m).
    """
    from .mass import mass_properties, second_moment_from_inertia

    base = _base_points(epsilon)
    _, cb, jb = mass_properties(_patches_from_table(base))
    base = base - cb
    m2b = second_moment_from_inertia(jb)
    t2 = second_moment_from_inertia(np.asarray(inertia, float) / density)
    Bh = _sym_sqrt(m2b)
    c = (np.linalg.det(Bh) / np.sqrt(np.linalg.det(t2))) ** 0.2
    L = c * _sym_sqrt(t2) @ np.linalg.inv(Bh)
    pts = _affine(base, L)
    _, cen, _ = mass_properties(_patches_from_table(pts))
    pts = _affine(pts, np.eye(3) * scale, -cen * scale)
    return _patches_from_table(pts)


def tune_epsilon(volume: float = VOLUME_A, inertia: np.ndarray = INERTIA_A,
                 density: float = DENSITY) -> float:
    """The ε whose fitted base body has the target's det(M2)/V^5 (root by Brent's method)."""
    from scipy.optimize import brentq

    from .mass import mass_properties, second_moment_from_inertia

    m2 = second_moment_from_inertia(np.asarray(inertia, float) / density)
    target = affine_invariant(volume, m2)

    def f(eps: float) -> float:
        v, _, j = mass_properties(_patches_from_table(_base_points(eps)))
        return affine_invariant(v, second_moment_from_inertia(j)) / target - 1.0

    return float(brentq(f, -0.3, -0.1, xtol=1e-15, rtol=1e-15))


# ---------------------------------------------------------------------- public API
def particle_name(kind: str) -> str:
    """File/display name of a paper particle ("A", "B" or "C")."""
    kind = str(kind).upper()
    if kind not in SCALES:
        raise ValueError(f"unknown paper particle {kind!r}; expected one of A, B, C")
    return kind


def paper_particle(kind: str = "A") -> list[Patch]:
    """The patches of the paper's particle A, B or C (file frame, metres, centroid at 0).

    Six bicubic patches, 6 × 6 control points each, parameters in [0, 2], outward normals,
    closed and convex. A has the paper's volume (98.57 cm^3) and, at 2700 kg/m^3, its inertia
    tensor about the centroid; B and C are A scaled by 0.8 and 0.6.
    """
    return build_particle(scale=SCALES[particle_name(kind)])


def paper_particle_shape(kind: str = "A"):
    """:class:`~nurbsdem.geometry.shape.Shape` of :func:`paper_particle` (named "A", "B", "C")."""
    from .shape import Shape
    return Shape(paper_particle(kind), name=particle_name(kind))


def write_paper_particles(directory: str | Path) -> list[Path]:
    """Write A.yaml, B.yaml and C.yaml into ``directory``; returns the paths written."""
    from ..io.shapefile import save_shape

    out = []
    for kind in SCALES:
        path = Path(directory) / f"{kind}.yaml"
        save_shape(path, paper_particle(kind), name=particle_name(kind))
        out.append(path)
    return out


if __name__ == "__main__":  # pragma: no cover
    import sys
    for p in write_paper_particles(sys.argv[1] if len(sys.argv) > 1 else "inputs/shapes"):
        print("wrote", p)

"""Fit a closed six-patch NURBS particle to a mesh or a point cloud (``nurbsdem fit``).

Topology: the cube-sphere of the paper particles (:mod:`nurbsdem.geometry.particles`) — six
faces of a cube, each a degree-p patch of n x n control points on [0, 2]^2 with uniform
interior knots; neighbouring faces share their boundary control points (one global table,
:func:`~nurbsdem.geometry.particles._control_point_table`), so the patches meet exactly.

Steps (on the data moved to their mean and scaled to unit size, so that the fit does not
depend on the units; the control points are scaled back at the end):

1. **Data.** A particle must be convex, so dents and measurement points inside are dropped.
   *Mesh:* the input is replaced by its convex hull (``trimesh``); the data are the hull's
   vertices, each weighted by its share of the hull's area (a third of its faces' areas),
   plus the centroids of the hull's faces with a small weight (:data:`FACET_WEIGHT`; they
   keep the fit well posed where the hull's vertices are sparser than the control net and
   bias it by a negligible fraction of the facets' sag). *Point cloud* (a scan, noisy): the
   hull of noisy points envelops the noise (a sphere with 1 % radial noise: +4.5 % volume
   with 2 000 points, +6.7 % with 20 000), so the data are the points themselves, equally
   weighted, those deeper below the hull than the noise band dropped
   (:func:`shell_points`); the least squares average the noise, and its RMS residual is the
   noise estimate (reported; warned of above :data:`NOISE_WARN` of the size).
2. **Parameters.** In the hull's principal frame, scaled to unit second moments (an
   ellipsoid becomes a sphere), each point's direction from the centroid picks a cube face and
   its equi-angular face coordinates t = 1 + (4/π) atan(s) in [0, 2] (the parametrisation of
   the paper particles).
3. **Least squares.** The control points minimise Σ w_k |S(u_k, v_k) - x_k|² + λ E, E the
   sum of squared second differences of every face's control net (smoothing, λ relative to
   the data term), subject to the linear smoothness constraints of the paper particles'
   fit (:func:`~nurbsdem.geometry.particles.cube_sphere_constraints`): C1 across the middle
   spans of every edge, one tangent plane at every corner, its normal estimated by a first
   fit. That is G1 wherever a bicubic cube-sphere admits it; what is left are small kinks
   on the end spans of the edges next to the corners (reported as the largest kink angle).
4. **Parameter correction.** Each point is projected onto the fitted surface (Newton) and
   the fit repeated with the new parameters (:data:`CORRECTIONS` times).
5. **Convexity.** If the non-convexity (:func:`~nurbsdem.geometry.connectivity.measure_convexity`)
   exceeds the tolerance, λ grows tenfold and the fit is repeated; if even the smoothest fit
   is not convex enough, the input is refused with where and how much. For a point cloud
   the smoothing acts on the deviation from an ellipsoid of the points' principal frame and
   mean size (:func:`ellipsoid_reference`), so that strong smoothing tends to that convex
   shape instead of shrinking the particle.

The errors reported are the distances of the input points to the fitted surface (closest
points by Newton from a dense sample), relative to the size (diagonal of the hull's
bounding box).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..errors import InputError
from .nurbs import Patch, basis_functions_derivs
from .particles import _FACES, _control_point_table, cube_sphere_constraints

#: Default control points per patch and direction.
DEFAULT_N_CP = 8
#: Default degree (bicubic).
DEFAULT_DEGREE = 3
#: Weight of the hull's face centroids relative to its vertices (per unit area).
FACET_WEIGHT = 0.01
#: Smoothing weights tried for point clouds (the deviation from an ellipsoid is smoothed,
#: so strong weights tend to the ellipsoid, not to a flat net).
CLOUD_SMOOTHING = (1e-6, 1e-4, 1e-2, 1e-1, 1.0, 10.0)
#: Point-cloud points deeper below the convex hull than this many times the median depth
#: are dents or interior points, not noise (:func:`shell_points`).
SHELL_BAND = 6.0
#: Noise (RMS residual of the fitted points) above this fraction of the size is warned of.
NOISE_WARN = 1e-3
#: Parameter corrections (projection + refit).
CORRECTIONS = 2
#: Smoothing weights tried in turn, relative to the data term's scale.
SMOOTHING = (1e-6, 1e-4, 1e-2, 1e-1)
#: File types read as meshes / point clouds by trimesh; .xyz / .txt / .csv are text points.
MESH_SUFFIXES = (".stl", ".ply", ".obj", ".off", ".glb", ".gltf")
TEXT_SUFFIXES = (".xyz", ".txt", ".csv", ".pts")


# ---------------------------------------------------------------------- input
@dataclass
class FitInput:
    """What was read: the points (N, 3) m, and the mesh (trimesh.Trimesh) if there is one."""

    points: np.ndarray
    mesh: object | None = None
    source: str = ""


def read_text_points(path: str | Path) -> np.ndarray:
    """Points of a text file, one ``x y z`` per line (commas or blanks; ``#`` comments; extra
    columns such as normals or colours are ignored). Errors: ``file:line: what is wrong``."""
    path = str(path)
    try:
        lines = Path(path).read_text().splitlines()
    except OSError as exc:
        raise InputError(f"cannot read file: {exc.strerror}", path=path) from None
    pts = []
    for k, line in enumerate(lines, 1):
        text = line.split("#", 1)[0].replace(",", " ").strip()
        if not text:
            continue
        fields = text.split()
        if len(fields) < 3:
            raise InputError(f"expected x y z, got {len(fields)} value(s)", path=path, line=k)
        try:
            xyz = [float(f) for f in fields[:3]]
        except ValueError:
            raise InputError(f"not a number in {' '.join(fields[:3])!r}", path=path,
                             line=k) from None
        if not np.all(np.isfinite(xyz)):
            raise InputError("coordinates must be finite", path=path, line=k)
        pts.append(xyz)
    return np.array(pts, float).reshape(-1, 3)


def read_input(path: str | Path) -> FitInput:
    """Read a mesh (STL, PLY, OBJ, OFF) or point cloud (PLY without faces, or XYZ text)."""
    path = str(path)
    from ..io.shapefile import not_a_file
    why = not_a_file(path)
    if why is not None:
        raise InputError(f"cannot read file: it {why}" if why.startswith("is ")
                         else "cannot read file: No such file or directory", path=path)
    suffix = Path(path).suffix.lower()
    if suffix in TEXT_SUFFIXES:
        pts = read_text_points(path)
        return FitInput(_check_points(pts, path), None, path)
    if suffix not in MESH_SUFFIXES:
        raise InputError(f"unknown file type {suffix!r}: expected a mesh (.stl, .ply, .obj, "
                         f".off) or a point cloud (.ply, .xyz text)", path=path)
    import trimesh
    try:   # unprocessed: trimesh's processing drops non-finite vertices without a word
        obj = trimesh.load(path, force=None, process=False)
    except Exception as exc:  # trimesh raises many types for bad files
        raise InputError(f"not a readable {suffix[1:].upper()} file ({type(exc).__name__}: "
                         f"{' '.join(str(exc).split())[:120]})", path=path) from None
    if isinstance(obj, trimesh.Scene):
        geoms = list(obj.geometry.values())
        if not geoms:
            raise InputError("the file holds no geometry", path=path)
        obj = trimesh.util.concatenate(geoms) if len(geoms) > 1 else geoms[0]
    _check_finite_vertices(np.asarray(getattr(obj, "vertices", np.zeros((0, 3))), float), path)
    if isinstance(obj, trimesh.Trimesh) and len(obj.faces):
        obj = trimesh.Trimesh(obj.vertices, obj.faces, process=True)
        return FitInput(_check_points(np.asarray(obj.vertices, float), path), obj, path)
    pts = np.asarray(getattr(obj, "vertices", np.zeros((0, 3))), float)
    return FitInput(_check_points(pts, path), None, path)


def _check_finite_vertices(pts: np.ndarray, path: str) -> None:
    """Refuse a file with a vertex that is not a finite number (NaN, inf), naming it."""
    bad = np.flatnonzero(~np.isfinite(pts).all(axis=1)) if pts.size else []
    if len(bad):
        k = int(bad[0])
        raise InputError(f"vertex {k} (counted from 0) has non-finite coordinates "
                         f"{' '.join(f'{x:g}' for x in pts[k])} ({len(bad)} such vertices)",
                         path=path)


def _check_points(pts: np.ndarray, path: str) -> np.ndarray:
    if len(pts) < 4:
        raise InputError(f"{len(pts)} point(s): at least 4 points not in one plane are needed",
                         path=path)
    if not np.all(np.isfinite(pts)):
        raise InputError("the file holds non-finite coordinates", path=path)
    c = pts - pts.mean(0)
    sv = np.linalg.svd(c, compute_uv=False)
    if sv[-1] <= 1e-9 * sv[0]:
        raise InputError("the points lie in one plane (or on one line): no solid to fit",
                         path=path)
    return pts


# ---------------------------------------------------------------------- topology / basis
def cube_sphere_knots(n_cp: int, degree: int) -> np.ndarray:
    """Clamped knot vector on [0, 2] with uniform interior knots (n_cp + degree + 1 values)."""
    inner = np.linspace(0.0, 2.0, n_cp - degree + 1)
    return np.concatenate([np.zeros(degree), inner, np.full(degree, 2.0)])


def _basis_rows(knots: np.ndarray, degree: int, n_cp: int, t: np.ndarray) -> np.ndarray:
    """Dense basis matrix (len(t), n_cp) of the B-spline basis at parameters t."""
    spans, ders = basis_functions_derivs(knots, degree, np.clip(t, 0.0, 2.0), 0)
    B = np.zeros((len(t), n_cp))
    for r in range(degree + 1):
        B[np.arange(len(t)), spans - degree + r] = ders[:, 0, r]
    return B


def _design(face, u, v, n_cp: int, degree: int, knots: np.ndarray):
    """Sparse design matrix (K, N): row k = basis values of point k on its face."""
    from scipy.sparse import coo_matrix

    ids, keys = _control_point_table(n_cp)
    Bu = _basis_rows(knots, degree, n_cp, u)
    Bv = _basis_rows(knots, degree, n_cp, v)
    rows, cols, vals = [], [], []
    for f in range(6):
        sel = np.flatnonzero(face == f)
        if not len(sel):
            continue
        B = np.einsum("ki,kj->kij", Bu[sel], Bv[sel]).reshape(len(sel), -1)
        r, c = np.nonzero(B)
        rows.append(sel[r])
        cols.append(ids[f].ravel()[c])
        vals.append(B[r, c])
    K = len(face)
    return coo_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                      shape=(K, len(keys))).tocsr()


def _smoothing_matrix(n_cp: int) -> np.ndarray:
    """Σ over faces of the squared second differences of the control net (N, N)."""
    ids, keys = _control_point_table(n_cp)
    rows = []
    for f in range(6):
        g = ids[f]
        for i in range(n_cp):
            for j in range(n_cp):
                for di, dj in ((1, 0), (0, 1)):
                    if i + 2 * di < n_cp and j + 2 * dj < n_cp:
                        rows.append((g[i, j], g[i + di, j + dj], g[i + 2 * di, j + 2 * dj]))
    D = np.zeros((len(rows), len(keys)))
    for k, (a, b, c) in enumerate(rows):
        D[k, a] += 1.0
        D[k, b] -= 2.0
        D[k, c] += 1.0
    return D.T @ D


def patches_from_table(points: np.ndarray, n_cp: int, degree: int) -> list[Patch]:
    """Six patches indexing the global control-point table (shared points stay identical)."""
    ids, _ = _control_point_table(n_cp)
    kn = cube_sphere_knots(n_cp, degree)
    return [Patch(degree, degree, kn.copy(), kn.copy(), points[ids[f]].copy()) for f in range(6)]


# ---------------------------------------------------------------------- parameters
@dataclass
class Frame:
    """The hull's centroid c (m), principal axes Q (columns, det +1) and semi-scales s (m):
    cube coordinates d = diag(1/s) Qᵀ (x - c)."""

    centre: np.ndarray
    axes: np.ndarray
    scales: np.ndarray

    def local(self, x: np.ndarray) -> np.ndarray:
        return ((x - self.centre) @ self.axes) / self.scales


def hull_frame(hull) -> Frame:
    """Principal frame of a convex hull mesh (trimesh), scaled to unit second moments."""
    c = np.asarray(hull.center_mass, float)
    J = np.asarray(hull.moment_inertia, float) / hull.density      # volume inertia, m^5
    M2 = 0.5 * np.trace(J) * np.eye(3) - J                           # ∫ x xᵀ dV
    w, Q = np.linalg.eigh(0.5 * (M2 + M2.T))
    if np.linalg.det(Q) < 0:
        Q[:, 0] = -Q[:, 0]
    return Frame(c, Q, np.sqrt(np.maximum(w, 1e-300) / hull.volume))


def cube_parameters(d: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Face index and equi-angular parameters (u, v) in [0, 2] of directions d (K, 3)."""
    normals = np.array([f[0] for f in _FACES], float)
    face = np.argmax(d @ normals.T, axis=1)
    n = normals[face]
    a = np.array([_FACES[f][1] for f in face], float)
    b = np.array([_FACES[f][2] for f in face], float)
    dn = np.einsum("ki,ki->k", d, n)
    su = np.einsum("ki,ki->k", d, a) / dn
    sv = np.einsum("ki,ki->k", d, b) / dn
    u = 1.0 + 4.0 / np.pi * np.arctan(su)
    v = 1.0 + 4.0 / np.pi * np.arctan(sv)
    return face, np.clip(u, 0.0, 2.0), np.clip(v, 0.0, 2.0)


def project(patches: list[Patch], face: np.ndarray, u: np.ndarray, v: np.ndarray,
            X: np.ndarray, iters: int = 8) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Closest points on each point's patch by Newton from (u, v), clipped to the domain.

    Returns (u, v, distance (m)) per point."""
    u = u.astype(float).copy()
    v = v.astype(float).copy()
    dist = np.empty(len(X))
    for f, p in enumerate(patches):
        sel = np.flatnonzero(face == f)
        if not len(sel):
            continue
        uu, vv, x = u[sel], v[sel], X[sel]
        lo, hi = p.domain[0], p.domain[1]
        for _ in range(iters):
            d = p.evaluate(uu, vv, 2)
            r = d[:, 0] - x
            Su, Sv = d[:, 1], d[:, 2]
            g = np.stack([np.einsum("ki,ki->k", Su, r), np.einsum("ki,ki->k", Sv, r)], -1)
            H = np.empty((len(sel), 2, 2))
            H[:, 0, 0] = np.einsum("ki,ki->k", Su, Su) + np.einsum("ki,ki->k", d[:, 3], r)
            H[:, 0, 1] = H[:, 1, 0] = (np.einsum("ki,ki->k", Su, Sv)
                                       + np.einsum("ki,ki->k", d[:, 4], r))
            H[:, 1, 1] = np.einsum("ki,ki->k", Sv, Sv) + np.einsum("ki,ki->k", d[:, 5], r)
            # Gauss-Newton where the full Hessian is not positive definite
            det = H[:, 0, 0] * H[:, 1, 1] - H[:, 0, 1] ** 2
            bad = (det <= 0) | (H[:, 0, 0] <= 0)
            H[bad, 0, 0] = np.einsum("ki,ki->k", Su[bad], Su[bad])
            H[bad, 1, 1] = np.einsum("ki,ki->k", Sv[bad], Sv[bad])
            H[bad, 0, 1] = H[bad, 1, 0] = np.einsum("ki,ki->k", Su[bad], Sv[bad])
            det = H[:, 0, 0] * H[:, 1, 1] - H[:, 0, 1] ** 2
            det = np.where(np.abs(det) > 0, det, 1e-300)
            step = np.stack([-(H[:, 1, 1] * g[:, 0] - H[:, 0, 1] * g[:, 1]) / det,
                             -(H[:, 0, 0] * g[:, 1] - H[:, 0, 1] * g[:, 0]) / det], -1)
            step = np.clip(step, -0.25, 0.25)
            uu = np.clip(uu + step[:, 0], lo, hi)
            vv = np.clip(vv + step[:, 1], lo, hi)
        u[sel], v[sel] = uu, vv
        dist[sel] = np.linalg.norm(p.points(uu, vv) - x, axis=1)
    return u, v, dist


def surface_distances(patches: list[Patch], X: np.ndarray, n: int = 40) -> np.ndarray:
    """Distance (m) of points X (K, 3) to a closed multi-patch surface: the nearest of a
    dense sample (n x n per patch) starts Newton on its patch."""
    from scipy.spatial import cKDTree

    t = np.linspace(0.0, 1.0, n)
    S, F, U, V = [], [], [], []
    for f, p in enumerate(patches):
        u0, u1, v0, v1 = p.domain
        uu, vv = np.meshgrid(u0 + t * (u1 - u0), v0 + t * (v1 - v0), indexing="ij")
        S.append(p.points(uu.ravel(), vv.ravel()))
        F.append(np.full(uu.size, f))
        U.append(uu.ravel())
        V.append(vv.ravel())
    S, F, U, V = map(np.concatenate, (S, F, U, V))
    # the nearest samples of a few patches: at an edge the closest point may be on either side
    _, kk = cKDTree(S).query(X, k=6)
    best = np.full(len(X), np.inf)
    for c in range(kk.shape[1]):
        k = kk[:, c]
        if c > 0:   # only candidates on a patch not tried yet for this point
            new = np.all(F[kk[:, :c]] != F[k][:, None], axis=1)
        else:
            new = np.ones(len(X), bool)
        if np.any(new):
            d = project(patches, F[k[new]], U[k[new]], V[k[new]], X[new])[2]
            best[new] = np.minimum(best[new], d)
    return best


# ---------------------------------------------------------------------- least squares
def _solve(A, W: np.ndarray, X: np.ndarray, C: np.ndarray, Rm: np.ndarray,
           lam: float, reference: np.ndarray | None = None) -> np.ndarray:
    """Constrained (C x = 0), smoothed weighted least squares by the KKT system:
    control-point table (N, 3). reference: a control net (N, 3) whose deviation from the
    fit is smoothed instead of the fit itself (strong smoothing then tends to it rather than
    to a flat net)."""
    AtW = A.T.multiply(W[None, :]).tocsr()
    G = (AtW @ A).toarray()
    rhs = np.asarray(AtW @ X)
    scale = np.trace(G) / max(np.trace(Rm), 1e-300)
    if reference is not None:
        rhs = rhs + lam * scale * (Rm @ reference)
    Gs = G + lam * scale * Rm
    N = G.shape[0]
    m = C.shape[0]
    K = np.zeros((3 * N + m, 3 * N + m))
    K[:3 * N, :3 * N] = np.kron(Gs, np.eye(3))       # unknowns point-major (x0 y0 z0 x1 ...)
    K[:3 * N, 3 * N:] = C.T
    K[3 * N:, :3 * N] = C
    b = np.concatenate([rhs.ravel(), np.zeros(m)])
    return np.linalg.solve(K, b)[:3 * N].reshape(N, 3)


def _corner_normals(patches: list[Patch], n_cp: int) -> dict:
    """Unit normals at the 8 cube corners (mean of the patch normals there), keyed by the
    corner's sign triple in the cube frame."""
    ids, keys = _control_point_table(n_cp)
    m = n_cp - 1
    out: dict = {}
    acc: dict = {}
    for f, p in enumerate(patches):
        u0, u1, v0, v1 = p.domain
        for (i, u), (j, v) in ((a, b) for a in ((0, u0), (m, u1)) for b in ((0, v0), (m, v1))):
            key = tuple(int(x) for x in np.sign(keys[ids[f, i, j]]))
            n = p.normals(np.array([u]), np.array([v]))[0]
            acc.setdefault(key, []).append(n / np.linalg.norm(n))
    for key, ns in acc.items():
        n = np.sum(ns, axis=0)
        out[key] = n / np.linalg.norm(n)
    return out


# ---------------------------------------------------------------------- result
@dataclass
class FitResult:
    """A fitted particle and how well it fits (lengths m, volumes m^3, inertia m^5)."""

    shape: object
    size: float
    err_max: float
    err_rms: float
    hull_err_max: float
    facet_err_max: float
    n_points: int
    n_hull_vertices: int
    volume_hull: float
    inertia_hull: np.ndarray
    volume_mesh: float | None
    inertia_mesh: np.ndarray | None
    kink_deg: float
    smoothing: float
    n_cp: int
    degree: int
    notes: list[str] = field(default_factory=list)
    #: RMS distance (m) of the fitted points to the surface: the noise estimate
    noise: float = 0.0

    def lines(self) -> list[str]:
        """The report printed by ``nurbsdem fit`` (one fact per line)."""
        s = self.shape
        L = self.size
        out = list(self.notes)
        out.append(f"fitted: 6 patches, degree {self.degree}, {self.n_cp} x {self.n_cp} control "
                   f"points each, smoothing {self.smoothing:g}; size (hull bounding-box "
                   f"diagonal) {L:.6g} m")
        out.append(f"fit error, {self.n_points} input points to the surface: max "
                   f"{self.err_max:.3g} m ({self.err_max / L:.2e} of the size), RMS "
                   f"{self.err_rms:.3g} m ({self.err_rms / L:.2e}); hull vertices: max "
                   f"{self.hull_err_max / L:.2e}; centres of the hull's facets: max "
                   f"{self.facet_err_max / L:.2e} (includes the facets' sag)")
        out.append(f"noise estimate (RMS distance of the fitted points to the surface): "
                   f"{self.noise:.3g} m ({self.noise / L:.2e} of the size)"
                   + ("; the hull envelops the noise, so its volume is an upper bound"
                      if self.noise > NOISE_WARN * L else ""))
        if self.facet_err_max > 10.0 * max(self.hull_err_max, 1e-3 * L):
            out.append("note: the hull has large flat facets that the smooth particle does not "
                       "follow (a polyhedron, or too few points?): check the volume below")
        out.append(f"G1 across patch edges: largest kink {self.kink_deg:.3g} deg (next to the "
                   f"corners, where a bicubic cube-sphere admits no C1 joint)")
        cv = s.convexity
        if cv is not None:
            out.append(f"non-convexity: {cv.relative:.2e} of the size"
                       + ("" if cv.convex else f" ({cv.where}: {cv.describe()})"))
        refs = [("convex hull", self.volume_hull, self.inertia_hull)]
        if self.volume_mesh is not None:
            refs.insert(0, ("input mesh", self.volume_mesh, self.inertia_mesh))
        for name, V, J in refs:
            dj = np.linalg.norm(s.inertia - J) / np.linalg.norm(J)
            out.append(f"volume {s.volume:.6g} m^3 vs {name} {V:.6g} m^3 "
                       f"({100 * (s.volume / V - 1):+.3f} %); inertia tensor (m^5, about the "
                       f"centroid) differs by {100 * dj:.3f} % (Frobenius norm)")
        return out


def _kink_degrees(shape, n: int = 21) -> float:
    """Largest angle (degrees) between the two patches' normals along the shared edges."""
    from .connectivity import edge_uv

    conn = shape.connectivity
    s = np.linspace(0.0, 1.0, n)
    worst = 0.0
    for i, p in enumerate(shape.patches):
        for e in range(4):
            j, f, r = conn.neighbours[i, e]
            if j < 0:
                continue
            u, v = edge_uv(p.domain, e, s)
            uj, vj = edge_uv(shape.patches[j].domain, f, 1.0 - s if r else s)
            a = p.normals(u, v)
            b = shape.patches[j].normals(uj, vj)
            a = a / np.linalg.norm(a, axis=1)[:, None]
            b = b / np.linalg.norm(b, axis=1)[:, None]
            ang = np.degrees(np.arccos(np.clip(np.einsum("ki,ki->k", a, b), -1, 1)))
            worst = max(worst, float(ang.max()))
    return worst


def _mass_of(mesh) -> tuple[float, np.ndarray]:
    return float(mesh.volume), np.asarray(mesh.moment_inertia, float) / mesh.density


# ---------------------------------------------------------------------- the fit
def fit_particle(data: FitInput | np.ndarray, n_cp: int = DEFAULT_N_CP,
                 degree: int = DEFAULT_DEGREE, convexity_tol: float | None = None,
                 name: str | None = None, smoothing: float | None = None) -> FitResult:
    """Fit a closed six-patch particle to a mesh or a point cloud (module docstring).

    Parameters
    ----------
    data: :class:`FitInput` (from :func:`read_input`) or an array of points (K, 3), m.
    n_cp: control points per patch and direction (degree + 1 ... 20).
    degree: polynomial degree in both directions (2 ... 5; 3 = bicubic).
    convexity_tol: accepted non-convexity relative to the size (default
        :data:`~nurbsdem.geometry.connectivity.DEFAULT_CONVEXITY_TOL`).
    name: the shape's name.
    smoothing: fixed smoothing weight (default: the smallest of :data:`SMOOTHING` whose fit
        is convex within the tolerance).

    The fit runs on the data moved to their mean and scaled to unit size (the diagonal of
    their bounding box), and its control points are scaled back: the result does not
    depend on the units (a 1 um grain fits as a 1 m one).

    Returns
    -------
    :class:`FitResult`; raises :class:`~nurbsdem.errors.InputError` for bad input or a fit
    that cannot be made convex.
    """
    from .connectivity import checked_convexity_tol
    from .shape import Shape

    if not isinstance(data, FitInput):
        data = FitInput(_check_points(np.asarray(data, float), "points"), None, "points")
    src = data.source or None
    if not 2 <= degree <= 5:
        raise InputError(f"degree must be 2 ... 5, got {degree}", path=src)
    if not degree + 1 <= n_cp <= 20:
        raise InputError(f"control-net size must be {degree + 1} ... 20 for degree {degree}, "
                         f"got {n_cp}", path=src)
    tol = checked_convexity_tol(convexity_tol, src)
    pts = np.asarray(data.points, float)
    centre = pts.mean(axis=0)
    L = float(np.linalg.norm(pts.max(0) - pts.min(0)))
    mesh = None
    if data.mesh is not None:
        mesh = data.mesh.copy()
        mesh.apply_translation(-centre)
        mesh.apply_scale(1.0 / L)
    unit = FitInput((pts - centre) / L, mesh, data.source)
    res = _fit_unit(unit, n_cp, degree, tol, smoothing, src)
    patches = [p.transformed(L * np.eye(3), centre) for p in res.shape.patches]
    res.shape = Shape(patches, name=name, source=src, convexity_tol=tol)
    for key in ("size", "err_max", "err_rms", "hull_err_max", "facet_err_max", "noise"):
        setattr(res, key, getattr(res, key) * L)
    res.volume_hull *= L ** 3
    res.inertia_hull = res.inertia_hull * L ** 5
    if res.volume_mesh is not None:
        res.volume_mesh *= L ** 3
        res.inertia_mesh = res.inertia_mesh * L ** 5
    if res.noise > NOISE_WARN * res.size:
        import logging
        logging.getLogger("nurbsdem").warning(
            f"{src or 'fit'}: noisy data: the fitted points lie {res.noise:.3g} m (RMS, "
            f"{res.noise / res.size:.2e} of the size) from the surface; the surface averages "
            f"them (check the volume against the data)")
    return res


def _fit_data(data: FitInput, hull, notes: list[str]) -> tuple[np.ndarray, np.ndarray, int]:
    """The points fitted and their weights, and how many of them are input points.

    A mesh: the hull's vertices, weighted by their share of its area, plus the centroids
    of its facets with a small weight (:data:`FACET_WEIGHT`). A point cloud: its points
    within the noise band below the hull (:func:`shell_points`), equally weighted, so that
    the least squares average the noise instead of enveloping it."""
    V = np.asarray(hull.vertices, float)
    if data.mesh is None:
        keep, band = shell_points(data.points)
        X = data.points[keep]
        n_out = len(data.points) - len(X)
        notes.append(f"input: {len(data.points)} points (point cloud); fitted: the {len(X)} "
                     f"points within {band:.3g} of the size below its convex hull (the noise "
                     f"band), by least squares")
        if n_out:
            notes.append(f"convex hull taken first: {n_out} input points deeper below it "
                         f"(dents, interior) are not fitted")
        return X, np.full(len(X), 1.0 / len(X)), len(X)
    notes.append(f"input: {len(data.points)} points, a mesh of {len(data.mesh.faces)} "
                 f"triangles; fitted to its convex hull ({len(V)} vertices, "
                 f"{len(hull.faces)} triangles)")
    n_inside = len(data.points) - len(V)
    if n_inside > 0:
        notes.append(f"convex hull taken first: {n_inside} input points not on the hull "
                     "(dents, noise, interior) are not fitted")
    area = np.asarray(hull.area_faces, float)
    wv = np.zeros(len(V))
    np.add.at(wv, np.asarray(hull.faces).ravel(), np.repeat(area / 3.0, 3))
    X = np.concatenate([V, np.asarray(hull.triangles_center, float)])
    W = np.concatenate([wv, FACET_WEIGHT * area])
    return X, W / W.sum(), len(V)


def shell_points(points: np.ndarray) -> tuple[np.ndarray, float]:
    """(mask, band): the points whose depth below the convex hull (distance to its nearest
    facet plane, inside) is within the noise band, and the band relative to the size.

    The band is :data:`SHELL_BAND` x the median depth: a noisy scan of a convex body has
    depths of the order of the noise everywhere (a few sigma at most), while dents and
    interior points lie far deeper than the median; noise-free data on a convex surface
    have depth 0 and keep every point on the hull."""
    from scipy.spatial import ConvexHull
    ch = ConvexHull(points)
    depth = np.full(len(points), np.inf)
    for s in range(0, len(points), 2048):
        d = -(points[s:s + 2048] @ ch.equations[:, :3].T + ch.equations[:, 3])
        depth[s:s + 2048] = d.min(axis=1)
    depth = np.maximum(depth, 0.0)
    size = float(np.linalg.norm(points.max(0) - points.min(0)))
    band = max(SHELL_BAND * float(np.median(depth)), 1e-9 * size)
    return depth <= band, band / size


def ellipsoid_reference(X: np.ndarray, W: np.ndarray, frame: Frame, n_cp: int) -> np.ndarray:
    """The control table of the cube's control nets projected radially onto the ellipsoid of
    the frame whose size is the points' weighted mean distance in cube coordinates (an
    unbiased size for zero-mean noise): a convex reference for :func:`_solve`."""
    _, keys = _control_point_table(n_cp)
    rho = float(np.sum(W * np.linalg.norm(frame.local(X), axis=1)) / np.sum(W))
    d = rho * keys / np.linalg.norm(keys, axis=1, keepdims=True)
    return frame.centre + (d * frame.scales) @ frame.axes.T


def _least_squares(X: np.ndarray, W: np.ndarray, frame: Frame, n_cp: int, degree: int,
                   lams, reference: np.ndarray | None = None):
    """Steps 2-4 of the module docstring for each smoothing weight of ``lams`` in turn:
    yields (patches, the weight, their :class:`~nurbsdem.geometry.connectivity.Convexity`)."""
    from .connectivity import measure_convexity
    face, u, v = cube_parameters(frame.local(X))
    knots = cube_sphere_knots(n_cp, degree)
    Rm = _smoothing_matrix(n_cp)
    C_edges = cube_sphere_constraints_edges(n_cp)
    for lam in lams:
        # first fit: C1 edge constraints only; corner normals from it; then the full fit
        A = _design(face, u, v, n_cp, degree, knots)
        P = _solve(A, W, X, C_edges, Rm, lam, reference)
        cn = _corner_normals(patches_from_table(P, n_cp, degree), n_cp)
        C = cube_sphere_constraints(n_cp, cn)
        uu, vv, ff = u, v, face
        for _ in range(CORRECTIONS + 1):
            A = _design(ff, uu, vv, n_cp, degree, knots)
            P = _solve(A, W, X, C, Rm, lam, reference)
            patches = patches_from_table(P, n_cp, degree)
            uu, vv, _ = project(patches, ff, uu, vv, X)
        cv = measure_convexity(patches)
        yield patches, lam, cv


def _convex_fit(X, W, frame, n_cp, degree, lams, tol, src,
                reference=None) -> tuple[list[Patch], float]:
    """The least squares with the smallest smoothing of ``lams`` whose fit is convex within
    ``tol`` of the size; :class:`GeometryError` when none is."""
    from ..errors import GeometryError
    for patches, lam, cv in _least_squares(X, W, frame, n_cp, degree, lams, reference):
        if cv.height <= tol * cv.size:
            return patches, lam
    raise GeometryError(
        f"the fitted particle is not convex within the tolerance even with the strongest "
        f"smoothing ({lams[-1]:g}): {cv.describe()}; the convexity tolerance is "
        f"{tol:g} of the size (option --convexity-tol); try a smaller control net "
        f"(--control-points)", path=src, where=cv.where)


def _fit_unit(data: FitInput, n_cp: int, degree: int, tol: float, smoothing: float | None,
              src: str | None) -> FitResult:
    """:func:`fit_particle` on data of unit size (lengths relative to the size)."""
    import trimesh

    from .shape import Shape

    notes: list[str] = []
    hull = trimesh.convex.convex_hull(data.points)
    V = np.asarray(hull.vertices, float)
    X, W, n_fit = _fit_data(data, hull, notes)
    frame = hull_frame(hull)
    size = float(np.linalg.norm(V.max(0) - V.min(0)))
    lams = SMOOTHING if smoothing is None else (smoothing,)
    if data.mesh is None:
        # the least squares of the noisy points, smoothing their deviation from an ellipsoid
        ref = ellipsoid_reference(X, W, frame, n_cp)
        patches, lam = _convex_fit(X, W, frame, n_cp, degree, CLOUD_SMOOTHING
                                   if smoothing is None else lams, tol, src, ref)
    else:
        patches, lam = _convex_fit(X, W, frame, n_cp, degree, lams, tol, src)
    shape = Shape(patches, source=src, check=False)      # checked once scaled back
    d_in = surface_distances(patches, data.points)
    d_fit = surface_distances(patches, X[:n_fit]) if data.mesh is None else d_in
    d_hull = surface_distances(patches, V)
    d_facet = surface_distances(patches, np.asarray(hull.triangles_center, float))
    vh, jh = _mass_of(hull)
    vm = jm = None
    if data.mesh is not None and data.mesh.is_watertight and data.mesh.volume > 0:
        vm, jm = _mass_of(data.mesh)
    elif data.mesh is not None:
        notes.append("the input mesh is not closed (or not oriented): its volume and inertia "
                     "are not compared")
    return FitResult(shape, size, float(d_in.max()), float(np.sqrt(np.mean(d_in ** 2))),
                     float(d_hull.max()), float(d_facet.max()), len(data.points), len(V), vh,
                     jh, vm, jm, _kink_degrees(shape), lam, n_cp, degree, notes,
                     noise=float(np.sqrt(np.mean(d_fit ** 2))))


def cube_sphere_constraints_edges(n_cp: int) -> np.ndarray:
    """The C1 edge constraints of :func:`cube_sphere_constraints` without the corner rows."""
    C = cube_sphere_constraints(n_cp, None)
    _, keys = _control_point_table(n_cp)
    m = n_cp - 1
    corner_ids = np.flatnonzero(np.sum(np.abs(keys) == m, axis=1) == 3)
    cols = np.concatenate([3 * corner_ids + c for c in range(3)])
    # corner rows are the only rows with a corner point's coordinates
    keep = ~np.any(C[:, cols] != 0, axis=1)
    return C[keep]


# ---------------------------------------------------------------------- near-convex CAD
def projected_cube_sphere(radius: float, n_cp: int = 6, degree: int = 3) -> list[Patch]:
    """A six-patch particle made the way CAD tools make one: the control nets of a cube's
    faces (n_cp x n_cp, uniform) projected radially onto a sphere of the given radius (m).
    Not exactly convex: a tiny saddle at every cube corner (outward normal curvature
    ~2.5 1/m for r = 25 mm, rising ~1e-7 m above the tangent plane there)."""
    _, keys = _control_point_table(n_cp)
    pts = radius * keys / np.linalg.norm(keys, axis=1, keepdims=True)
    return patches_from_table(pts, n_cp, degree)

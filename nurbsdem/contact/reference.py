"""Independent references for the contact tests and benchmarks (slow, plain NumPy/SciPy).

Nothing here shares code with the compiled LCP (:mod:`.lcp`, :mod:`.support`):

* **Ellipsoids** (analytic support function): an ellipsoid with centre c and shape matrix
  M = R diag(a², b², c²) Rᵀ has h(d) = c·d + sqrt(dᵀ M d) and support point
  c + M d / sqrt(dᵀ M d). The signed distance of a pair is −min_{|d|=1} [h_A(d) + h_B(−d)]
  (penetration depth when positive min, distance when negative, see the ``lcp`` module
  docstring), found by a dense start over ~4000 directions and a BFGS refinement in a
  re-centred tangent chart.
* **NURBS bodies** (any shape): the support function is evaluated by dense sampling of the
  surface (vectorised evaluator of :mod:`nurbsdem.geometry.nurbs`) refined with SciPy's
  L-BFGS-B on the best patches; the direction search is the same dense start + BFGS.

Units: metres. Returned tuples: (signed_distance, normal (towards B), point_a, point_b).
"""
from __future__ import annotations

import math

import numpy as np
from scipy.optimize import minimize


def fibonacci_directions(n: int) -> np.ndarray:
    """n nearly uniform unit vectors (Fibonacci lattice), array (n, 3)."""
    k = np.arange(n) + 0.5
    z = 1.0 - 2.0 * k / n
    r = np.sqrt(np.maximum(0.0, 1.0 - z * z))
    ph = np.pi * (1.0 + 5 ** 0.5) * k
    return np.stack([r * np.cos(ph), r * np.sin(ph), z], axis=1)


def _chart(d0: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    a = np.eye(3)[int(np.argmin(np.abs(d0)))]
    t1 = a - (a @ d0) * d0
    t1 /= np.linalg.norm(t1)
    return t1, np.cross(d0, t1)


def minimise_on_sphere(phi_grad, d0: np.ndarray, scale: float, rounds: int = 1) -> np.ndarray:
    """Minimise phi over unit vectors from d0 (BFGS in a tangent chart re-centred each round).

    ``phi_grad(d) -> (phi, euclidean gradient (3,))``."""
    d = np.asarray(d0, float) / np.linalg.norm(d0)
    for _ in range(rounds):
        t1, t2 = _chart(d)

        def fun(x, d=d, t1=t1, t2=t2):
            y = d + x[0] * t1 + x[1] * t2
            ny = np.linalg.norm(y)
            dd = y / ny
            f, g = phi_grad(dd)
            # d(dd)/dx_i = (t_i - dd (dd . t_i)) / ny
            gx = np.array([(g @ (t1 - dd * (dd @ t1))), (g @ (t2 - dd * (dd @ t2)))]) / ny
            return f, gx

        res = minimize(fun, np.zeros(2), jac=True, method="BFGS",
                       options={"gtol": 1e-13 * scale, "maxiter": 100})
        y = d + res.x[0] * t1 + res.x[1] * t2
        d = y / np.linalg.norm(y)
    return d


# --------------------------------------------------------------------------- ellipsoids
def ellipsoid_matrix(axes, rotation) -> np.ndarray:
    """Shape matrix M = R diag(a², b², c²) Rᵀ (m²)."""
    R = np.asarray(rotation, float)
    return R @ np.diag(np.asarray(axes, float) ** 2) @ R.T


def ellipsoid_support(centre, M, d) -> tuple[float, np.ndarray]:
    """Support function value h(d) (m) and support point (m) of an ellipsoid."""
    d = np.asarray(d, float)
    s = math.sqrt(float(d @ M @ d))
    return float(np.asarray(centre) @ d) + s, np.asarray(centre, float) + M @ d / s


def ellipsoid_pair(axes_a, pose_a, axes_b, pose_b, n_dirs: int = 4000):
    """Reference contact of two ellipsoids (centred at their pose positions).

    Returns (signed_distance, normal, point_a, point_b)."""
    ca, Ra = np.asarray(pose_a[0], float), np.asarray(pose_a[1], float)
    cb, Rb = np.asarray(pose_b[0], float), np.asarray(pose_b[1], float)
    Ma, Mb = ellipsoid_matrix(axes_a, Ra), ellipsoid_matrix(axes_b, Rb)
    D = fibonacci_directions(n_dirs)
    phi = D @ ca + np.sqrt(np.einsum("ij,jk,ik->i", D, Ma, D)) - D @ cb + \
        np.sqrt(np.einsum("ij,jk,ik->i", D, Mb, D))
    d0 = D[int(np.argmin(phi))]

    def phi_grad(d):
        ha, pa = ellipsoid_support(ca, Ma, d)
        hb, pb = ellipsoid_support(cb, Mb, -d)
        return ha + hb, pa - pb

    scale = max(np.max(axes_a), np.max(axes_b))
    d = minimise_on_sphere(phi_grad, d0, scale)
    ha, pa = ellipsoid_support(ca, Ma, d)
    hb, pb = ellipsoid_support(cb, Mb, -d)
    return -(ha + hb), d, pa, pb


# --------------------------------------------------------------------------- NURBS bodies
def _newton_polish(pt, e: np.ndarray, x: np.ndarray, iters: int = 3) -> np.ndarray:
    """A few projected Newton steps on max e·s(u, v) over the patch rectangle, after the
    L-BFGS-B solution (which stalls near machine precision): parameters at a bound with the
    gradient pointing out stay fixed."""
    u0, u1, v0, v1 = pt.domain
    lo, hi = np.array([u0, v0]), np.array([u1, v1])
    x = np.array(x, float)
    for _ in range(iters):
        ev = pt.evaluate(np.array([x[0]]), np.array([x[1]]), 2)[0]
        g = np.array([ev[1] @ e, ev[2] @ e])
        H = np.array([[ev[3] @ e, ev[4] @ e], [ev[4] @ e, ev[5] @ e]])
        free = ~(((x <= lo) & (g < 0)) | ((x >= hi) & (g > 0)))
        if not free.any():
            break
        idx = np.flatnonzero(free)
        Hf = H[np.ix_(idx, idx)]
        if np.any(np.linalg.eigvalsh(Hf) >= 0):
            break
        step = np.zeros(2)
        step[idx] = -np.linalg.solve(Hf, g[idx])
        if np.linalg.norm(step) > 0.05 * max(u1 - u0, v1 - v0):
            break
        x = np.clip(x + step, lo, hi)
    return x


class SampledBody:
    """A NURBS shape in a pose with a dense surface sample, for reference support mappings.

    ``n`` samples per parameter per patch (cell corners, edges included)."""

    def __init__(self, shape, pose, n: int = 40) -> None:
        self.shape = shape
        self.pos = np.asarray(pose[0], float)
        self.R = np.asarray(pose[1], float)
        pts, par, pid = [], [], []
        for i, pt in enumerate(shape.patches):
            u0, u1, v0, v1 = pt.domain
            U, V = np.meshgrid(np.linspace(u0, u1, n), np.linspace(v0, v1, n), indexing="ij")
            x = pt.evaluate(U.ravel(), V.ravel(), 0)[:, 0]
            pts.append(x)
            par.append(np.stack([U.ravel(), V.ravel()], 1))
            pid.append(np.full(U.size, i))
        self.x_file = np.concatenate(pts)
        self.x = self.x_file @ self.R.T + self.pos
        self.uv = np.concatenate(par)
        self.pid = np.concatenate(pid)
        self.scale = float(shape.bounding_radius)

    def sampled_support(self, D: np.ndarray) -> np.ndarray:
        """Sampled (lower-bound) support values for directions D (m, 3): (m,)."""
        return (self.x @ D.T).max(axis=0)

    def support(self, d: np.ndarray, n_patches: int = 3) -> tuple[float, np.ndarray]:
        """Support value (m) and point (world, m) along the world direction d, refined by
        L-BFGS-B on the ``n_patches`` best patches (by sampled value)."""
        e = self.R.T @ np.asarray(d, float)
        vals = self.x_file @ e
        best_h, best_p = -np.inf, None
        order = []
        for i in range(len(self.shape.patches)):
            m = self.pid == i
            k = np.flatnonzero(m)[int(np.argmax(vals[m]))]
            order.append((vals[k], i, k))
        order.sort(reverse=True)
        # patches whose best sample is close to the overall best (a support point near an
        # edge or a corner can lie on any of them); the others cannot hold the maximum
        close = [o for o in order[:n_patches] if o[0] >= order[0][0] - 2e-3 * self.scale]
        for _, i, k in close:
            pt = self.shape.patches[i]
            u0, u1, v0, v1 = pt.domain

            def fun(x, pt=pt):
                ev = pt.evaluate(np.array([x[0]]), np.array([x[1]]), 1)[0]
                return -float(ev[0] @ e), -np.array([ev[1] @ e, ev[2] @ e])

            res = minimize(fun, self.uv[k], jac=True, method="L-BFGS-B",
                           bounds=[(u0, u1), (v0, v1)],
                           options={"ftol": 1e-14, "gtol": 1e-11 * self.scale, "maxiter": 200})
            x = _newton_polish(pt, e, res.x)
            ev = pt.evaluate(np.array([x[0]]), np.array([x[1]]), 0)[0, 0]
            h = float(ev @ e)
            if h > best_h:
                best_h = h
                best_p = ev
        p = self.pos + self.R @ best_p
        return float(self.pos @ d + best_h), p


def nurbs_pair(shape_a, pose_a, shape_b, pose_b, n: int = 40, n_dirs: int = 3000,
               d_start: np.ndarray | None = None):
    """Reference contact of two NURBS bodies (dense sampling + SciPy refinement).

    Returns (signed_distance, normal, point_a, point_b)."""
    A = SampledBody(shape_a, pose_a, n)
    B = SampledBody(shape_b, pose_b, n)
    D = fibonacci_directions(n_dirs)
    phi = A.sampled_support(D) + B.sampled_support(-D)
    d0 = D[int(np.argmin(phi))] if d_start is None else np.asarray(d_start, float)

    def phi_grad(d):
        ha, pa = A.support(d)
        hb, pb = B.support(-d)
        return ha + hb, pa - pb

    d = minimise_on_sphere(phi_grad, d0, A.scale + B.scale)
    ha, pa = A.support(d)
    hb, pb = B.support(-d)
    return -(ha + hb), d, pa, pb


def wall_reference(shape, pose, origin, normal, n: int = 40):
    """Reference of a body against the plane through ``origin`` with unit ``normal`` (pointing
    to the body's side): (signed_distance, body point (world)). No rectangle check."""
    A = SampledBody(shape, pose, n)
    nrm = np.asarray(normal, float)
    h, p = A.support(-nrm)
    return float(nrm @ (p - np.asarray(origin, float))), p


def random_pair_poses(table, sa, sb, rng, lo, hi):
    """Random poses for the seeded sweeps of the tests and the report: random orientations,
    B along a random direction from A, then translated along the computed normal until the
    signed distance is a target drawn uniformly in [lo, hi] × the smaller bounding radius.

    table: :class:`~nurbsdem.contact.detect.ContactTable`; sa, sb: int (K,) shape indices;
    rng: numpy Generator. Returns (pa, Ra, pb, Rb): positions (K, 3) m, rotations (K, 3, 3).
    """
    from scipy.spatial.transform import Rotation

    from .detect import detect_batch
    from .lcp import F_N, F_SD
    K = len(sa)
    ra = Rotation.random(K, random_state=rng).as_matrix()
    rb = Rotation.random(K, random_state=rng).as_matrix()
    u = rng.normal(size=(K, 3))
    u /= np.linalg.norm(u, axis=1)[:, None]
    pa = rng.normal(size=(K, 3)) * 0.01 - np.einsum("kij,kj->ki", ra, table.centroid[sa])
    ca = pa + np.einsum("kij,kj->ki", ra, table.centroid[sa])
    r = np.minimum(table.radius[sa], table.radius[sb])
    pb = ca + 0.9 * (table.radius[sa] + table.radius[sb])[:, None] * u \
        - np.einsum("kij,kj->ki", rb, table.centroid[sb])
    target = rng.uniform(lo, hi, K) * r
    for _ in range(4):
        f, _ = detect_batch(table, sa, pa, ra, sb, pb, rb)
        pb = pb + (target - f[:, F_SD])[:, None] * f[:, F_N:F_N + 3]
    return pa, ra, pb, rb

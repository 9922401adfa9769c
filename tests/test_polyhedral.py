"""Polyhedral contact (GJK/EPA on tessellated hulls): exact cubes, convergence to the exact
sphere contact, and random hulls against independent SciPy references."""
from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize import minimize
from scipy.spatial import ConvexHull
from scipy.spatial.transform import Rotation

from nurbsdem.geometry.generators import sphere
from polyhedral import (EPA_MAX_IT, GJK_MAX_IT, ST_APPROX, Polyhedron, facet_count,  # benchmarks/
                        polyhedral_contact, polyhedral_contact_batch, polyhedron_from_shape)

I3 = np.eye(3)
CUBE = np.array([[x, y, z] for x in (-.5, .5) for y in (-.5, .5) for z in (-.5, .5)])


def _check_consistent(res, tol=1e-10):
    sd, n, pa, pb, it = res[:5]
    assert abs(np.linalg.norm(n) - 1) < 1e-12
    assert abs(n @ (pa - pb) + sd) < tol
    assert it <= GJK_MAX_IT + EPA_MAX_IT


# --------------------------------------------------------------------------- cubes
@pytest.mark.parametrize("off, sd, normal", [
    ((0.9, 0.2, 0.1), -0.1, (1, 0, 0)),               # face overlap along x
    ((0.15, -0.8, 0.3), -0.2, (0, -1, 0)),            # overlap along -y
    ((1.3, 0.2, 0.1), 0.3, (1, 0, 0)),                # face separation
    ((1.2, 1.3, 0.0), np.hypot(.2, .3), (.2, .3, 0)),  # edge-edge separation
    ((1.2, 1.3, -1.4), np.sqrt(.04 + .09 + .16), (.2, .3, -.4)),  # vertex-vertex
    ((0.5, 0.0, 0.0), -0.5, (1, 0, 0)),
])
@pytest.mark.parametrize("hull", [False, True])
def test_axis_aligned_cubes_exact(off, sd, normal, hull):
    a = Polyhedron.from_vertices(CUBE) if hull else CUBE
    # a common rigid motion of both bodies must rotate the answer and change nothing else
    for Q, t in [(I3, np.zeros(3)),
                 (Rotation.from_rotvec([0.3, -0.7, 0.2]).as_matrix(), np.array([3., -1., 2.]))]:
        res = polyhedral_contact(a, (t, Q), a, (t + Q @ np.array(off, float), Q))
        n_exp = Q @ (np.array(normal, float) / np.linalg.norm(normal))
        assert res[0] == pytest.approx(sd, abs=1e-12)
        assert np.allclose(res[1], n_exp, atol=1e-9)
        _check_consistent(res)
        # points lie on the (moved) cubes
        la = Q.T @ (res[2] - t)
        lb = Q.T @ (res[3] - t) - np.array(off)
        assert np.all(np.abs(la) <= 0.5 + 1e-12) and np.all(np.abs(lb) <= 0.5 + 1e-12)


@pytest.mark.parametrize("off", [(1.0, 0.3, 0.2), (1.0, 1.0, 1.0), (1.0, 1.0, 0.0), (0, 0, 0),
                                 (0.5, 0.5, 0.5), (1.0, 0.0, 0.0)])
def test_touching_and_coincident_cubes_terminate(off):
    """Touching (distance 0) and fully symmetric overlaps: no hang, exact depth."""
    res = polyhedral_contact(CUBE, (np.zeros(3), I3), CUBE, (np.array(off, float), I3),
                             return_status=True)
    _check_consistent(res)
    # overlap of axis-aligned unit cubes: depth = min over axes of (1 - |offset|)
    assert res[0] == pytest.approx(-min(1 - abs(o) for o in off), abs=1e-12)
    assert res[5] != ST_APPROX


def test_flat_vertex_sets_do_not_hang():
    sq = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0.]])
    for off in ([0.5, 0.5, 0.0], [0.2, 0.1, 0.0], [0.3, 0.3, 0.5]):
        res = polyhedral_contact(sq, (np.zeros(3), I3), sq, (np.array(off), I3),
                                 return_status=True)
        assert res[4] <= GJK_MAX_IT + EPA_MAX_IT
        assert np.isfinite(res[0])
    assert res[0] == pytest.approx(0.5)


# --------------------------------------------------------------------------- spheres
@pytest.fixture(scope="module")
def sphere_polys():
    s = sphere(1.0)
    return {n: Polyhedron.from_shape(s, n) for n in (4, 8, 16, 32)}


def test_polyhedron_from_shape_dedupes_and_counts(sphere_polys):
    v = polyhedron_from_shape(sphere(1.0), 4)
    # 6 faces of a 5x5 grid on a cube: 6*25 points, edges and corners shared
    assert len(v) == 6 * 4 * 4 + 2
    assert np.allclose(np.linalg.norm(v, axis=1), 1.0, atol=1e-14)
    assert facet_count(v) == 2 * len(v) - 4  # triangulated sphere-like hull (Euler)
    assert sphere_polys[4].n_facets == facet_count(v)


def test_sphere_contact_converges_quadratically(sphere_polys):
    rng = np.random.default_rng(7)
    K = 8
    Ra = Rotation.random(K, random_state=11).as_matrix()
    Rb = Rotation.random(K, random_state=12).as_matrix()
    u = rng.normal(size=(K, 3))
    u /= np.linalg.norm(u, axis=1)[:, None]
    med_pen, med_dist = [], []
    for n, P in sphere_polys.items():
        ep, ed = [], []
        for k in range(K):
            for s, ref in ((1.9, -0.1), (2.1, 0.1)):
                res = polyhedral_contact(P, (np.zeros(3), Ra[k]), P, (s * u[k], Rb[k]))
                _check_consistent(res)
                # inscribed polyhedra: less penetration, more distance, never the reverse
                assert res[0] >= ref - 1e-12
                assert np.degrees(np.arccos(min(1.0, res[1] @ u[k]))) < 60.0 / n
                (ep if ref < 0 else ed).append(res[0] - ref)
        med_pen.append(np.median(ep))
        med_dist.append(np.median(ed))
    for med in (med_pen, med_dist):
        ratios = np.array(med[:-1]) / np.array(med[1:])
        assert np.all((ratios > 3.0) & (ratios < 5.5)), ratios  # O(h^2): 4 per halving of h
    assert med_pen[-1] < 1e-3 and med_dist[-1] < 1e-3


def test_hill_climbing_equals_brute_force(sphere_polys):
    P = sphere_polys[16]
    rng = np.random.default_rng(3)
    for k in range(10):
        Ra, Rb = Rotation.random(2, random_state=k).as_matrix()
        pb = rng.normal(size=3)
        pb *= rng.uniform(1.5, 2.3) / np.linalg.norm(pb)
        r1 = polyhedral_contact(P, (np.zeros(3), Ra), P, (pb, Rb))
        r2 = polyhedral_contact(P.vertices, (np.zeros(3), Ra), P.vertices, (pb, Rb))
        assert r1[0] == pytest.approx(r2[0], abs=1e-12)
        assert np.allclose(r1[1], r2[1], atol=1e-8)


def test_batch_matches_single(sphere_polys):
    P = sphere_polys[8]
    K = 5
    R = Rotation.random(2 * K, random_state=5).as_matrix()
    pos_b = np.tile([1.95, 0.1, 0.0], (K, 1)) * np.linspace(0.9, 1.2, K)[:, None]
    out, its, sts = polyhedral_contact_batch(P, np.zeros((K, 3)), R[:K], P, pos_b, R[K:])
    for k in range(K):
        r = polyhedral_contact(P, (np.zeros(3), R[k]), P, (pos_b[k], R[K + k]))
        assert out[k, 0] == pytest.approx(r[0], abs=1e-15) and its[k] == r[4]


# --------------------------------------------------------------------------- random hulls
def _world(v, pos, R):
    return pos + v @ R.T


def _ref_penetration(A, B):
    """Exact: the Minkowski difference A − B as an explicit hull; origin inside -> depth is
    the smallest facet-plane distance, normal that facet's outward normal."""
    cso = ConvexHull((A[:, None, :] - B[None, :, :]).reshape(-1, 3))
    eq = cso.equations  # n·x + off <= 0 inside, n outward unit
    if np.any(eq[:, 3] > 0):
        return None
    k = int(np.argmin(-eq[:, 3]))
    return -eq[k, 3], eq[k, :3]


def _ref_distance(A, B):
    """Distance of two hulls by a QP over convex combinations (SciPy SLSQP)."""
    na, nb = len(A), len(B)

    def f(x):
        g = A.T @ x[:na] - B.T @ x[na:]
        return g @ g, np.concatenate([2 * A @ g, -2 * B @ g])

    cons = [{"type": "eq", "fun": lambda x: x[:na].sum() - 1, "jac": lambda x: np.r_[np.ones(na), np.zeros(nb)]},
            {"type": "eq", "fun": lambda x: x[na:].sum() - 1, "jac": lambda x: np.r_[np.zeros(na), np.ones(nb)]}]
    x0 = np.r_[np.full(na, 1 / na), np.full(nb, 1 / nb)]
    r = minimize(f, x0, jac=True, bounds=[(0, 1)] * (na + nb), constraints=cons,
                 method="SLSQP", options={"ftol": 1e-16, "maxiter": 500})
    return float(np.sqrt(max(r.fun, 0.0)))


def _ref_distance_cso(A, B):
    """Distance of two hulls as the distance from the origin to the explicit Minkowski
    difference hull: minimum over its triangles of the point-triangle distance (NumPy)."""
    cso = ConvexHull((A[:, None, :] - B[None, :, :]).reshape(-1, 3))
    T = cso.points[cso.simplices]  # (F, 3, 3)
    a, b, c = T[:, 0], T[:, 1], T[:, 2]
    n = np.cross(b - a, c - a)
    n /= np.linalg.norm(n, axis=1)[:, None]
    h = np.einsum("ij,ij->i", a, n)
    p = h[:, None] * n  # origin projected on each plane
    inside = np.ones(len(T), bool)
    for u, v in ((a, b), (b, c), (c, a)):
        inside &= np.einsum("ij,ij->i", np.cross(v - u, p - u), n) >= 0
    best = np.where(inside, np.abs(h), np.inf)
    for u, v in ((a, b), (b, c), (c, a)):
        e = v - u
        t = np.clip(-np.einsum("ij,ij->i", u, e) / np.einsum("ij,ij->i", e, e), 0, 1)
        best = np.minimum(best, np.linalg.norm(u + t[:, None] * e, axis=1))
    return float(best.min())


def test_random_hulls_against_scipy_references():
    rng = np.random.default_rng(2024)
    n_pen = n_sep = 0
    for trial in range(40):
        va = rng.normal(size=(rng.integers(8, 30), 3)) * rng.uniform(0.3, 1.5, 3)
        vb = rng.normal(size=(rng.integers(8, 30), 3)) * rng.uniform(0.3, 1.5, 3)
        Ra, Rb = Rotation.random(2, random_state=100 + trial).as_matrix()
        pos_a = rng.normal(size=3)
        pos_b = pos_a + rng.normal(size=3) * rng.uniform(0.5, 3.0)
        A, B = _world(va, pos_a, Ra), _world(vb, pos_b, Rb)
        for verts_a, verts_b in ((va, vb), (Polyhedron.from_vertices(va), Polyhedron.from_vertices(vb))):
            res = polyhedral_contact(verts_a, (pos_a, Ra), verts_b, (pos_b, Rb))
            _check_consistent(res, tol=1e-9)
            sd, n, pa, pb = res[:4]
            pen = _ref_penetration(A, B)
            if pen is not None:
                n_pen += 1
                assert sd == pytest.approx(-pen[0], rel=1e-9, abs=1e-12)
                assert np.allclose(n, pen[1], atol=1e-7)
            else:
                n_sep += 1
                assert sd == pytest.approx(_ref_distance(A, B), rel=1e-6, abs=1e-9)
                assert sd == pytest.approx(_ref_distance_cso(A, B), rel=1e-10, abs=1e-13)
                # dual certificate: separating slab of width sd along the normal
                assert (B @ n).min() - (A @ n).max() == pytest.approx(sd, rel=1e-9, abs=1e-12)
            # witness points lie in the hulls
            for P, p in ((A, pa), (B, pb)):
                eq = ConvexHull(P).equations
                assert np.all(eq[:, :3] @ p + eq[:, 3] <= 1e-9)
    assert n_pen >= 8 and n_sep >= 8


def test_fine_polyhedra_against_explicit_minkowski_difference(sphere_polys):
    """EPA/GJK on many small facets (where early termination would show) against the exact
    polytope answer: the explicit CSO hull (penetration) and the SLSQP QP (distance)."""
    rng = np.random.default_rng(99)
    for k in range(4):
        Ra, Rb = Rotation.random(2, random_state=300 + k).as_matrix()
        u = rng.normal(size=3)
        u /= np.linalg.norm(u)
        P = sphere_polys[8]
        pos_b = rng.uniform(1.80, 1.98) * u
        res = polyhedral_contact(P, (np.zeros(3), Ra), P, (pos_b, Rb))
        pen = _ref_penetration(_world(P.vertices, np.zeros(3), Ra), _world(P.vertices, pos_b, Rb))
        assert res[0] == pytest.approx(-pen[0], rel=1e-10)
        assert np.allclose(res[1], pen[1], atol=1e-8)
        pos_b = rng.uniform(2.02, 2.3) * u
        res = polyhedral_contact(P, (np.zeros(3), Ra), P, (pos_b, Rb))
        A, B = _world(P.vertices, np.zeros(3), Ra), _world(P.vertices, pos_b, Rb)
        assert res[0] == pytest.approx(_ref_distance_cso(A, B), rel=1e-10)

"""An exact sphere against a NURBS body as a point-to-surface problem (contact/sphere.py):
against the closed-form distance to an ellipsoid, against the 4-parameter LCP on the same
geometry, and in a scene (the same dynamics as with the LCP, fewer LCPs)."""
from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize import brentq
from scipy.spatial.transform import Rotation

from nurbsdem.contact.detect import ContactTable, detect_batch
from nurbsdem.contact.lcp import (F_N, F_PA, F_PB, F_SD, I_DEG, I_FAIL, I_NEV, I_PA, I_PB,
                                  I_STAGE, I_VALID, NF, NI, STAGE_POINT, warm_start)
from nurbsdem.contact.sphere import sphere_nurbs_rows
from nurbsdem.geometry.generators import ellipsoid
from nurbsdem.geometry.particles import paper_particle_shape
from nurbsdem.shapes import sphere
from runs import spread_points

R_S = 0.01
AXES = (0.03, 0.02, 0.012)


@pytest.fixture(scope="module")
def table():
    return ContactTable([sphere(R_S), ellipsoid(*AXES), paper_particle_shape("A")])


def _poses(table, sb, K, rng, lo=-0.8, hi=1.0):
    """K poses of body shape sb and a sphere centre along a random direction from its centroid,
    at (bounding radius + r) × s, s in [lo, hi] scaled so that contacts and gaps both occur."""
    Rb = Rotation.random(K, random_state=rng).as_matrix()
    pb = rng.normal(size=(K, 3)) * 0.01
    d = rng.normal(size=(K, 3))
    d /= np.linalg.norm(d, axis=1)[:, None]
    cen = pb + np.einsum("kij,j->ki", Rb, table.centroid[sb])
    reach = table.radius[sb] + R_S
    c = cen + d * reach * rng.uniform(0.55, 0.95, (K, 1))
    return c, pb, Rb


def _solve(table, sb, c, pb, Rb, prev=None, sphere_is_a=True):
    K = c.shape[0]
    rf, ri = np.zeros((K, NF)), np.zeros((K, NI), np.int64)
    pf, pi = prev if prev is not None else (np.zeros((K, NF)), np.zeros((K, NI), np.int64))
    ok = sphere_nurbs_rows(table.tab, table.info, table.centroid, table.radius, table.seeds,
                           np.full(K, sb), c, np.full(K, R_S), pb, Rb,
                           np.full(K, sphere_is_a), pf, pi, rf, ri)
    return ok, rf, ri


def _ellipsoid_distance(y: np.ndarray) -> float:
    """Distance from a point y outside the ellipsoid AXES (its frame) to its surface: the
    closest point a_i² y_i / (a_i² + t) with t > 0 the root of Σ (a_i y_i / (a_i² + t))² = 1."""
    a = np.array(AXES)
    f = lambda t: np.sum((a * y / (a * a + t)) ** 2) - 1.0      # noqa: E731
    t = brentq(f, 0.0, 10.0 * np.linalg.norm(y) * a.max(), xtol=1e-300, rtol=1e-15, maxiter=500)
    x = a * a * y / (a * a + t)
    return float(np.linalg.norm(y - x))


def test_sphere_against_ellipsoid_equals_the_closed_form_distance(table):
    rng = np.random.default_rng(1)
    c, pb, Rb = _poses(table, 1, 400, rng)
    ok, rf, ri = _solve(table, 1, c, pb, Rb)
    assert ok.mean() > 0.9                      # the rest: the LCP's (another patch)
    for k in np.nonzero(ok)[0]:
        y = Rb[k].T @ (c[k] - pb[k] - Rb[k] @ table.centroid[1])
        ref = _ellipsoid_distance(y) - R_S
        assert abs(rf[k, F_SD] - ref) <= 1e-15, (k, rf[k, F_SD], ref)
    assert (rf[ok, F_SD] < 0).sum() > 50 and (rf[ok, F_SD] > 0).sum() > 50


@pytest.mark.parametrize("sb", [1, 2])
@pytest.mark.parametrize("sphere_is_a", [True, False])
def test_equals_the_lcp_on_the_same_geometry(table, sb, sphere_is_a):
    """Rows agree with the 4-parameter LCP to its stopping tolerance; warm-started from the
    LCP's rows every solve whose centre is outside the body and whose LCP needed no
    degeneration (a crease: the LCP's case) succeeds."""
    rng = np.random.default_rng(10 * sb + sphere_is_a)
    K = 500
    c, pb, Rb = _poses(table, sb, K, rng)
    sph = np.zeros(K, np.int64)
    ps, Rs = c - table.centroid[0], np.tile(np.eye(3), (K, 1, 1))
    if sphere_is_a:
        f, i = detect_batch(table, sph, ps, Rs, np.full(K, sb), pb, Rb)
    else:
        f, i = detect_batch(table, np.full(K, sb), pb, Rb, sph, ps, Rs)
    assert not i[:, I_FAIL].any()
    sphere_side = I_PA if sphere_is_a else I_PB
    i_prev = i.copy()
    i_prev[:, sphere_side] = -1                 # as the scene's rows of this solver
    ok_w, rw, iw = _solve(table, sb, c, pb, Rb, (f, i_prev), sphere_is_a)
    ok_c, rc, ic = _solve(table, sb, c, pb, Rb, None, sphere_is_a)
    outside = f[:, F_SD] > -R_S            # the centre outside B: this solver's case
    assert outside.sum() > 250 and ((f[:, F_SD] < 0) & outside).sum() > 50
    smooth = outside & (i[:, I_DEG] == 0)   # not on a crease of the patch connections
    assert ok_w[smooth].all() and not ok_w[~outside].any() and not ok_c[~outside].any()
    assert ok_c[outside].mean() > 0.85      # cold: the rest start on another patch
    scale = table.radius[sb]
    for ok, r in ((ok_w, rw), (ok_c, rc)):
        assert np.abs(r[ok, F_SD] - f[ok, F_SD]).max() <= 1e-12 * scale
        assert np.linalg.norm(r[ok, F_N:F_N + 3] - f[ok, F_N:F_N + 3], axis=1).max() <= 1e-9
        for col in (F_PA, F_PB):
            assert np.linalg.norm(r[ok, col:col + 3] - f[ok, col:col + 3], axis=1).max() \
                <= 1e-9 * scale


def test_the_lcp_starts_cold_from_a_point_solvers_row(table):
    """A pair the point solver hands to the LCP (its centre inside the body) holds the point
    solver's row, valid but naming no patch of the sphere: the LCP starts cold from it (the
    same bits as from no row), and from its own row warm (fewer patch evaluations)."""
    rng = np.random.default_rng(7)
    K = 200
    c, pb, Rb = _poses(table, 2, K, rng)
    sph = np.zeros(K, np.int64)
    ps, Rs = c - table.centroid[0], np.tile(np.eye(3), (K, 1, 1))
    args = (table, sph, ps, Rs, np.full(K, 2), pb, Rb)
    cold_f, cold_i = detect_batch(*args)
    point_i = cold_i.copy()
    point_i[:, I_PA] = -1                    # the sphere's side: a closed form
    point_i[:, I_STAGE] = STAGE_POINT
    assert all(warm_start(row) for row in cold_i) and not any(warm_start(r) for r in point_i)
    f, i = detect_batch(*args, prev_f=cold_f, prev_i=point_i)
    assert np.array_equal(f, cold_f) and np.array_equal(i, cold_i)
    invalid = cold_i.copy()
    invalid[:, I_VALID] = 0
    assert not any(warm_start(r) for r in invalid)
    _, warm_i = detect_batch(*args, prev_f=cold_f, prev_i=cold_i)
    assert warm_i[:, I_NEV].sum() < cold_i[:, I_NEV].sum()


def test_scene_with_spheres_and_particles_matches_the_lcp(tmp_path):
    """Spheres and paper particles C dropped together: the same motion with the point-to-
    surface solver as with the LCP for every mixed pair (to the LCP's tolerance)."""
    from pathlib import Path

    from nurbsdem.io.deck import parse_deck
    from nurbsdem.solver import Solver
    shapes = Path(__file__).resolve().parents[1] / "inputs" / "shapes"
    lines = []
    pts = spread_points(np.random.default_rng(3), 14, [0.02, 0.02, 0.02], [0.09, 0.09, 0.16],
                        0.04)
    for i, p in enumerate(pts):
        lines.append(f"  Particle {i + 1} Shape {1 + i % 2} Material 1 Position "
                     f"{p[0]:.6f} {p[1]:.6f} {p[2]:.6f}")
    deck = tmp_path / "mixed.inp"
    deck.write_text(f"""Environment
  Gravity 0 0 -9.81
Materials
  Material 1 Density 2700
Shapes
  Shape 1 Sphere Radius 0.014
  Shape 2 File {shapes / 'C.yaml'}
Particles
""" + "\n".join(lines) + """
Walls
  Box 1 Min 0 0 0 Max 0.11 0.11 0.2
Contact
  Interface 1 NormalPenalty 1e5 TangentialPenalty 1e4 NormalDamping 1e2 TangentialDamping 0 Friction 0.5
Steps
  Step 1 Dynamic Duration 0.15 TimeStep 1e-3
Output
  Directory out
  VTK Every 1 Resolution 2
  Monitors Every 0.01
""")
    runs = {}
    for on in (True, False):
        s = Solver(parse_deck(deck), write_output=False, quiet=True,
                   contact_options=dict(point_surface=on))
        summary = s.run()
        runs[on] = (s.bodies.position.copy(), summary, s.scene.point_solves)
    (x1, s1, n1), (x0, s0, n0) = runs[True], runs[False]
    assert n1 > 1000 and n0 == 0
    assert s1.failed == 0 and s0.failed == 0 and s1.substeps == s0.substeps
    # the pile forms (later the trajectories part: granular flow amplifies the LCP tolerance)
    assert np.abs(x1 - x0).max() <= 1e-9 and s1.active_max >= 10

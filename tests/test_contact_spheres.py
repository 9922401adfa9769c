"""LCP on exact spheres (6-patch Cobb sphere and the single-patch sphere with poles and a
seam): the exact answer is known, signed distance = |c_B − c_A| − r_A − r_B, normal along
the centre line. Contact points in a patch interior, exactly on a patch edge, exactly at a
3-patch corner, at a pole and on the seam; depths from 1e-9 to 20 % of the radius."""
from __future__ import annotations

import os
import subprocess
import sys

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from nurbsdem.contact import ContactResult, ContactTable, detect, detect_batch
from nurbsdem.contact.lcp import F_N, F_SD, I_FAIL
from nurbsdem.geometry.generators import single_patch_sphere_patches, sphere
from nurbsdem.geometry.shape import Shape

R = 0.01
SPH = sphere(R)
# check=False: the shape check of the pole patch is being reworked elsewhere; the
# connectivity (poles, seam) is what the LCP needs
SP1 = Shape(single_patch_sphere_patches(R), name="single-patch sphere", check=False)
I3 = np.eye(3)
GAPS = [0.1, 1e-6, 0.0, -1e-9, -1e-6, -1e-3, -0.05, -0.2]   # relative to the radius
DIRS = {
    "interior": np.array([0.3, -0.2, 0.9]),
    "edge": np.array([1.0, 1.0, 0.0]),
    "edge_xz": np.array([1.0, 0.0, -1.0]),
    "corner": np.array([1.0, 1.0, 1.0]),
    "corner2": np.array([-1.0, 1.0, -1.0]),
}


def angle(a, b) -> float:
    """Angle between unit vectors (rad), accurate for small angles."""
    return float(np.linalg.norm(np.cross(a, b)))


def check(res: ContactResult, gap: float, d: np.ndarray, tol: float = 1e-10) -> None:
    assert not res.failed
    assert np.all(np.isfinite(res.gap))
    assert abs(res.signed_distance - gap) <= tol * R, (res.signed_distance, gap)
    assert angle(res.normal, d) <= 1e-8
    assert res.active == (res.signed_distance < 0)
    # gap vector along the normal (paper Eq. 4): n . g = -signed distance
    assert np.allclose(res.gap, -res.signed_distance * res.normal, atol=1e-10 * R)


def perturbed_previous(res: ContactResult, angle_rad: float, rng) -> ContactResult:
    """A fake previous solution whose direction is off by ``angle_rad`` (exercises the
    Newton iteration on the sphere, which a centred start on spheres skips)."""
    rf = res.row_f.copy()
    n = rf[F_N:F_N + 3]
    t = np.cross(n, rng.normal(size=3))
    t /= np.linalg.norm(t)
    rf[F_N:F_N + 3] = np.cos(angle_rad) * n + np.sin(angle_rad) * t
    return ContactResult.from_rows(rf, res.row_i)


@pytest.mark.parametrize("where", list(DIRS))
@pytest.mark.parametrize("gap", GAPS)
def test_six_patch_sphere_exact(where, gap):
    d = DIRS[where] / np.linalg.norm(DIRS[where])
    pose_b = ((2 * R + gap * R) * d, I3)
    res = detect(SPH, (np.zeros(3), I3), SPH, pose_b)
    check(res, gap * R, d)
    assert res.point_a == pytest.approx(R * d, abs=1e-11 * R)
    # the same from a previous direction 0.3 rad off: Newton on the direction sphere
    prev = perturbed_previous(res, 0.3, np.random.default_rng(1))
    res2 = detect(SPH, (np.zeros(3), I3), SPH, pose_b, previous=prev)
    check(res2, gap * R, d)


@pytest.mark.parametrize("gap", [0.05, -1e-9, -0.01, -0.2])
def test_random_rotations_six_patch(gap):
    rng = np.random.default_rng(7)
    for _ in range(20):
        d = rng.normal(size=3)
        d /= np.linalg.norm(d)
        ra, rb = Rotation.random(2, random_state=rng).as_matrix()
        c = rng.normal(size=3) * R
        res = detect(SPH, (c, ra), SPH, (c + (2 + gap) * R * d, rb))
        check(res, gap * R, d)


@pytest.mark.parametrize("gap", [0.1, -1e-9, -1e-4, -0.2])
@pytest.mark.parametrize("d", [(0, 0, 1), (0, 0, -1), (1, 0, 0), (1, 1e-9, 0), (1, -1e-9, 0),
                               (0.6, 0.0, 0.8), (0, 1, 0), (0.3, 0.1, -0.9)])
def test_single_patch_sphere_pole_and_seam(gap, d):
    """Poles (±z: a collapsed edge) and the seam (the meridian through +x, u = 0 = 1)."""
    d = np.asarray(d, float) / np.linalg.norm(d)
    res = detect(SP1, (np.zeros(3), I3), SP1, ((2 + gap) * R * d, I3))
    check(res, gap * R, d)
    prev = perturbed_previous(res, 0.2, np.random.default_rng(2))
    res2 = detect(SP1, (np.zeros(3), I3), SP1, ((2 + gap) * R * d, I3), previous=prev)
    check(res2, gap * R, d)


def test_single_patch_random_rotations():
    rng = np.random.default_rng(11)
    for _ in range(40):
        d = rng.normal(size=3)
        d /= np.linalg.norm(d)
        gap = rng.uniform(-0.2, 0.05)
        ra, rb = Rotation.random(2, random_state=rng).as_matrix()
        res = detect(SP1, (np.zeros(3), ra), SPH, ((2 + gap) * R * d, rb))
        check(res, gap * R, d)


def test_bounding_spheres_reject_far_pairs():
    res = detect(SPH, (np.zeros(3), I3), SPH, (np.array([0.0, 0.0, 3.0 * R]), I3))
    assert res.broad_rejected and not res.active and res.signed_distance > 0
    assert res.iterations == 0


def test_warm_start_is_cheap():
    """Warm start from the previous step's solution: 1–2 Newton steps (+ the final check)."""
    rng = np.random.default_rng(3)
    d = np.array([0.2, 0.5, 0.8])
    d /= np.linalg.norm(d)
    ra, rb = Rotation.random(2, random_state=rng).as_matrix()
    prev = detect(SPH, (np.zeros(3), ra), SPH, (1.99 * R * d, rb))
    d2 = d + 1e-3 * rng.normal(size=3)
    d2 /= np.linalg.norm(d2)
    small = Rotation.from_rotvec([1e-3, 0, 0]).as_matrix()
    res = detect(SPH, (np.zeros(3), small @ ra), SPH, (1.98 * R * d2, rb), previous=prev)
    check(res, -0.02 * R, d2)
    assert res.iterations <= 3


def test_concentric_never_aborts():
    """Degenerate input (coincident centres): no exception, no NaN."""
    res = detect(SPH, (np.zeros(3), I3), SPH, (np.zeros(3), I3))
    assert np.all(np.isfinite(res.row_f))
    assert res.signed_distance == pytest.approx(-2 * R, rel=1e-9)


def test_batch_matches_single():
    rng = np.random.default_rng(5)
    table = ContactTable([SPH, SP1])
    K = 50
    d = rng.normal(size=(K, 3))
    d /= np.linalg.norm(d, axis=1)[:, None]
    gap = rng.uniform(-0.2, 0.05, K) * R
    rot_a = Rotation.random(K, random_state=rng).as_matrix()
    rot_b = Rotation.random(K, random_state=rng).as_matrix()
    sa = rng.integers(0, 2, K)
    sb = rng.integers(0, 2, K)
    f, i = detect_batch(table, sa, np.zeros((K, 3)), rot_a, sb, (2 * R + gap)[:, None] * d, rot_b)
    assert not i[:, I_FAIL].any()
    assert np.abs(f[:, F_SD] - gap).max() <= 1e-10 * R
    assert np.max(np.linalg.norm(np.cross(f[:, F_N:F_N + 3], d), axis=1)) <= 1e-8


def test_plain_python_path():
    """NUMBA_DISABLE_JIT=1 runs the same kernels as plain Python."""
    code = (
        "import numpy as np\n"
        "from nurbsdem.geometry.generators import sphere\n"
        "from nurbsdem.contact import detect\n"
        "s = sphere(1.0); d = np.array([1.0, 2.0, 2.0]) / 3\n"
        "r = detect(s, (np.zeros(3), np.eye(3)), s, (1.9 * d, np.eye(3)))\n"
        "assert abs(r.signed_distance + 0.1) < 1e-12 and not r.failed, r\n"
        "print('ok')\n")
    env = dict(os.environ, NUMBA_DISABLE_JIT="1")
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True,
                         timeout=300)
    assert out.returncode == 0, out.stderr[-2000:]
    assert "ok" in out.stdout

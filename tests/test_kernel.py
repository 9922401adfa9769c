"""NURBS kernel: vectorised and compiled paths against each other and finite differences."""
import numpy as np
import pytest

from nurbsdem.geometry.kernel import PatchPool, make_workspace, patch_derivs
from nurbsdem.geometry.nurbs import Patch, basis_functions_derivs
from nurbsdem.geometry.generators import (ellipsoid_patches, single_patch_sphere_patches,
                                          sphere_patches)


def random_patch(rng, p, q, nu, nv, rational=True):
    def knots(deg, n):
        inner = np.sort(rng.uniform(0.0, 2.0, n - deg - 1))
        return np.r_[[0.0] * (deg + 1), inner, [2.0] * (deg + 1)]
    w = rng.uniform(0.3, 3.0, (nu, nv)) if rational else None
    return Patch(p, q, knots(p, nu), knots(q, nv), rng.normal(size=(nu, nv, 3)), w)


PATCHES = [(3, 3, 6, 6), (2, 4, 5, 7), (1, 1, 2, 2), (1, 3, 3, 5), (4, 4, 5, 5), (5, 2, 9, 4)]


@pytest.mark.parametrize("pq", PATCHES)
def test_compiled_equals_vectorised(pq):
    rng = np.random.default_rng(hash(pq) % 2**32)
    patch = random_patch(rng, *pq)
    patch.validate()
    u = rng.uniform(0, 2, 500)
    v = rng.uniform(0, 2, 500)
    vec = patch.evaluate(u, v, 2)
    comp = PatchPool.from_patches([patch]).evaluate(0, u, v, 2)
    scale = np.abs(vec).max()
    assert np.abs(vec - comp).max() <= 1e-12 * scale


@pytest.mark.parametrize("pq", PATCHES)
def test_derivatives_against_finite_differences(pq):
    """First and second derivatives against central differences of the lower order (1e-7 rel)."""
    rng = np.random.default_rng(7 + sum(pq))
    patch = random_patch(rng, *pq)
    # stay away from knots (derivatives jump there) by evaluating mid-span
    ku = np.unique(patch.knots_u)
    kv = np.unique(patch.knots_v)
    u = 0.5 * (ku[:-1] + ku[1:])
    v = 0.5 * (kv[:-1] + kv[1:])
    U, V = [a.ravel() for a in np.meshgrid(u, v, indexing="ij")]
    h = 1e-5
    d = patch.evaluate(U, V, 2)
    du = (patch.evaluate(U + h, V, 1) - patch.evaluate(U - h, V, 1)) / (2 * h)
    dv = (patch.evaluate(U, V + h, 1) - patch.evaluate(U, V - h, 1)) / (2 * h)
    pairs = [(du[:, 0], d[:, 1]), (dv[:, 0], d[:, 2]), (du[:, 1], d[:, 3]),
             (dv[:, 1], d[:, 4]), (du[:, 2], d[:, 4]), (dv[:, 2], d[:, 5])]
    for fd, exact in pairs:
        scale = max(np.abs(exact).max(), 1.0)
        assert np.abs(fd - exact).max() <= 1e-7 * scale


def _repeated_knot_patch(rng, p, n):
    """A rational patch of degree p with an interior knot of multiplicity 2 in u and one of
    multiplicity p in v (empty spans in the power table, a C0 line in v)."""
    ku = np.r_[[0.0] * (p + 1), 0.5, 0.5, np.sort(rng.uniform(0.6, 2.0, n - p - 3)), [2.0] * (p + 1)]
    kv = np.r_[[0.0] * (p + 1), [0.9] * p, np.sort(rng.uniform(1.0, 2.0, n - 2 * p - 1)), [2.0] * (p + 1)]
    return Patch(p, p, ku, kv, rng.normal(size=(n, n, 3)), rng.uniform(0.3, 3.0, (n, n)))


POWER_PATCHES = PATCHES + [(9, 9, 12, 12), (7, 6, 10, 9)]


@pytest.mark.parametrize("pq", POWER_PATCHES)
def test_power_form_equals_a2_3(pq):
    """The contact kernels' power form (Taylor polynomials about each span's centre) against
    A2.3's compiled path: S and its derivatives to second order within 1e-13 of the largest
    value, at random parameters, at every knot, at the ends and beyond them (clamped)."""
    rng = np.random.default_rng(sum(pq) + 100)
    patch = random_patch(rng, *pq)
    patch.validate()
    knots = np.r_[patch.knots_u, patch.knots_v]
    u = np.r_[rng.uniform(0, 2, 400), knots, -0.3, 2.4, 0.0, 2.0]
    v = np.r_[rng.uniform(0, 2, 400), knots[::-1], 2.4, -0.3, 2.0, 0.0]
    pool = PatchPool.from_patches([patch])
    for order in (0, 1, 2):
        ref = pool.evaluate(0, u, v, order)
        power = pool.evaluate(0, u, v, order, power=True)
        rows = (1, 3, 6)[order]
        scale = np.abs(ref[:, :rows]).max()
        assert np.abs(power[:, :rows] - ref[:, :rows]).max() <= 1e-13 * scale


def test_power_form_with_repeated_knots_and_exact_shapes():
    """Repeated interior knots (empty spans, never evaluated) and the exact sphere and
    ellipsoid faces: the power form on the points of A2.3 within 1e-13 relative, and on the
    exact surface (|S| = r, the ellipsoid's equation) to 1e-13."""
    rng = np.random.default_rng(21)
    patch = _repeated_knot_patch(rng, 3, 9)
    patch.validate()
    u = np.r_[rng.uniform(0, 2, 300), 0.5, 0.9]
    v = np.r_[rng.uniform(0, 2, 300), 0.9, 0.5]
    pool = PatchPool.from_patches([patch])
    ref, power = pool.evaluate(0, u, v, 2), pool.evaluate(0, u, v, 2, power=True)
    assert np.abs(power - ref).max() <= 1e-13 * np.abs(ref).max()
    a = np.array([0.03, 0.02, 0.011])
    for patches, check in ((sphere_patches(0.7), lambda x: np.linalg.norm(x, axis=1) / 0.7),
                           (ellipsoid_patches(*a), lambda x: np.linalg.norm(x / a, axis=1))):
        pool = PatchPool.from_patches(patches)
        for ip, pt in enumerate(patches):
            u0, u1, v0, v1 = pt.domain
            uu, vv = rng.uniform(u0, u1, 500), rng.uniform(v0, v1, 500)
            ref, power = pool.evaluate(ip, uu, vv, 2), pool.evaluate(ip, uu, vv, 2, power=True)
            assert np.abs(power - ref).max() <= 1e-13 * np.abs(ref).max()
            assert np.abs(check(power[:, 0]) - 1.0).max() < 1e-13


def test_contact_table_evaluates_the_power_form_of_its_shapes():
    """What the LCP evaluates (support.evaluate on a ContactTable of two shapes, global patch
    indices) is each shape's own patch, point and derivatives within 1e-13 relative."""
    from nurbsdem.contact import support
    from nurbsdem.contact.detect import ContactTable
    from nurbsdem.geometry.generators import ellipsoid, sphere
    shapes = [sphere(0.4), ellipsoid(0.03, 0.02, 0.011)]
    table = ContactTable(shapes)
    rng = np.random.default_rng(5)
    ws, out = make_workspace(), np.zeros((6, 3))
    for k, sh in enumerate(shapes):
        first = table.info[k, 0]
        for ip, pt in enumerate(sh.patches):
            u0, u1, v0, v1 = pt.domain
            for u, v in zip(rng.uniform(u0, u1, 20), rng.uniform(v0, v1, 20)):
                support.evaluate(table.tab, first + ip, u, v, 2, ws, out)
                ref = pt.evaluate(np.array([u]), np.array([v]), 2)[0]
                assert np.abs(out - ref).max() <= 1e-13 * np.abs(ref).max()


def test_patches_with_a_pole_keep_a2_3_in_the_contact_table():
    """A patch with a collapsed edge (the single-patch sphere's poles) is evaluated by A2.3
    (poff -1): there the Taylor form's round-off turned the LCP's normal by 1e-10 rad
    (test_contact_spheres' pole cases); the Cobb sphere's patches use the power form."""
    from nurbsdem.contact.detect import ContactTable
    from nurbsdem.geometry.generators import sphere
    from nurbsdem.geometry.shape import Shape
    poles = Shape(single_patch_sphere_patches(0.01), name="poles", check=False)
    table = ContactTable([sphere(0.01), poles])
    poff = table.tab[9]
    assert (poff[:6] >= 0).all() and (poff[6:] == -1).all()


def test_basis_partition_of_unity_and_derivative_sum():
    rng = np.random.default_rng(3)
    knots = np.r_[[0.0] * 4, np.sort(rng.uniform(0, 1, 5)), [1.0] * 4]
    t = rng.uniform(0, 1, 100)
    _, ders = basis_functions_derivs(knots, 3, t, 2)
    assert np.allclose(ders[:, 0].sum(1), 1.0, atol=1e-14)
    assert np.allclose(ders[:, 1].sum(1), 0.0, atol=1e-11)
    assert np.allclose(ders[:, 2].sum(1), 0.0, atol=1e-9)


def test_endpoints_are_evaluated_on_the_last_span():
    patch = random_patch(np.random.default_rng(5), 3, 3, 6, 6)
    corner = patch.points(2.0, 2.0)
    w = patch.weights[-1, -1]
    assert np.allclose(corner, patch.control_points[-1, -1], atol=1e-14 / w)
    comp = PatchPool.from_patches([patch]).evaluate(0, [2.0], [2.0], 0)[0, 0]
    assert np.allclose(comp, corner, atol=1e-14)


def test_scalar_kernel_clamps_outside_parameters():
    patch = random_patch(np.random.default_rng(9), 3, 3, 6, 6)
    pool = PatchPool.from_patches([patch])
    ws, out = make_workspace(), np.zeros((6, 3))
    patch_derivs(*pool.arrays, 0, -0.5, 2.5, 2, ws, out)
    assert np.allclose(out[0], patch.points(0.0, 2.0), atol=1e-13)


@pytest.mark.parametrize("radius", [1e-3, 1.0, 37.0])
def test_exact_sphere_points_at_radius(radius):
    rng = np.random.default_rng(11)
    for patches in (sphere_patches(radius), single_patch_sphere_patches(radius)):
        for p in patches:
            u0, u1, v0, v1 = p.domain
            x = p.points(rng.uniform(u0, u1, 4000), rng.uniform(v0, v1, 4000))
            assert np.abs(np.linalg.norm(x, axis=1) / radius - 1).max() < 1e-12


def test_exact_ellipsoid_points_and_outward_normals():
    rng = np.random.default_rng(12)
    a = np.array([0.03, 0.02, 0.011])
    for p in ellipsoid_patches(*a):
        u, v = rng.uniform(0, 1, 3000), rng.uniform(0, 1, 3000)
        d = p.evaluate(u, v, 1)
        x = d[:, 0]
        assert np.abs(np.linalg.norm(x / a, axis=1) - 1).max() < 1e-12
        n = np.cross(d[:, 1], d[:, 2])
        grad = x / a**2  # outward normal of the implicit surface
        cosang = np.einsum("ij,ij->i", n, grad) / np.linalg.norm(n, axis=1) / np.linalg.norm(grad, axis=1)
        assert cosang.min() > 1 - 1e-12


# --------------------------------------------------------------------------- compilation
def test_hot_kernels_compile_without_reference_counting():
    """The LCP's kernels are compiled by nurbsdem.jit.kernel (no NRT: no atomic reference
    counts on every view of a workspace or shape table); the evaluation still matches the
    vectorised path above, so only the counting is gone."""
    from nurbsdem.contact import lcp, support
    from nurbsdem.jit import kernel
    for f in (patch_derivs, support.support_map, lcp.solve_pair):
        assert f.targetoptions.get("_nrt") is False, f.__name__
    with pytest.raises(Exception, match="zeros"):      # a kernel may not allocate
        kernel(lambda n: np.zeros(n))(3)


def test_threading_layer_is_openmp_where_there_else_work_queue():
    """Importing nurbsdem before numba picks OpenMP for the parallel LCP batches where the
    GNU OpenMP runtime is installed, else numba's work queue; never TBB (see nurbsdem/__init__)."""
    import ctypes
    import os
    import subprocess
    import sys
    code = ("import nurbsdem, numba, numpy as np\n"
            "@numba.njit(parallel=True)\n"
            "def total(x):\n"
            "    s = 0.0\n"
            "    for i in numba.prange(x.size):\n"
            "        s += x[i]\n"
            "    return s\n"
            "assert total(np.ones(64)) == 64.0\n"
            "print(numba.threading_layer())\n")
    env = {k: v for k, v in os.environ.items() if not k.startswith("NUMBA_THREADING_LAYER")}
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True,
                         check=True).stdout.split()[-1]
    try:
        ctypes.CDLL("libgomp.so.1")
        expected = "omp"
    except OSError:
        expected = "workqueue"
    assert out == expected


# --------------------------------------------------------------------------- unrolled basis
def test_unrolled_basis_module_is_what_the_generator_writes():
    from nurbsdem.geometry import basis_codegen
    assert basis_codegen.TARGET.read_text() == basis_codegen.module_source()


@pytest.mark.parametrize("p", [2, 3])
def test_unrolled_basis_equals_a2_3_to_the_bit(p):
    """The straight-line basis of degrees 2 and 3 (used by patch_derivs) performs A2.3's
    operations in its order: the same bits as the general routine, for random non-uniform
    knots with repeated interior knots, at random parameters, at knots and at the ends."""
    from nurbsdem.geometry import _basis_unrolled as unrolled
    from nurbsdem.geometry.kernel import basis_ders, find_span
    rng = np.random.default_rng(p)
    for trial in range(20):
        n = p + 1 + int(rng.integers(0, 6))
        inner = np.sort(rng.uniform(0.0, 2.0, n - p - 1))
        if inner.size > 1 and trial % 3 == 0:
            inner[1] = inner[0]                                    # a repeated knot
        knots = np.r_[[0.0] * (p + 1), inner, [2.0] * (p + 1)]
        ts = np.r_[rng.uniform(0.0, 2.0, 40), knots, 0.0, 2.0]
        for nd in (0, 1, 2):
            fast = getattr(unrolled, f"basis_ders_{p}_{nd}")
            for t in ts:
                span = find_span(knots, 0, n, p, t)
                ref = np.zeros((3, 10))
                ws = np.zeros((16, 10))
                basis_ders(knots, 0, span, p, t, nd, ws[:10], ws[10:12], ws[12], ws[13], ref)
                got = np.zeros((3, 10))
                fast(knots, 0, span, t, got)
                assert np.array_equal(got[:nd + 1], ref[:nd + 1]), (p, nd, t)


def test_cycle_counter_times_a_compiled_loop():
    """nurbsdem.jit.cycles (the split of a compiled deck step's time): ticks converted by
    seconds_per_cycle agree with perf_counter over a busy interval (x86-64; elsewhere 0)."""
    import time

    from nurbsdem.jit import HAS_CYCLE_COUNTER, _cycles_now, seconds_per_cycle
    if not HAS_CYCLE_COUNTER:
        assert _cycles_now() == 0 and seconds_per_cycle() == 0.0
        return
    c0, t0 = _cycles_now(), time.perf_counter()
    while time.perf_counter() - t0 < 0.05:
        pass
    c1, t1 = _cycles_now(), time.perf_counter()
    assert (c1 - c0) * seconds_per_cycle() == pytest.approx(t1 - t0, rel=0.05)

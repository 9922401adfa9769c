"""The paper's particles A, B, C (nurbsdem.geometry.particles and inputs/shapes/*.yaml)."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import nurbsdem
from nurbsdem.geometry import particles
from nurbsdem.geometry.mass import mass_properties, second_moment_from_inertia
from nurbsdem.io.shapefile import read_patches

SHAPES = Path(__file__).resolve().parents[1] / "inputs" / "shapes"
KINDS = ("A", "B", "C")
DENSITY = 2700.0


@pytest.fixture(scope="module")
def loaded():
    return {k: nurbsdem.load_shape(SHAPES / f"{k}.yaml") for k in KINDS}


def frob_rel(a, b) -> float:
    return float(np.linalg.norm(a - b) / np.linalg.norm(b))


@pytest.mark.parametrize("kind", KINDS)
def test_volume_and_inertia_match_table1(loaded, kind):
    shape = loaded[kind]
    V, J = particles.TABLE1[kind]
    assert shape.name == kind
    assert abs(shape.volume / V - 1) < 0.01
    assert frob_rel(shape.inertia * DENSITY, J) < 0.02
    assert np.linalg.norm(shape.centroid) < 1e-12


def test_particle_a_matches_its_targets_to_quadrature_accuracy(loaded):
    """A's volume and inertia are constructed to match, not merely within tolerance."""
    shape = loaded["A"]
    assert abs(shape.volume / particles.VOLUME_A - 1) < 1e-9
    assert frob_rel(shape.inertia * DENSITY, particles.INERTIA_A) < 1e-9


def test_tuned_epsilon_matches_target_invariant():
    patches = particles._patches_from_table(particles._base_points(particles.EPSILON))
    v, _, j = mass_properties(patches)
    inv = particles.affine_invariant(v, second_moment_from_inertia(j))
    target = particles.affine_invariant(
        particles.VOLUME_A, second_moment_from_inertia(particles.INERTIA_A / DENSITY))
    assert abs(inv / target - 1) < 1e-9


def test_scaling_relation(loaded):
    a = loaded["A"]
    for kind, s in (("B", 0.8), ("C", 0.6)):
        x = loaded[kind]
        for pa, px in zip(a.patches, x.patches):
            assert np.allclose(px.control_points, s * pa.control_points, rtol=1e-14, atol=1e-18)
        assert abs(x.volume / (s ** 3 * a.volume) - 1) < 1e-12
        assert frob_rel(x.inertia, s ** 5 * a.inertia) < 1e-12


@pytest.mark.parametrize("kind", KINDS)
def test_structure(kind):
    patches, name = read_patches(SHAPES / f"{kind}.yaml")
    assert name == kind and len(patches) == 6
    for p in patches:
        assert (p.degree_u, p.degree_v) == (3, 3)
        assert p.shape == (6, 6)
        assert p.domain == (0.0, 2.0, 0.0, 2.0)
        assert np.all(p.weights == 1.0)


@pytest.mark.parametrize("kind", KINDS)
def test_files_are_what_the_generator_makes(kind):
    patches, _ = read_patches(SHAPES / f"{kind}.yaml")
    fresh = particles.paper_particle(kind)
    for p, q in zip(patches, fresh):
        assert np.array_equal(p.knots_u, q.knots_u) and np.array_equal(p.knots_v, q.knots_v)
        # reproducible to rounding (LAPACK may differ in the last bits between machines)
        assert np.allclose(p.control_points, q.control_points, rtol=1e-12, atol=1e-17)


def test_write_round_trip(tmp_path):
    paths = particles.write_paper_particles(tmp_path)
    assert [p.name for p in paths] == ["A.yaml", "B.yaml", "C.yaml"]
    back, name = read_patches(paths[0])
    assert name == "A"
    for p, q in zip(back, particles.paper_particle("A")):
        assert np.array_equal(p.control_points, q.control_points)


def _boundary_rows(cp: np.ndarray) -> list[np.ndarray]:
    return [cp[0], cp[-1], cp[:, 0], cp[:, -1]]


@pytest.mark.parametrize("kind", KINDS)
def test_edges_shared_bit_identically(kind):
    """Every boundary control row equals (bitwise, possibly reversed) one row of another patch."""
    patches, _ = read_patches(SHAPES / f"{kind}.yaml")
    rows = [(i, r) for i, p in enumerate(patches) for r in _boundary_rows(p.control_points)]
    for i, r in rows:
        matches = [j for j, s in rows
                   if j != i and (np.array_equal(r, s) or np.array_equal(r, s[::-1]))]
        assert len(matches) == 1
    # corners: each distinct corner point is on exactly 3 patches
    corners = [tuple(p.control_points[i, j]) for p in patches for i in (0, -1) for j in (0, -1)]
    _, counts = np.unique(np.array(corners), axis=0, return_counts=True)
    assert len(counts) == 8 and np.all(counts == 3)


def _samples(patches, n: int = 41):
    t = np.linspace(0.0, 2.0, n)
    U, V = np.meshgrid(t, t, indexing="ij")
    pts, nrm = [], []
    for p in patches:
        pts.append(p.points(U, V).reshape(-1, 3))
        nrm.append(p.normals(U, V).reshape(-1, 3))
    return np.concatenate(pts), np.concatenate(nrm)


@pytest.mark.parametrize("kind", KINDS)
def test_outward_and_convex_by_sampling(loaded, kind):
    """Independent check: every sampled point lies on the inner side of every sampled
    tangent plane (sampled points include the patch edges and corners)."""
    shape = loaded[kind]
    pts, nrm = _samples(shape.patches)
    assert np.all(np.einsum("ij,ij->i", pts - shape.centroid, nrm) > 0)
    size = np.linalg.norm(pts.max(0) - pts.min(0))
    worst = -np.inf
    for k in range(0, len(pts), 500):
        h = np.einsum("kj,mj->km", nrm[k:k + 500], pts) - np.einsum("kj,kj->k", nrm[k:k + 500],
                                                                     pts[k:k + 500])[:, None]
        worst = max(worst, h.max())
    assert worst < 1e-12 * size


def test_strictly_convex_interior_curvature(loaded):
    """Second fundamental form negative definite (outward normal) on a dense grid."""
    t = np.linspace(0.0, 2.0, 31)
    U, V = np.meshgrid(t, t, indexing="ij")
    for p in loaded["A"].patches:
        d = p.evaluate(U, V, 2)
        n = np.cross(d[..., 1, :], d[..., 2, :])
        n /= np.linalg.norm(n, axis=-1, keepdims=True)
        L, M, N = ((d[..., k, :] * n).sum(-1) for k in (3, 4, 5))
        assert np.all(L < 0) and np.all(N < 0) and np.all(L * N - M * M > 0)


def test_semi_axes_roughly_as_in_paper(loaded):
    """The equivalent ellipsoid of A has semi-axes ≈ 3.24 × 2.91 × 2.51 cm."""
    s = loaded["A"]
    lam = np.linalg.eigvalsh(second_moment_from_inertia(s.inertia))
    axes = np.sort(np.sqrt(5.0 * lam / s.volume))[::-1]
    assert np.allclose(axes, [0.0324, 0.0291, 0.0251], rtol=0.01)


def test_unknown_kind():
    with pytest.raises(ValueError):
        particles.paper_particle("D")

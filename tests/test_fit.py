"""``nurbsdem fit``: six-patch cube-sphere least-squares fit to meshes and point clouds.

References: the exact ellipsoid (semi-axes 30, 20, 12 mm) — its analytic volume and the
distance of the fitted surface to it (first-order distance |F - 1| / |grad F| of
F(x) = |x / a|, exact to O(d^2)); the fitted surface's own geometry (normals across the edges);
an independent dense-sampling distance for the reported fit error.
"""
from __future__ import annotations

import numpy as np
import pytest
from click.testing import CliRunner
from scipy.spatial import cKDTree

from nurbsdem.cli import main
from nurbsdem.errors import InputError
from nurbsdem.geometry.connectivity import edge_uv
from nurbsdem.geometry.fit import FitInput, fit_particle, read_input
from nurbsdem.io.shapefile import load_shape

trimesh = pytest.importorskip("trimesh")

AX = np.array([0.03, 0.02, 0.012])
V_EXACT = 4.0 / 3.0 * np.pi * AX.prod()


def ellipsoid_mesh(subdivisions: int):
    """Icosphere mapped onto the ellipsoid: every vertex exactly on it."""
    m = trimesh.creation.icosphere(subdivisions=subdivisions)
    m.apply_scale(AX)
    return m


def error_to_ellipsoid(shape, n: int = 40) -> tuple[float, float]:
    """(max, RMS) distance (m) of surface samples (n x n per patch) to the exact ellipsoid."""
    X = []
    for p in shape.patches:
        t = np.linspace(0.0, 2.0, n)
        U, V = np.meshgrid(t, t, indexing="ij")
        X.append(p.points(U.ravel(), V.ravel()))
    X = np.concatenate(X)
    y = X / AX
    F = np.linalg.norm(y, axis=1)
    g = np.linalg.norm(y / AX, axis=1) / F
    e = np.abs((F - 1.0) / g)
    return float(e.max()), float(np.sqrt(np.mean(e ** 2)))


_cache: dict = {}


def fitted(sub: int, n_cp: int):
    key = (sub, n_cp)
    if key not in _cache:
        m = ellipsoid_mesh(sub)
        _cache[key] = fit_particle(FitInput(np.asarray(m.vertices), m, "ellipsoid"), n_cp=n_cp)
    return _cache[key]


def test_error_falls_with_mesh_resolution_and_volume_within_half_percent():
    errs = []
    for sub in (2, 3, 4):              # 162, 642, 2562 vertices
        r = fitted(sub, 8)
        emax, erms = error_to_ellipsoid(r.shape)
        errs.append(emax / r.size)
        assert abs(r.shape.volume / V_EXACT - 1.0) < 5e-3
        assert r.err_max / r.size < 3e-3
        assert r.shape.convexity.relative <= 1e-4
    assert errs[0] > errs[1] > errs[2]
    assert errs[2] < 5e-4


def test_error_falls_with_control_net_size():
    maxs, rmss = [], []
    for n_cp in (6, 8, 10):
        r = fitted(4, n_cp)
        emax, erms = error_to_ellipsoid(r.shape)
        maxs.append(emax / r.size)
        rmss.append(erms / r.size)
        assert abs(r.shape.volume / V_EXACT - 1.0) < 5e-4
        # the mesh's own mass properties: the inscribed polyhedron, slightly smaller
        assert r.volume_mesh is not None and r.volume_mesh < V_EXACT
    assert maxs[0] > maxs[1] > maxs[2] and rmss[0] > rmss[1] > rmss[2]
    assert rmss[2] < 5e-5


def test_reported_error_agrees_with_dense_sampling():
    """The reported max distance (Newton closest points) against the nearest of a dense
    sample: never larger, and larger by at most the sample spacing."""
    r = fitted(4, 8)
    m = ellipsoid_mesh(4)
    X, spacing = [], 0.0
    for p in r.shape.patches:
        t = np.linspace(0.0, 2.0, 300)
        U, V = np.meshgrid(t, t, indexing="ij")
        G = p.points(U.ravel(), V.ravel()).reshape(300, 300, 3)
        spacing = max(spacing, np.linalg.norm(np.diff(G, axis=0), axis=2).max(),
                      np.linalg.norm(np.diff(G, axis=1), axis=2).max())
        X.append(G.reshape(-1, 3))
    d, _ = cKDTree(np.concatenate(X)).query(m.vertices)
    assert r.err_max <= d.max() + 1e-12
    assert d.max() <= np.hypot(r.err_max, spacing)
    assert r.err_rms <= r.err_max


def test_g1_on_middle_spans_and_small_kinks():
    """C1 across the middle knot span of every edge (normals of both patches agree there);
    the kinks left next to the corners are small and reported."""
    r = fitted(4, 8)
    sh = r.shape
    conn = sh.connectivity
    s = np.linspace(0.4, 0.6, 5)          # inside the middle spans (8 cp: spans of 2/5)
    for i, p in enumerate(sh.patches):
        for e in range(4):
            j, f, rev = conn.neighbours[i, e]
            u, v = edge_uv(p.domain, e, s)
            uj, vj = edge_uv(sh.patches[j].domain, f, 1.0 - s if rev else s)
            a = p.normals(u, v)
            b = sh.patches[j].normals(uj, vj)
            a /= np.linalg.norm(a, axis=1)[:, None]
            b /= np.linalg.norm(b, axis=1)[:, None]
            assert np.all(np.einsum("ki,ki->k", a, b) > 1 - 1e-12)
    assert 0.0 < r.kink_deg < 5.0
    assert len(conn.corners) == 8 and conn.closed


def test_noisy_point_cloud_cli(tmp_path):
    """XYZ text with noise: the hull is taken first (and said); the error is of the order
    of the noise; volume and inertia compared with the hull."""
    rng = np.random.default_rng(3)
    d = rng.normal(size=(3000, 3))
    d /= np.linalg.norm(d, axis=1)[:, None]
    pts = d * AX * (1.0 + 1e-3 * rng.normal(size=(3000, 1)))
    f = tmp_path / "cloud.xyz"
    np.savetxt(f, pts, header="x y z (m)")
    out = tmp_path / "cloud.yaml"
    r = CliRunner().invoke(main, ["fit", str(f), "-o", str(out), "--control-points", "6"])
    assert r.exit_code == 0, r.output
    assert "convex hull taken first" in r.output and "point cloud" in r.output
    assert "fit error" in r.output and "vs convex hull" in r.output
    sh = load_shape(out)
    assert abs(sh.volume / V_EXACT - 1.0) < 0.01


@pytest.mark.parametrize("suffix", [".stl", ".ply", ".obj"])
def test_mesh_formats_read(tmp_path, suffix):
    m = ellipsoid_mesh(2)
    f = tmp_path / f"e{suffix}"
    m.export(f)
    data = read_input(f)
    assert data.mesh is not None and len(data.points) == len(m.vertices)
    assert np.isclose(data.mesh.volume, m.volume, rtol=1e-6)


def test_nonconvex_mesh_fitted_to_its_hull():
    """Two overlapping spheres (a dumbbell): the fit is convex and holds the mesh."""
    a = trimesh.creation.icosphere(subdivisions=3, radius=0.01)
    b = a.copy()
    b.apply_translation([0.012, 0, 0])
    m = trimesh.util.concatenate([a, b])
    r = fit_particle(FitInput(np.asarray(m.vertices), None, "dumbbell"), n_cp=6)
    assert r.shape.convexity.relative <= 1e-4
    assert any("convex hull taken first" in n for n in r.notes)
    hull = trimesh.convex.convex_hull(m.vertices)
    assert abs(r.shape.volume / hull.volume - 1.0) < 0.05
    assert r.hull_err_max / r.size < 0.03


def test_bad_inputs_one_line(tmp_path):
    f = tmp_path / "bad.xyz"
    f.write_text("0 0 0\n1 0 0\n0 1 x\n")
    r = CliRunner().invoke(main, ["fit", str(f), "-o", str(tmp_path / "o.yaml")])
    assert r.exit_code == 2 and f"{f}:3: not a number" in r.output
    assert "Traceback" not in r.output
    f.write_text("0 0 0\n1 0 0\n0 1 0\n1 1 0\n")
    with pytest.raises(InputError, match="one plane"):
        read_input(f)
    g = tmp_path / "x.step"
    g.write_text("nothing")
    with pytest.raises(InputError, match="unknown file type"):
        read_input(g)
    h = tmp_path / "broken.stl"
    h.write_text("solid x\nfacet nonsense\n")
    r = CliRunner().invoke(main, ["fit", str(h), "-o", str(tmp_path / "o.yaml")])
    assert r.exit_code == 2 and str(h) in r.output and "Traceback" not in r.output


# ---------------------------------------------------------------------- the README's example
INPUTS = __import__("pathlib").Path(__file__).resolve().parent.parent / "inputs"


def test_shipped_grain_is_small_and_its_fit_reproducible(tmp_path):
    scan = INPUTS / "shapes" / "grain_scan.ply"
    assert scan.stat().st_size < 1_000_000
    data = read_input(scan)
    r = fit_particle(data, name="synthetic grain")
    shipped = load_shape(INPUTS / "shapes" / "grain.yaml")
    assert abs(r.shape.volume / shipped.volume - 1.0) < 1e-9
    # synthetic noise sigma = 15 um on a 38 mm grain: RMS error of the order of the noise
    assert r.err_rms < 3 * 15e-6 and r.err_max / r.size < 5e-3
    assert abs(r.shape.volume / r.volume_mesh - 1.0) < 0.01


def test_grain_deck_runs_briefly(tmp_path):
    deck = (INPUTS / "grain" / "drop_grains.inp").read_text()
    deck = deck.replace("File ../shapes/grain.yaml", f"File {INPUTS / 'shapes' / 'grain.yaml'}")
    deck = deck.replace("Duration 0.8", "Duration 0.01")
    f = tmp_path / "drop.inp"
    f.write_text(deck)
    r = CliRunner().invoke(main, ["solve", str(f), "--quiet", "--output", str(tmp_path / "out")])
    assert r.exit_code == 0, r.output
    energy = np.loadtxt(tmp_path / "out" / "monitors" / "energy.csv", delimiter=",", skiprows=1)
    assert energy[-1, 0] == pytest.approx(0.01)
    assert energy[-1, 1] > 0.0       # falling

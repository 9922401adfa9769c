"""Quad tessellation: grid layout, outward normals, area convergence on the exact sphere."""
from __future__ import annotations

import numpy as np
import pytest

from nurbsdem.geometry import generators as gen
from nurbsdem.geometry.tessellate import (parameter_grid, quad_areas_normals, tessellate_patch,
                                          tessellate_shape)


def test_grid_includes_knots_and_counts():
    k = np.array([0, 0, 0, 0, 2 / 3, 4 / 3, 2, 2, 2, 2.0])
    t = parameter_grid(k, 3, 6)
    assert t[0] == 0 and t[-1] == 2 and len(t) == 7
    assert all(np.any(np.isclose(t, x, rtol=0, atol=1e-15)) for x in (2 / 3, 4 / 3))
    # uneven spans: every span gets at least one interval, knots are grid lines
    k = np.array([0, 0, 0, 0.1, 1, 1, 1.0])
    t = parameter_grid(k, 2, 4)
    assert 0.1 in t and np.all(np.diff(t) > 0)
    pts, quads = tessellate_patch(gen.sphere_patches(1.0)[0], 5)
    assert pts.shape == (36, 3) and quads.shape == (25, 4) and quads.dtype == np.int64
    assert quads.max() == 35


def test_sphere_area_converges_to_4_pi_r2():
    r = 0.7
    exact = 4 * np.pi * r ** 2
    errs = []
    for n in (4, 8, 16, 32):
        pts, quads, pid = tessellate_shape(gen.sphere(r), n)
        assert quads.shape == (6 * n * n, 4) and np.array_equal(np.unique(pid), np.arange(6))
        area, _ = quad_areas_normals(pts, quads)
        errs.append(abs(area.sum() - exact) / exact)
    rates = np.log2(np.array(errs[:-1]) / np.array(errs[1:]))
    assert np.all(rates > 1.8)         # second order in h
    assert errs[-1] < 1e-3


@pytest.mark.parametrize("make", [lambda: gen.sphere(1.0), lambda: gen.ellipsoid(3, 2, 1),
                                  lambda: gen.single_patch_sphere(1.0)])
def test_quad_normals_point_outward(make):
    sh = make()
    pts, quads, _ = tessellate_shape(sh, 12)
    area, nrm = quad_areas_normals(pts, quads)
    good = area > 1e-12 * area.max()
    centre = pts[quads].mean(1)
    assert np.all(np.einsum("ij,ij->i", nrm[good], centre[good] - sh.centroid) > 0)


def test_single_patch_sphere_area():
    pts, quads, _ = tessellate_shape(gen.single_patch_sphere(1.0), 48)
    area, _ = quad_areas_normals(pts, quads)     # pole quads are triangles
    assert abs(area.sum() - 4 * np.pi) / (4 * np.pi) < 2e-3


def test_paper_particle_normals_outward():
    particles = pytest.importorskip("nurbsdem.geometry.particles")
    from nurbsdem.geometry.shape import Shape
    sh = Shape(particles.paper_particle("A"))
    pts, quads, pid = tessellate_shape(sh, 9)    # spans of 2/3: 3 quads per span
    assert len(quads) == 6 * 9 * 9
    area, nrm = quad_areas_normals(pts, quads)
    assert np.all(np.einsum("ij,ij->i", nrm, pts[quads].mean(1) - sh.centroid) > 0)
    assert np.all(np.isin(np.arange(6), pid))

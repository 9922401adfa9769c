"""The silo floor of benchmarks/bench_beverloo.py: a valid mesh wall, the square less the
orifice's polygon exactly (its area, its rim on the circle of diameter D, its fronts +z)."""
import math
import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
import bench_beverloo  # noqa: E402

from nurbsdem.io.meshfile import edge_use, read_wall_mesh  # noqa: E402


@pytest.mark.parametrize("segments", [8, 64])
def test_floor_with_orifice(tmp_path, segments):
    side, D = 0.1, 0.026
    path = tmp_path / "floor.stl"
    bench_beverloo.write_floor(path, side, D, segments)
    mesh = read_wall_mesh(path, one_sided=True)
    assert mesh.warnings == []
    v, f = mesh.vertices, mesh.faces
    a, b, c = v[f[:, 0]], v[f[:, 1]], v[f[:, 2]]
    normal = np.cross(b - a, c - a)
    assert np.all(normal[:, 2] > 0) and np.allclose(v[:, 2], 0.0)
    polygon = 0.5 * segments * (D / 2) ** 2 * math.sin(2 * math.pi / segments)
    # the area, to the float32 of an STL
    assert 0.5 * normal[:, 2].sum() == pytest.approx(side * side - polygon, rel=1e-6)
    edges, counts, _ = edge_use(f)
    rim = edges[counts == 1]                      # the boundary: the orifice and the square
    r = np.linalg.norm(v[:, :2], axis=1)
    inner = np.all(np.isclose(r[rim], D / 2, rtol=1e-6), axis=1)
    outer = np.all(np.isclose(np.abs(v[rim][:, :, :2]).max(axis=2), side / 2, rtol=1e-6),
                   axis=1)
    assert inner.sum() == segments and np.all(inner | outer)
    outside = r > D / 2 * (1 + 1e-6)                # the other vertices lie on the square
    assert np.abs(v[outside, :2]).max(axis=1) == pytest.approx(side / 2, rel=1e-6)
    with pytest.raises(ValueError):
        bench_beverloo.write_floor(path, side, D, 12)


@pytest.mark.parametrize("shape", bench_beverloo.SHAPES)
def test_the_grains_of_each_shape_have_the_spheres_volumes(tmp_path, shape):
    """The fill and discharge decks of each grain parse, and their three shapes have the
    volumes of the spheres of radii RADII (the paper's particles scaled to them)."""
    from nurbsdem.io.deck import parse_deck
    if shape == "paper":
        bench_beverloo.write_paper_shapes(tmp_path)
    bench_beverloo.write_floor(tmp_path / "floor.stl", 0.06, 0.024)
    fill, _ = bench_beverloo.fill_deck(0.06, 0.036, 300, shape)
    for name, text in (("fill", fill), ("discharge", bench_beverloo.discharge_deck(
            0.036, 0.06, 0.15, shape)), ("warm", bench_beverloo.warm_deck(shape))):
        (tmp_path / f"{name}.inp").write_text(text)
        model = parse_deck(tmp_path / f"{name}.inp", place=name != "discharge")
        volumes = [model.shapes[k].volume for k in sorted(model.shapes)]
        np.testing.assert_allclose(volumes, [4 / 3 * math.pi * r ** 3
                                             for r in bench_beverloo.RADII], rtol=1e-9)

"""Random placement (reproducible, non-overlapping), explicit overlaps, Replicate, rotations."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from nurbsdem import save_shape, shapes
from nurbsdem.errors import InputError
from nurbsdem.io.deck import parse_deck
from nurbsdem.geometry.rotation import (matrix_to_quat, quat_from_rotvec, quat_to_matrix,
                                        random_quaternions)
from nurbsdem.model import Bodies
from nurbsdem.placement import bodies_overlap, layer_thickness, replicate_layers, replicate_step

ROOT = Path(__file__).resolve().parents[1]

DECK = """\
Materials
  Material 1 Density 2700
Shapes
  Shape 1 File shapes/E.yaml
  Shape 2 Sphere Radius 0.012
  Shape 3 Ellipsoid SemiAxes 0.02 0.015 0.01
Particles
  Random 1 Shapes 1 2 3 Counts 5 3 6 Material 1 Region 0.01 0.01 0.01 0.24 0.24 0.24 Seed {seed}
Walls
  Box 1 Min 0 0 0 Max 0.25 0.25 0.6
Contact
  Interface 1 NormalPenalty 1e5
Steps
  Step 1 Dynamic Duration 1 TimeStep 1e-3
  Step 2 Replicate Layers 8 Height {height}
"""


@pytest.fixture(scope="module")
def deckdir(tmp_path_factory) -> Path:
    d = tmp_path_factory.mktemp("placement")
    (d / "shapes").mkdir()
    save_shape(d / "shapes" / "E.yaml", shapes.ellipsoid(0.0324, 0.0291, 0.0251, name="E"))
    return d


def _model(deckdir: Path, seed: int = 1, height: float = 0.5, name: str = "p.inp"):
    path = deckdir / name
    path.write_text(DECK.format(seed=seed, height=height))
    return parse_deck(path)


def _radii(m, b: Bodies) -> np.ndarray:
    return np.array([m.shapes[int(s)].bounding_radius for s in b.shape_id])


def test_random_is_reproducible(deckdir):
    a = _model(deckdir, seed=1).bodies
    b = _model(deckdir, seed=1).bodies
    c = _model(deckdir, seed=2).bodies
    for name in ("position", "quaternion", "id", "shape_id"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name))
    assert not np.allclose(a.position, c.position)


def test_random_is_inside_region_and_non_overlapping(deckdir):
    m = _model(deckdir, seed=3)
    b = m.bodies
    g = m.random_groups[0]
    assert list(b.id) == list(range(1, 15))
    assert list(b.shape_id) == [1] * 5 + [2] * 3 + [3] * 6
    r = _radii(m, b)
    assert np.all(b.position - r[:, None] >= g.region_lo - 1e-15)
    assert np.all(b.position + r[:, None] <= g.region_hi + 1e-15)
    d = np.linalg.norm(b.position[:, None] - b.position[None], axis=-1)
    np.fill_diagonal(d, np.inf)
    assert np.all(d >= r[:, None] + r[None])
    np.testing.assert_allclose(np.linalg.norm(b.quaternion, axis=1), 1.0)
    assert np.all(b.velocity == 0) and np.all(b.angular_velocity == 0)


def test_random_rotations_are_uniform():
    q = random_quaternions(np.random.default_rng(0), 20000)
    R = quat_to_matrix(q)
    # Haar measure: E[R] = 0 and E[R_ij^2] = 1/3
    assert np.abs(R.mean(axis=0)).max() < 0.02
    assert np.abs((R ** 2).mean(axis=0) - 1 / 3).max() < 0.02


def test_rotation_helpers_match_scipy():
    rng = np.random.default_rng(5)
    rv = rng.normal(size=(50, 3)) * 2
    rv[0] = 0.0
    rv[1] = [1e-10, 0, 0]
    q = quat_from_rotvec(rv)
    ref = Rotation.from_rotvec(rv).as_matrix()
    np.testing.assert_allclose(quat_to_matrix(q), ref, atol=1e-12)
    q2 = matrix_to_quat(ref)
    np.testing.assert_allclose(quat_to_matrix(q2), ref, atol=1e-12)
    assert np.all(q2[:, 0] >= 0)


def test_bodies_overlap_spheres():
    s = shapes.sphere(0.01)
    eye = np.eye(3)
    assert bodies_overlap(s, [0, 0, 0], eye, s, [0.019, 0, 0], eye)
    assert not bodies_overlap(s, [0, 0, 0], eye, s, [0.0201, 0, 0], eye)
    # ellipsoids: bounding spheres overlap, bodies do not
    e = shapes.ellipsoid(0.03, 0.01, 0.01)
    Rz = quat_to_matrix(quat_from_rotvec([0, 0, np.pi / 2]))
    assert not bodies_overlap(e, [0, 0, 0], eye, e, [0, 0.045, 0], eye)
    assert bodies_overlap(e, [0, 0, 0], eye, e, [0, 0.035, 0], Rz)


def test_replicate_14_to_112(deckdir):
    m = _model(deckdir, seed=1)
    b = m.bodies.copy()
    b.velocity[:] = 1.0
    b.angular_velocity[:] = 2.0
    out = replicate_layers(b, 8, 0.5)
    assert len(out) == 112
    assert len(set(out.id.tolist())) == 112 and out.id.min() == 1 and out.id.max() == 112
    np.testing.assert_array_equal(out.position[:14], b.position)
    for k in range(8):
        layer = out.take(slice(14 * k, 14 * (k + 1)))
        np.testing.assert_allclose(layer.position, b.position + [0, 0, k * 0.5 / 7])
        np.testing.assert_array_equal(layer.quaternion, b.quaternion)
        np.testing.assert_array_equal(layer.shape_id, b.shape_id)
    assert np.all(out.velocity == 0) and np.all(out.angular_velocity == 0)
    assert np.all(b.velocity == 1.0)  # input untouched


def test_replicate_step_checks_overlap(deckdir):
    m = _model(deckdir, seed=1, height=0.5, name="r1.inp")
    # the unsettled random layer is ~0.2 m thick: layers 0.071 m apart overlap
    with pytest.raises(InputError) as info:
        replicate_step(m, m.bodies, m.steps[1])
    msg = str(info.value)
    assert msg.startswith(f"{m.path}:15: Step 2: replicated layers overlap")
    assert "use Height >=" in msg
    t = layer_thickness(m.bodies, {k: e.shape for k, e in m.shapes.items()})
    m2 = _model(deckdir, seed=1, height=8 * t * 1.01, name="r2.inp")
    out = replicate_step(m2, m2.bodies, m2.steps[1])
    assert len(out) == 112


def test_bodies_container_roundtrip():
    b = Bodies(id=[3, 1], shape_id=[1, 1], material_id=[1, 1], position=np.zeros((2, 3)),
               quaternion=[[1, 0, 0, 0]] * 2, velocity=np.zeros((2, 3)),
               angular_velocity=np.zeros((2, 3)), line=[5, 6])
    assert list(b.sorted_by_id().id) == [1, 3]
    c = Bodies.from_dict(b.as_dict())
    np.testing.assert_array_equal(c.position, b.position)
    assert len(Bodies.concatenate([b, Bodies.empty(), b])) == 4


@pytest.mark.skipif(not (ROOT / "inputs/shapes/A.yaml").is_file(), reason="paper shapes missing")
def test_paper_deck_placement():
    m = parse_deck(ROOT / "inputs" / "paper" / "compaction.inp")
    b = m.bodies
    r = _radii(m, b)
    d = np.linalg.norm(b.position[:, None] - b.position[None], axis=-1)
    np.fill_diagonal(d, np.inf)
    assert np.all(d >= r[:, None] + r[None])
    assert np.all(b.position - r[:, None] >= 0.01 - 1e-12)
    assert np.all(b.position + r[:, None] <= 0.24 + 1e-12)


def _placed_by_python(model, group, obstacles):
    """The positions of a Random group as placed before the placement was compiled (a grid of
    Python lists, ``rng.uniform`` per attempt): the reference of the compiled one."""
    import math

    from nurbsdem.geometry.rotation import random_quaternions
    rng = np.random.default_rng(group.seed)
    shape_ids = np.repeat(np.array(group.shape_ids, np.int64), group.counts)
    n = len(shape_ids)
    radii = np.array([model.shapes[int(s)].bounding_radius for s in shape_ids])
    lo, hi = np.asarray(group.region_lo, float), np.asarray(group.region_hi, float)
    radii_all = np.concatenate([obstacles[1], radii])
    cell = 2.0 * float(radii_all.max())
    cells: dict = {}

    def key(c):
        return tuple(math.floor(v / cell) for v in c)

    def clear(c, r):
        i, j, k = key(c)
        for di in (-1, 0, 1):
            for dj in (-1, 0, 1):
                for dk in (-1, 0, 1):
                    for cx, cy, cz, rj in cells.get((i + di, j + dj, k + dk), ()):
                        dx, dy, dz = cx - c[0], cy - c[1], cz - c[2]
                        if math.sqrt(dx * dx + dy * dy + dz * dz) < rj + r:
                            return False
        return True

    for c, r in zip(obstacles[0], obstacles[1]):
        cells.setdefault(key(c), []).append((*map(float, c), float(r)))
    position = np.zeros((n, 3))
    random_quaternions(rng, n)
    for placed, k in enumerate(np.argsort(-radii, kind="stable")):
        r = radii[k]
        for _ in range(group.max_attempts):
            c = rng.uniform(lo + r, hi - r)
            if clear(c, float(r)):
                break
        else:
            return position, (placed, k)
        position[k] = c
        cells.setdefault(key(c), []).append((*map(float, c), float(r)))
    return position, None


@pytest.mark.parametrize("counts, attempts, seed, block", [
    ((5, 3, 6), 20000, 1, None), ((12, 20, 30), 20000, 4, 6), ((12, 20, 30), 20000, 6, None),
    ((40, 60, 90), 20000, 4, 9), ((40, 60, 90), 3, 5, None)])
def test_compiled_placement_has_the_bits_of_the_python_placement(deckdir, monkeypatch, counts,
                                                                 attempts, seed, block):
    """The compiled random placement (hash grid, uniform numbers drawn by the block) places
    every body where the Python placement did, to the bit, around obstacles, with blocks of
    draws that end between and within attempts, and fails at the same body with the same
    message where the region is too full."""
    from dataclasses import replace

    from nurbsdem import placement
    if block is not None:
        monkeypatch.setattr(placement, "_DRAW_BLOCK", block)
    m = _model(deckdir, seed=seed)
    full = counts == (40, 60, 90)           # too many for the region: fails
    group = replace(m.random_groups[0], counts=counts, max_attempts=attempts, seed=seed,
                    region_lo=np.array([0.0, 0.0, 0.0]),
                    region_hi=np.array([0.25, 0.25, 0.2]) if full else np.array([0.4, 0.4, 0.3]))
    obstacles = (np.array([[0.1, 0.1, 0.1], [0.3, 0.1, 0.05], [0.2, 0.2, 0.19]]),
                 np.array([0.03, 0.05, 0.02]))
    want, failed = _placed_by_python(m, group, obstacles)
    if failed is None:
        got = placement.place_random_group(m, group, obstacles).position
        assert np.array_equal(got.view(np.int64), want.view(np.int64))
    else:
        placed, k = failed
        with pytest.raises(InputError, match=rf"could not place particle {group.id + k} .* "
                                             rf"after {attempts} attempts \({placed} of"):
            placement.place_random_group(m, group, obstacles)
    assert (failed is not None) == full

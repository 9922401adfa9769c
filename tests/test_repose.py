"""postproc/repose.py against heaps of known angle: particles on a lattice filling a cone of
angle α (their tops under the cone's flank) give α back."""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "postproc"))
from repose import angle_of_repose  # noqa: E402


def _cone_heap(alpha_deg: float, foot: float = 0.1, d: float = 0.004, seed: int = 0):
    """Centres of spheres of diameter d on a jittered lattice under the flank
    z + d/2 <= (foot − r) tan α, with a floor layer out to the foot."""
    rng = np.random.default_rng(seed)
    g = np.arange(-foot, foot + d, d)
    x, y, z = np.meshgrid(g, g, np.arange(0.5 * d, foot, d), indexing="ij")
    p = np.column_stack([x.ravel(), y.ravel(), z.ravel()])
    p[:, :2] += rng.uniform(-0.2 * d, 0.2 * d, (len(p), 2))
    r = np.hypot(p[:, 0], p[:, 1])
    keep = (p[:, 2] + 0.5 * d <= (foot - r) * np.tan(np.radians(alpha_deg)) + 0.5 * d) & (r <= foot)
    return p[keep], 0.5 * d


@pytest.mark.parametrize("alpha", [15.0, 25.0, 35.0])
def test_a_lattice_cone_gives_its_angle_back(alpha):
    x, radius = _cone_heap(alpha)
    rep = angle_of_repose(x, radius, axis=(0.0, 0.0))
    assert rep.angle == pytest.approx(alpha, abs=1.5)
    assert rep.error < 1.5


def test_the_axis_defaults_to_the_heaps_centre_and_a_flat_layer_is_flat():
    x, radius = _cone_heap(25.0)
    x = x + [0.3, -0.2, 0.0]
    assert angle_of_repose(x, radius).angle == pytest.approx(25.0, abs=1.5)
    layer = x[x[:, 2] < 0.004]
    assert abs(angle_of_repose(layer, radius).angle) < 1.0


@pytest.mark.parametrize("beta", [-30.0, 0.0, 12.0, 35.0])
def test_a_tilted_circular_segment_gives_its_tilt(beta):
    """Points filling a circular segment of a drum (radius 0.1 m, 35 % full, axis x) whose
    chord is tilted by β: bed_angle returns β."""
    from repose import bed_angle
    rng = np.random.default_rng(1)
    g = np.arange(-0.1, 0.1, 0.001) + 0.0005
    p = np.stack(np.meshgrid(g, g, indexing="ij"), axis=-1).reshape(-1, 2)
    p = p[np.hypot(p[:, 0], p[:, 1]) < 0.1]
    b = np.radians(beta)
    height = p[:, 1] * np.cos(b) - p[:, 0] * np.sin(b)       # across the tilted chord
    bed = p[height < -0.03]
    x = np.column_stack([rng.uniform(-0.02, 0.02, len(bed)), bed])
    assert bed_angle(x) == pytest.approx(beta, abs=0.05)

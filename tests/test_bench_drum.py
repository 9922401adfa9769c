"""The drum of benchmarks/bench_drum.py with the paper's particles: its deck parses, each
particle has the volume of the sphere it replaces, and the placement keeps the particles'
bounding spheres apart and inside the drum."""
import math
import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
import bench_drum  # noqa: E402


def test_the_paper_drum_deck_holds_particles_of_the_spheres_volumes_apart(tmp_path):
    from nurbsdem.geometry.surfaces import cylinder_patch
    from nurbsdem.io.deck import parse_deck
    from nurbsdem.io.shapefile import save_shape
    save_shape(tmp_path / "drum.yaml", [cylinder_patch(bench_drum.R_DRUM, bench_drum.LENGTH,
                                                       axis=(0, 0, 1))])
    files = bench_drum.paper_shapes(tmp_path)
    clear = {r: v[1] for r, v in files.items()}
    full, kinds = bench_drum.place_lattice(800, clear)          # the benchmark's count fits
    assert len(full) == 800 and set(kinds.tolist()) == set(bench_drum.RADII)
    pos, rad = bench_drum.place_lattice(24, clear)
    rb = np.array([clear[float(r)] for r in rad])
    for x, r in ((full, np.full(800, max(clear.values()))), (pos, rb)):
        gap = np.linalg.norm(x[:, None] - x[None], axis=2) - r[:, None] - r[None]
        assert gap[~np.eye(len(x), dtype=bool)].min() > 0.0
        assert np.all(np.hypot(x[:, 1], x[:, 2]) + r <= bench_drum.R_DRUM)
        assert np.all(np.abs(x[:, 0]) + r <= bench_drum.LENGTH / 2)
    line = ("Surface 1 Name drum File drum.yaml Rotation 0 1.5707963267948966 0 Position "
            f"{-bench_drum.LENGTH / 2} 0 0")
    (tmp_path / "drum.inp").write_text(bench_drum.nurbsdem_deck(pos, rad, 0.1, line,
                                                                files=files))
    model = parse_deck(tmp_path / "drum.inp")
    volumes = [model.shapes[k].volume for k in sorted(model.shapes)]
    np.testing.assert_allclose(volumes, [4 / 3 * math.pi * r ** 3 for r in bench_drum.RADII],
                               rtol=1e-9)
    for k, (_, bound) in enumerate(files[r] for r in bench_drum.RADII):
        assert model.shapes[k + 1].shape.bounding_radius == pytest.approx(bound)
    turned = [p for p in model.particles if np.linalg.norm(p.rotation) > 0]
    assert len(model.particles) == 24 and len(turned) == 24

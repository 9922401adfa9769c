"""A NURBS particle against a NURBS surface wall (``nurbsdem/contact/surface_particle.py``):
the time per contact of the compiled solve, called once per particle from Python and for all
particles in one call (as the provider and the compiled deck steps call it), against the
Python solve (the reference), and the largest difference of their rows.

Poses: the drum of ``inputs/drum/drum.yaml`` (radius 0.1 m, axis z, length 0.1 m); 50
random orientations of an exact NURBS ellipsoid 30 × 20 × 15 mm and of the paper's particle
A, the centroid at 0.70–0.95 of the bounding radius from the mantle: touching and apart.

Usage: .venv/bin/python benchmarks/bench_surface_particle.py
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from common import best_per_item
from nurbsdem import shapes
from nurbsdem.contact.detect import table_of
from nurbsdem.contact.lcp import F_SD, NF
from nurbsdem.contact.surface_particle import (particle_surface_row,
                                               particle_surface_row_reference, surface_rows)
from nurbsdem.contact.surface_wall import build_surface_wall
from nurbsdem.geometry.rotation import quat_from_rotvec, quat_to_matrix
from nurbsdem.io.shapefile import read_patches

DRUM = Path(__file__).resolve().parents[1] / "inputs" / "drum" / "drum.yaml"


def poses(table, n: int, rng) -> list[tuple[np.ndarray, np.ndarray]]:
    """n poses (position, R) of the table's shape 0 near the drum's mantle."""
    out = []
    for _ in range(n):
        R = quat_to_matrix(quat_from_rotvec(rng.normal(size=3)))
        phi = rng.uniform(0, 2 * math.pi)
        rho = 0.1 - float(table.radius[0]) * rng.uniform(0.7, 0.95)
        c = np.array([rho * math.cos(phi), rho * math.sin(phi), rng.uniform(0.03, 0.07)])
        out.append((c - R @ table.centroid[0], R))
    return out


def main() -> None:
    drum = build_surface_wall(read_patches(DRUM)[0])
    rng = np.random.default_rng(1)
    for name, shape in (("ellipsoid", shapes.ellipsoid(0.03, 0.02, 0.015)),
                        ("paper A", shapes.paper_particle_shape("A"))):
        table = table_of(shape)
        ps = poses(table, 50, rng)
        one = lambda pos, R: particle_surface_row(table, 0, pos, R, drum)       # noqa: E731
        ref = lambda pos, R: particle_surface_row_reference(table, 0, pos, R, drum)  # noqa
        one(*ps[0])
        t_one, rows = best_per_item(one, ps)
        t_ref, rows_ref = best_per_item(ref, ps, repeat=1)
        P = np.array([p for p, _ in ps])
        Rs = np.array([r for _, r in ps])
        idx, shape_of = np.arange(len(ps)), np.zeros(len(ps), np.int64)
        batch = lambda: surface_rows(table, drum, idx, shape_of, P, Rs, np.eye(3),  # noqa
                                     np.zeros(3))
        batch()
        t_batch = best_per_item(batch, [()] * 20)[0] / len(ps)
        diff = max(float(np.abs(a[0] - b[0])[:NF].max()) for a, b in zip(rows, rows_ref))
        touching = sum(bool(r[2] and r[0][F_SD] < 0) for r in rows)
        print(f"{name}: compiled {t_one * 1e6:.1f} us per call, {t_batch * 1e6:.1f} us per "
              f"contact in one call; Python {t_ref * 1e6:.0f} us; {touching} of {len(ps)} "
              f"touching; largest row difference {diff:.1e}")


if __name__ == "__main__":
    main()

"""Make the synthetic "scanned" grain of the README's worked example (``grain_scan.ply``).

It is **synthetic**, not a real scan: a smooth, irregular, convex body — an ellipsoid with
semi-axes 14 x 10 x 8 mm whose radius is modulated by a few low-order smooth terms (at most
±9 %), turned to an arbitrary orientation — sampled at the 2562 vertices of a subdivided
icosahedron (a triangulated closed surface, as a scanner's software exports one), each
vertex moved along the surface normal by Gaussian measurement noise (σ = 15 µm, about 0.1 %
of the size). Written as binary PLY (about 100 kB) with trimesh. Seeded: re-running it
reproduces the file.

    .venv/bin/python inputs/shapes/make_grain.py      # writes inputs/shapes/grain_scan.ply
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

SEMI_AXES = np.array([0.014, 0.010, 0.008])     # m
NOISE = 15e-6                                    # m, standard deviation along the normal
SEED = 2026


def radius(d: np.ndarray) -> np.ndarray:
    """Radius (m) of the body in the unit directions d (K, 3): ellipsoid times a smooth,
    low-order modulation (kept small enough that the body stays convex)."""
    x, y, z = d.T
    ell = 1.0 / np.sqrt((x / SEMI_AXES[0]) ** 2 + (y / SEMI_AXES[1]) ** 2 + (z / SEMI_AXES[2]) ** 2)
    mod = 1.0 + 0.05 * x * y + 0.04 * y * z - 0.03 * z * x + 0.03 * x ** 3 - 0.02 * y ** 3 \
        + 0.025 * (z ** 2 - y ** 2) * x
    return ell * mod


def make(path: Path) -> None:
    import trimesh
    from scipy.spatial.transform import Rotation

    rng = np.random.default_rng(SEED)
    m = trimesh.creation.icosphere(subdivisions=4)
    d = np.asarray(m.vertices) / np.linalg.norm(m.vertices, axis=1)[:, None]
    pts = d * radius(d)[:, None]
    m = trimesh.Trimesh(pts, m.faces, process=False)
    n = np.asarray(m.vertex_normals)
    pts = pts + n * rng.normal(0.0, NOISE, len(pts))[:, None]
    R = Rotation.from_euler("xyz", [0.4, -0.7, 1.1]).as_matrix()
    m = trimesh.Trimesh(pts @ R.T + np.array([0.001, -0.002, 0.0005]), m.faces, process=False)
    m.export(path, encoding="binary")


if __name__ == "__main__":
    out = Path(__file__).with_name("grain_scan.ply")
    make(out)
    print(f"wrote {out} ({out.stat().st_size} bytes)")

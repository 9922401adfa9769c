"""A NURBS particle against a triangle-mesh wall (``nurbsdem/contact/mesh_particle.py``,
compiled in ``nurbsdem/contact/mesh_particle_compiled.py``): the time per mesh query of the
compiled solve, called once per particle from Python and for all particles in one call (as
the provider and the compiled deck steps call it), against the Python solve (the
reference), and the largest difference of their rows.

Meshes: a 6 cm cube (12 triangles: faces, edges, corners) and a 0.12 m square of 72
triangles whose heights undulate by ±1 cm (convex and concave folds).  Poses: 50 random
orientations of an exact NURBS ellipsoid 30 × 20 × 15 mm and of the paper's particle A,
the centroid within about a bounding radius of the mesh: touching and apart.

Usage: .venv/bin/python benchmarks/bench_mesh_particle.py
"""
from __future__ import annotations


import numpy as np

from common import best_per_item
from nurbsdem import shapes
from nurbsdem.contact.detect import table_of
from nurbsdem.contact.lcp import NF
from nurbsdem.contact.mesh_particle import particle_mesh_contacts
from nurbsdem.contact.mesh_particle_compiled import mesh_rows
from nurbsdem.contact.mesh_wall import build_mesh_wall
from nurbsdem.geometry.rotation import quat_from_rotvec, quat_to_matrix

#: most rows per particle and mesh (the provider's MAX_PER_WALL)
PER = 8


def meshes() -> dict:
    """The cube and the bumped square (module docstring)."""
    import trimesh
    box = trimesh.creation.box(extents=(0.06, 0.06, 0.06))
    n, half = 6, 0.06
    s = np.linspace(-half, half, n + 1)
    gx, gy = np.meshgrid(s, s, indexing="ij")
    v = np.column_stack([gx.ravel(), gy.ravel(),
                         0.01 * np.sin(40 * gx.ravel()) * np.cos(30 * gy.ravel())])
    faces = []
    for i in range(n):
        for j in range(n):
            a, b = i * (n + 1) + j, (i + 1) * (n + 1) + j
            faces += [(a, b, b + 1), (a, b + 1, a + 1)]
    return {"cube": build_mesh_wall(box.vertices, box.faces),
            "bumps": build_mesh_wall(v, np.array(faces))}


def poses(table, mesh_name: str, n: int, rng) -> list[tuple[np.ndarray, np.ndarray]]:
    """n poses (position, R) of the table's shape 0 near the mesh."""
    rad = float(table.radius[0])
    out = []
    for _ in range(n):
        R = quat_to_matrix(quat_from_rotvec(rng.normal(size=3)))
        if mesh_name == "cube":
            d = rng.normal(size=3)
            c = d / np.linalg.norm(d) * (0.03 + rad * rng.uniform(0.3, 1.0))
        else:
            c = np.array([*rng.uniform(-0.04, 0.04, size=2), rad * rng.uniform(0.2, 1.0)])
        out.append((c - R @ table.centroid[0], R))
    return out


def main() -> None:
    rng = np.random.default_rng(1)
    for mesh_name, mesh in meshes().items():
        for name, shape in (("ellipsoid", shapes.ellipsoid(0.03, 0.02, 0.015)),
                            ("paper A", shapes.paper_particle_shape("A"))):
            table = table_of(shape)
            ps = poses(table, mesh_name, 50, rng)
            zero = np.zeros(1, np.int64)

            def one(pos, R):
                return mesh_rows(table, mesh, zero, zero, pos[None], R[None], np.eye(3),
                                 np.zeros(3), PER)[0]

            def ref(pos, R):
                return particle_mesh_contacts(table, 0, pos, R, mesh)[0][:PER]
            one(*ps[0])
            t_one, rows = best_per_item(one, ps)
            t_ref, rows_ref = best_per_item(ref, ps, repeat=1)
            P = np.array([p for p, _ in ps])
            Rs = np.array([r for _, r in ps])
            idx, shape_of = np.arange(len(ps)), np.zeros(len(ps), np.int64)
            t_batch = best_per_item(lambda: mesh_rows(table, mesh, idx, shape_of, P, Rs, np.eye(3),
                                                  np.zeros(3), PER), [()] * 20)[0] / len(ps)
            same = all(len(a) == len(b) for a, b in zip(rows, rows_ref))
            diff = max((float(np.abs(a - b)[:, :NF].max()) for a, b in zip(rows, rows_ref)
                        if len(a) and len(a) == len(b)), default=0.0)
            touching = sum(len(r) > 0 for r in rows)
            print(f"{mesh_name}, {name}: compiled {t_one * 1e6:.1f} us per query, "
                  f"{t_batch * 1e6:.1f} us per query in one call; Python {t_ref * 1e6:.0f} us; "
                  f"{touching} of {len(ps)} touching; same rows {same}; largest row "
                  f"difference {diff:.1e}")


if __name__ == "__main__":
    main()

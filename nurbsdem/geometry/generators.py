"""Exact NURBS shapes: spheres, ellipsoids, and flat walls.

All generated shapes are centred at the origin of their frame with axes along x, y, z.
Lengths in metres.

* :func:`sphere` — six rational biquartic Bézier patches on a cube topology (J. E. Cobb,
  1988), exact: no poles, no seam.
* :func:`ellipsoid` — the affine image diag(a, b, c) of that sphere (NURBS are affine
  invariant, so it is exact too).
* :func:`single_patch_sphere` — the classic single rational biquadratic patch with two
  poles and a seam (the hard case of the paper's Fig. 1a).
* :func:`flat_wall`, :func:`box_walls` — degree-1 patches with 2×2 control points
  (the walls of the paper's example).
"""
from __future__ import annotations

import numpy as np

from .nurbs import Patch

_R2, _R3, _R6 = np.sqrt(2.0), np.sqrt(3.0), np.sqrt(6.0)

#: Proper rotations (integer matrices, so edges stay bit-identical) mapping the -z face
#: of the cube onto each of the six faces.
_FACE_ROTATIONS = {
    "-z": np.array([[1, 0, 0], [0, 1, 0], [0, 0, 1]]),
    "+z": np.array([[1, 0, 0], [0, -1, 0], [0, 0, -1]]),
    "-x": np.array([[0, 0, 1], [0, 1, 0], [-1, 0, 0]]),
    "+x": np.array([[0, 0, -1], [0, 1, 0], [1, 0, 0]]),
    "+y": np.array([[1, 0, 0], [0, 0, -1], [0, 1, 0]]),
    "-y": np.array([[1, 0, 0], [0, 0, 1], [0, -1, 0]]),
}


def _cobb_face_homogeneous() -> np.ndarray:
    """Homogeneous control net (5, 5, 4) of the -z face of Cobb's unit sphere."""
    r2, r3, r6 = _R2, _R3, _R6
    q = {
        (0, 0): (4 * (1 - r3), 4 * (1 - r3), 4 * (1 - r3), 4 * (3 - r3)),
        (0, 1): (r2 * (r3 - 4), -r2, r2 * (r3 - 4), r2 * (3 * r3 - 2)),
        (0, 2): (4 * (1 - 2 * r3) / 3, 0.0, 4 * (1 - 2 * r3) / 3, 4 * (5 - r3) / 3),
        (1, 0): (-r2, r2 * (r3 - 4), r2 * (r3 - 4), r2 * (3 * r3 - 2)),
        (1, 1): ((2 - 3 * r3) / 2, (2 - 3 * r3) / 2, -(r3 + 6) / 2, (r3 + 6) / 2),
        (1, 2): (r2 * (2 * r3 - 7) / 3, 0.0, -5 * r6 / 3, r2 * (r3 + 6) / 3),
        (2, 0): (0.0, 4 * (1 - 2 * r3) / 3, 4 * (1 - 2 * r3) / 3, 4 * (5 - r3) / 3),
        (2, 1): (0.0, r2 * (2 * r3 - 7) / 3, -5 * r6 / 3, r2 * (r3 + 6) / 3),
        (2, 2): (0.0, 0.0, 4 * (r3 - 5) / 3, 4 * (5 * r3 - 1) / 9),
    }
    H = np.zeros((5, 5, 4))
    for i in range(5):
        for j in range(5):
            ii, jj = min(i, 4 - i), min(j, 4 - j)
            x, y, z, w = q[(ii, jj)]
            if i > 2:
                x = -x
            if j > 2:
                y = -y
            H[i, j] = (x, y, z, w)
    return H


def _cobb_face_patch(rotation: np.ndarray) -> Patch:
    """One face of Cobb's unit sphere, rotated, with its normal outward."""
    H = _cobb_face_homogeneous()
    pts = H[..., :3] / H[..., 3:4]
    w = H[..., 3].copy()
    # On the -z face as tabulated, S_u x S_v must point to -z (outward); transpose if not.
    knots = np.array([0, 0, 0, 0, 0, 1, 1, 1, 1, 1], dtype=float)
    probe = Patch(4, 4, knots, knots, pts, w)
    d = probe.evaluate(0.5, 0.5, 1)
    if np.cross(d[1], d[2])[2] > 0:
        pts = pts.transpose(1, 0, 2).copy()
        w = w.T.copy()
    pts = pts @ rotation.T.astype(float)
    return Patch(4, 4, knots.copy(), knots.copy(), pts, w)


def sphere_patches(radius: float) -> list[Patch]:
    """The six patches of the exact sphere of the given radius (m), centred at the origin."""
    if not radius > 0:
        raise ValueError("radius must be > 0")
    out = []
    for rot in _FACE_ROTATIONS.values():
        p = _cobb_face_patch(rot)
        out.append(Patch(4, 4, p.knots_u, p.knots_v, p.control_points * radius, p.weights))
    return out


def ellipsoid_patches(a: float, b: float, c: float) -> list[Patch]:
    """Six patches of the exact ellipsoid x²/a² + y²/b² + z²/c² = 1 (semi-axes in m)."""
    if not (a > 0 and b > 0 and c > 0):
        raise ValueError("semi-axes must be > 0")
    return [p.transformed(np.diag([a, b, c])) for p in sphere_patches(1.0)]


def single_patch_sphere_patches(radius: float) -> list[Patch]:
    """The single rational biquadratic sphere patch (poles at v = 0, 1; seam at u = 0 = 1)."""
    if not radius > 0:
        raise ValueError("radius must be > 0")
    h = np.sqrt(2.0) / 2
    cx = np.array([1, 1, 0, -1, -1, -1, 0, 1, 1], dtype=float)
    cy = np.array([0, 1, 1, 1, 0, -1, -1, -1, 0], dtype=float)
    cw = np.array([1, h, 1, h, 1, h, 1, h, 1])
    r = np.array([0, 1, 1, 1, 0], dtype=float)
    z = np.array([-1, -1, 0, 1, 1], dtype=float)
    rw = np.array([1, h, 1, h, 1])
    pts = np.stack([r[None, :] * cx[:, None], r[None, :] * cy[:, None],
                    np.broadcast_to(z[None, :], (9, 5))], axis=-1) * radius
    w = cw[:, None] * rw[None, :]
    ku = np.array([0, 0, 0, .25, .25, .5, .5, .75, .75, 1, 1, 1])
    kv = np.array([0, 0, 0, .5, .5, 1, 1, 1])
    return [Patch(2, 2, ku, kv, pts, w)]


def sphere(radius: float, name: str | None = None):
    """Exact sphere of 6 rational biquartic patches as a :class:`Shape`."""
    from .shape import Shape
    return Shape(sphere_patches(radius), name=name or f"sphere r={radius:g}")


def ellipsoid(a: float, b: float, c: float, name: str | None = None):
    """Exact ellipsoid with semi-axes a, b, c along x, y, z as a :class:`Shape`."""
    from .shape import Shape
    return Shape(ellipsoid_patches(a, b, c), name=name or f"ellipsoid {a:g}x{b:g}x{c:g}")


def single_patch_sphere(radius: float, name: str | None = None):
    """Exact single-patch sphere (poles and seam) as a :class:`Shape`."""
    from .shape import Shape
    return Shape(single_patch_sphere_patches(radius), name=name or f"single-patch sphere r={radius:g}")


def flat_wall(point, normal, size, first_axis=None) -> Patch:
    """A flat rectangular wall: degree 1, 2×2 control points.

    Parameters
    ----------
    point: centre of the rectangle (m).
    normal: the wall's active side (particles are on this side); S_u × S_v points along it.
    size: (length along the first in-plane axis, length along the second) (m).
    first_axis: in-plane direction of u; by default the in-plane projection of the global
        axis least aligned with the normal.
    """
    n = np.asarray(normal, float)
    n = n / np.linalg.norm(n)
    if first_axis is None:
        first_axis = np.eye(3)[int(np.argmin(np.abs(n)))]
    t1 = np.asarray(first_axis, float)
    t1 = t1 - n * (t1 @ n)
    t1 /= np.linalg.norm(t1)
    t2 = np.cross(n, t1)  # t1 x t2 = n
    c = np.asarray(point, float)
    hu, hv = 0.5 * float(size[0]), 0.5 * float(size[1])
    pts = np.array([[c - hu * t1 - hv * t2, c - hu * t1 + hv * t2],
                    [c + hu * t1 - hv * t2, c + hu * t1 + hv * t2]])
    k = np.array([0.0, 0.0, 1.0, 1.0])
    return Patch(1, 1, k, k.copy(), pts)


def box_walls(lo, hi, top: bool = False) -> dict[str, Patch]:
    """Walls of the box [lo, hi] with normals pointing into the box.

    Returns a dict name -> patch with names bottom, x_min, x_max, y_min, y_max (and top if
    requested).
    """
    lo = np.asarray(lo, float)
    hi = np.asarray(hi, float)
    c = 0.5 * (lo + hi)
    L = hi - lo
    walls = {
        "bottom": flat_wall([c[0], c[1], lo[2]], [0, 0, 1], (L[0], L[1]), [1, 0, 0]),
        "x_min": flat_wall([lo[0], c[1], c[2]], [1, 0, 0], (L[1], L[2]), [0, 1, 0]),
        "x_max": flat_wall([hi[0], c[1], c[2]], [-1, 0, 0], (L[1], L[2]), [0, 1, 0]),
        "y_min": flat_wall([c[0], lo[1], c[2]], [0, 1, 0], (L[0], L[2]), [1, 0, 0]),
        "y_max": flat_wall([c[0], hi[1], c[2]], [0, -1, 0], (L[0], L[2]), [1, 0, 0]),
    }
    if top:
        walls["top"] = flat_wall([c[0], c[1], hi[2]], [0, 0, -1], (L[0], L[1]), [1, 0, 0])
    return walls

"""Rhino ``.3dm`` import (and a small writer for tests) through the optional ``rhino3dm``
package (``pip install 'nurbsdem[cad]'``), imported lazily.

What is read: every NURBS surface object, every other surface object converted with
``ToNurbsSurface`` (plane, revolution and sum surfaces), and the underlying surface of
every face of every Brep (and of Extrusions, through their Brep form), in file order.

Conversion to nurbsdem's :class:`~nurbsdem.geometry.nurbs.Patch`:

* degree = order - 1;
* openNURBS stores n + p - 1 knots per direction (no superfluous end knots): the clamped
  knot vector of length n + p + 1 is that list with its first and last value repeated once;
* control points come as homogeneous (w x, w y, w z, w) ``Point4d`` values (verified: a
  surface written with homogeneous points evaluates, with ``PointAt``, to the same points as
  nurbsdem's patch); Euclidean point = (w x, w y, w z) / w; a non-rational surface has w = 1;
* a Brep face whose orientation is reversed relative to its surface
  (``OrientationIsReversed``) is transposed (u <-> v), which flips S_u x S_v so the patch's
  normal is the face's normal;
* trimmed faces are rejected (the untrimmed surface would be a different shape), and so are
  periodic (unclamped) knot vectors.

Lengths are taken as metres (scale the model in the CAD tool if it is in mm). Errors are
:class:`~nurbsdem.errors.InputError` naming the file and the object (and face).
"""
from __future__ import annotations

from pathlib import Path
from typing import Sequence

import numpy as np

from ..errors import GeometryError, InputError, NurbsdemError
from ..geometry.nurbs import Patch


def _rhino3dm():
    try:
        import rhino3dm  # noqa: F401
    except ImportError:
        raise NurbsdemError("reading .3dm files needs the optional package rhino3dm "
                            "(pip install 'nurbsdem[cad]')") from None
    return rhino3dm


def patch_from_nurbs_surface(srf, path: str | None = None, where: str | None = None) -> Patch:
    """A :class:`Patch` from a ``rhino3dm.NurbsSurface`` (conversion rules: module docstring)."""
    p, q = srf.OrderU - 1, srf.OrderV - 1
    nu, nv = srf.Points.CountU, srf.Points.CountV
    ku = np.array(list(srf.KnotsU.ToList()), dtype=float)
    kv = np.array(list(srf.KnotsV.ToList()), dtype=float)
    if len(ku) != nu + p - 1 or len(kv) != nv + q - 1:
        raise InputError(f"unexpected knot counts {len(ku)}, {len(kv)} for {nu} x {nv} control "
                         f"points of orders {p + 1}, {q + 1}", path=path, where=where)
    ku = np.concatenate([ku[:1], ku, ku[-1:]])
    kv = np.concatenate([kv[:1], kv, kv[-1:]])
    H = np.empty((nu, nv, 4))
    for i in range(nu):
        for j in range(nv):
            c = srf.Points[i, j]
            H[i, j] = c.X, c.Y, c.Z, c.W
    if not srf.IsRational:
        H[..., 3] = 1.0
    w = H[..., 3].copy()
    if np.any(w <= 0):
        i, j = np.argwhere(w <= 0)[0]
        raise InputError(f"control point weight [{i}][{j}] = {w[i, j]} is not > 0",
                         path=path, where=where)
    pts = H[..., :3] / w[..., None]
    for name, k, deg in (("u", ku, p), ("v", kv, q)):
        if not (np.all(k[:deg + 1] == k[0]) and np.all(k[-deg - 1:] == k[-1])):
            raise InputError(f"the {name} knot vector is not clamped (a periodic surface?); "
                             "make it non-periodic in the CAD tool", path=path, where=where)
    patch = Patch(p, q, ku, kv, pts, w)
    try:
        patch.validate(path)
    except GeometryError as exc:
        raise InputError(exc.detail, path=path, where=where) from None
    return patch


def _transposed(p: Patch) -> Patch:
    return Patch(p.degree_v, p.degree_u, p.knots_v.copy(), p.knots_u.copy(),
                 p.control_points.transpose(1, 0, 2).copy(), p.weights.T.copy())


def read_3dm_patches(path: str | Path) -> list[Patch]:
    """All surfaces of a ``.3dm`` file as patches (module docstring)."""
    r3 = _rhino3dm()
    path = str(path)
    if not Path(path).is_file():
        raise InputError("cannot read file: No such file or directory", path=path)
    model = r3.File3dm.Read(path)
    if model is None:
        raise InputError("not a readable Rhino .3dm file", path=path)
    patches: list[Patch] = []
    for k, obj in enumerate(model.Objects):
        geom = obj.Geometry
        where = f"object {k}"
        if isinstance(geom, r3.Extrusion):
            geom = geom.ToBrep(True)
        if isinstance(geom, r3.Brep):
            for fi, face in enumerate(geom.Faces):
                fw = f"{where}, brep face {fi}"
                dup = face.DuplicateFace(False)
                if dup is not None and not dup.IsSurface:
                    raise InputError("the face is trimmed; only untrimmed faces can be imported",
                                     path=path, where=fw)
                srf = face.UnderlyingSurface().ToNurbsSurface()
                if srf is None:
                    raise InputError("the face has no NURBS form", path=path, where=fw)
                pt = patch_from_nurbs_surface(srf, path, fw)
                patches.append(_transposed(pt) if face.OrientationIsReversed else pt)
        elif isinstance(geom, r3.NurbsSurface):
            patches.append(patch_from_nurbs_surface(geom, path, where))
        elif isinstance(geom, r3.Surface):
            srf = geom.ToNurbsSurface()
            if srf is None:
                raise InputError("the surface has no NURBS form", path=path, where=where)
            patches.append(patch_from_nurbs_surface(srf, path, where))
    if not patches:
        raise InputError("no surfaces or breps in the file", path=path)
    return patches


def nurbs_surface_from_patch(patch: Patch):
    """A ``rhino3dm.NurbsSurface`` equal to the patch (homogeneous control points)."""
    r3 = _rhino3dm()
    nu, nv = patch.shape
    rational = not np.all(patch.weights == 1.0)
    srf = r3.NurbsSurface.Create(3, rational, patch.degree_u + 1, patch.degree_v + 1, nu, nv)
    H = patch.homogeneous
    for i in range(nu):
        for j in range(nv):
            srf.Points[i, j] = r3.Point4d(*(float(x) for x in H[i, j]))
    for k, t in enumerate(patch.knots_u[1:-1]):
        srf.KnotsU[k] = float(t)
    for k, t in enumerate(patch.knots_v[1:-1]):
        srf.KnotsV[k] = float(t)
    return srf


def write_3dm(path: str | Path, patches: Sequence[Patch], breps: bool = False,
              version: int = 7) -> None:
    """Write patches as NURBS surface objects, or (``breps=True``) as one single-face Brep
    per patch (``Brep.CreateFromSurface``; rhino3dm cannot join faces into one Brep)."""
    r3 = _rhino3dm()
    patches = getattr(patches, "patches", patches)
    model = r3.File3dm()
    for p in patches:
        srf = nurbs_surface_from_patch(p)
        if breps:
            model.Objects.AddBrep(r3.Brep.CreateFromSurface(srf))
        else:
            model.Objects.AddSurface(srf)
    if not model.Write(str(path), version):
        raise OSError(f"rhino3dm could not write {path}")


def import_3dm(path: str | Path, out: str | Path | None = None, name: str | None = None,
               check: bool = True):
    """Read a ``.3dm`` file into a checked :class:`~nurbsdem.geometry.shape.Shape`
    (optionally written to the shape file ``out``)."""
    from ..geometry.shape import Shape
    from .shapefile import save_shape

    shape = Shape(read_3dm_patches(path), name=name if name is not None else Path(path).stem,
                  source=str(path), check=check)
    if out is not None:
        save_shape(out, shape)
    return shape

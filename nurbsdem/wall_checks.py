"""Pre-run checks of mesh and surface walls (``Mesh``, ``Surface``): what ``nurbsdem check``,
every run and every Python step refuse or warn of about them, called from
:mod:`nurbsdem.validation` (so the deck and the Python API share the rules and the messages).

* **particles against the walls** (:func:`check_curved_walls_scene`, in
  :func:`~nurbsdem.validation.validate_scene`).  The depth by which a particle crosses
  a wall's surface is the contact law's own: the solver's kernels at the wall's rest pose (the
  mesh's closest triangles, :mod:`nurbsdem.contact.mesh_wall`; the surface's projected
  Newton closest point, :mod:`nurbsdem.contact.surface_wall`), signed distance d − r.  A
  crossing deeper than the resting overlap that flat walls accept
  (:func:`~nurbsdem.check_rules.allowed_overlap`) is an error naming the particle and the
  wall.  A one-sided wall (a ``OneSided yes`` mesh, every surface) acts only on a centre in
  front of it (the side its triangles' vertex order, or the surface's S_u × S_v, faces), so a
  sphere whose centre is behind it and which crosses its surface by as much is refused too:
  the wall would let it through.  The back of a *closed*, consistently oriented one-sided
  mesh is solid: a centre there, however far from the surface, is refused
  (:func:`winding_numbers`).  A two-sided mesh is a shell: either side may hold particles.
* **mesh sizes** (:func:`warn_mesh_size`): a mesh more than 1e3 times larger than the
  largest particle, or smaller than the smallest, is warned of (a millimetre file read as
  metres, or the reverse: :func:`nurbsdem.io.meshfile.size_mismatch`).
* **strokes** (:func:`check_curved_wall_strokes`): the ``MoveWall`` steps of a mesh or
  surface wall (``Displacement``, ``Rotate``) must not carry it through a flat wall (or out
  of a ``Box`` through one of its walls), as the strokes of flat walls must not
  (:func:`~nurbsdem.validation.check_wall_strokes`): the particles between would be crushed
  through that wall.  The wall's points (a mesh's vertices, a surface's samples) are placed
  at the end of each step by the steps' poses so far; a point in front of a flat wall at the
  start that ends behind it, within the wall's rectangle, is an error at the step's line.

A NURBS particle is checked as a sphere is, its depth the solver's NURBS kernels' at its
pose (:mod:`nurbsdem.contact.mesh_particle`, :mod:`nurbsdem.contact.surface_particle`), the
accepted overlap that of its bounding radius (as against a flat wall).  Lengths in metres,
angles in radians.
"""
from __future__ import annotations

from typing import TYPE_CHECKING, Sequence

import numpy as np

from .errors import vector_text as _vec

if TYPE_CHECKING:  # pragma: no cover
    from .model import Bodies, CurvedWallSpec, Model

#: Points of a moving wall within this fraction of its size of a flat wall's plane are on it
#: (round-off of the placement and of the turns), not behind it.
PLANE_TOLERANCE = 1e-9


def _where(model: "Model", spec: "CurvedWallSpec") -> str:
    """The place a wall's file is named by in messages: ``deck:line``, or the wall."""
    if spec.line and model.path:
        return f"{model.path}:{spec.line}"
    return f"{spec.kind} wall {spec.name!r}"


def _title(spec: "CurvedWallSpec") -> str:
    return f"{spec.kind} wall {spec.name!r}"


# ---------------------------------------------------------------------------- winding numbers


def _point_cells(xy: np.ndarray) -> tuple[np.ndarray, float, np.ndarray, np.ndarray, np.ndarray]:
    """A plan-view grid of the points xy (P,2): (corner (2,), cell edge, cells per axis (2,),
    the points sorted by cell, the CSR start (C+1,) of each cell's points in that order)."""
    lo = xy.min(axis=0)
    span = xy.max(axis=0) - lo
    n_side = int(np.ceil(np.sqrt(len(xy))))
    cell = max(float(span.max()) / n_side, 1e-300)
    dims = np.minimum(np.floor(span / cell).astype(np.int64) + 1, n_side + 1)
    ij = np.minimum(np.floor((xy - lo) / cell).astype(np.int64), dims - 1)
    ids = ij[:, 0] + dims[0] * ij[:, 1]
    order = np.argsort(ids, kind="stable")
    start = np.concatenate([[0], np.cumsum(np.bincount(ids, minlength=int(np.prod(dims))))])
    return lo, cell, dims, order, start


def _expand(counts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(owner, rank) of ``counts.sum()`` items: item k is the rank-th of owner's counts."""
    owner = np.repeat(np.arange(len(counts)), counts)
    first = np.cumsum(counts) - counts
    return owner, np.arange(int(counts.sum())) - first[owner]


def _orientations(vertices: np.ndarray, fa: np.ndarray, fb: np.ndarray,
                  p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(sign, value) of the plan-view orientation of p (K,3) against the directed edges
    fa -> fb (vertex indices (K,)): > 0 with p on the left.  Each edge is computed from its
    lower vertex index (then negated), so the two triangles of an edge agree to the bit; a
    zero is broken by the perturbation p + (eps, eps^2)."""
    swap = fa > fb
    a = vertices[np.where(swap, fb, fa)]
    b = vertices[np.where(swap, fa, fb)]
    ex, ey = b[:, 0] - a[:, 0], b[:, 1] - a[:, 1]
    value = ex * (p[:, 1] - a[:, 1]) - ey * (p[:, 0] - a[:, 0])
    tie = np.where(ey != 0, -np.sign(ey), np.sign(ex))
    sign = np.where(value != 0, np.sign(value), tie)
    flip = np.where(swap, -1.0, 1.0)
    return sign * flip, value * flip


def winding_numbers(vertices: np.ndarray, faces: np.ndarray, points: np.ndarray,
                    block: int = 1 << 20) -> np.ndarray:
    """The winding number (int (P,)) of the closed triangle surface (vertices (V,3) m, faces
    (T,3)) about each point (P,3): the signed count of the triangles that the ray from the
    point along +z crosses, +1 where a triangle's front (vertex order) faces up, -1 where it
    faces down.  For a closed, consistently oriented surface it is 1 inside and 0 outside
    when the fronts face out, -1 inside when they face in.  A ray through an edge or a
    vertex (in plan view) is decided by the perturbation of :func:`_orientations`, the same
    for both triangles of an edge, so each crossing counts once.  The triangles' plan-view
    boxes are matched to the points through a grid of the points (``block`` candidate pairs
    at a time), so the cost is about the number of crossings, not points x triangles."""
    pts = np.ascontiguousarray(points, float).reshape(-1, 3)
    out = np.zeros(len(pts), np.int64)
    if not len(pts) or not len(faces):
        return out
    lo, cell, dims, order, start = _point_cells(pts[:, :2])
    tri = vertices[faces]
    i0 = np.clip(np.floor((tri[:, :, :2].min(axis=1) - lo) / cell), -1, dims).astype(np.int64)
    i1 = np.clip(np.floor((tri[:, :, :2].max(axis=1) - lo) / cell), -1, dims).astype(np.int64)
    i0, i1 = np.maximum(i0, 0), np.minimum(i1, dims - 1)
    width = np.maximum(i1 - i0 + 1, 0)
    t_of, k = _expand(width[:, 0] * width[:, 1])
    cx = i0[t_of, 0] + k % np.maximum(width[t_of, 0], 1)
    cy = i0[t_of, 1] + k // np.maximum(width[t_of, 0], 1)
    cid = cx + dims[0] * cy
    n_in = start[cid + 1] - start[cid]
    ends = np.cumsum(n_in)
    first = 0
    while first < len(cid):                        # blocks of (triangle, cell) pairs
        last = int(np.searchsorted(ends, ends[first] - n_in[first] + block, side="right"))
        last = max(last, first + 1)
        pair, rank = _expand(n_in[first:last])
        t = t_of[first:last][pair]
        p_idx = order[start[cid[first:last][pair]] + rank]
        _count_crossings(vertices, faces[t], pts[p_idx], p_idx, out)
        first = last
    return out


def _count_crossings(vertices: np.ndarray, f: np.ndarray, p: np.ndarray, p_idx: np.ndarray,
                     out: np.ndarray) -> None:
    """Add to ``out[p_idx]`` the signed crossings of the rays from p (K,3) along +z with
    the triangles f (K,3) (:func:`winding_numbers`)."""
    s_ab, o_ab = _orientations(vertices, f[:, 0], f[:, 1], p)
    s_bc, o_bc = _orientations(vertices, f[:, 1], f[:, 2], p)
    s_ca, o_ca = _orientations(vertices, f[:, 2], f[:, 0], p)
    inside = (s_ab == s_bc) & (s_bc == s_ca) & (s_ab != 0)
    twice_area = o_ab + o_bc + o_ca
    inside &= twice_area != 0
    w = np.where(inside, twice_area, 1.0)
    z = (o_bc * vertices[f[:, 0], 2] + o_ca * vertices[f[:, 1], 2]
         + o_ab * vertices[f[:, 2], 2]) / w
    hit = inside & (z > p[:, 2])
    np.add.at(out, p_idx[hit], s_ab[hit].astype(np.int64))


def closed_and_oriented(faces: np.ndarray) -> bool:
    """Whether triangles ``faces`` (T,3) form closed surfaces whose neighbours agree on their
    front: every edge in exactly two triangles, which run along it in opposite directions."""
    from .io.meshfile import edge_use
    _, counts, forward = edge_use(np.asarray(faces, np.int64))
    return bool(np.all(counts == 2) and np.all(forward == 1))


def signed_volume(vertices: np.ndarray, faces: np.ndarray) -> float:
    """The volume (m^3) a closed surface encloses, > 0 when its fronts face out."""
    a, b, c = (vertices[faces[:, k]] for k in range(3))
    return float(np.einsum("ij,ij->", a, np.cross(b, c))) / 6.0


# ---------------------------------------------------------------------------- particles


def _near_box(x: np.ndarray, r: np.ndarray, pts: np.ndarray, pad: float) -> np.ndarray:
    """Indices of the spheres (x, r) whose boxes meet the box of ``pts`` widened by pad (m)."""
    lo, hi = pts.min(axis=0) - pad, pts.max(axis=0) + pad
    return np.flatnonzero(np.all((x + r[:, None] >= lo) & (x - r[:, None] <= hi), axis=1))


def sphere_crossings(geometry, x: np.ndarray, r: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(front (N,), back (N,)): the depth (m, 0: none) by which each sphere (centres x (N,3),
    radii r (N,)) crosses the mesh or surface wall ``geometry`` (at rest) from a side the wall
    acts on, and from behind it: its kind's answer
    (:meth:`~nurbsdem.contact.wall_kinds.WallKind.sphere_crossings`: the solver's kernels)
    for the spheres whose boxes meet the wall's."""
    from .contact.wall_kinds import kind_of
    kind = kind_of(geometry)
    x = np.ascontiguousarray(x, float)
    r = np.ascontiguousarray(r, float)
    return kind.sphere_crossings(geometry, x, r, _near_box(x, r, *kind.box_points(geometry)))


def nurbs_crossings(geometry, shapes: Sequence, x: np.ndarray,
                    R: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(front (N,), back (N,)) as :func:`sphere_crossings`, for NURBS particles (``shapes``
    (N,), centroids x (N,3) m, rotations R (N,3,3)) against a mesh or surface wall at rest:
    the deepest contact of the solver's kernels, in front of the wall or (a one-sided wall)
    behind it (:meth:`~nurbsdem.contact.wall_kinds.WallKind.particle_crossings`)."""
    from .contact.wall_kinds import kind_of
    return kind_of(geometry).particle_crossings(geometry, shapes, x, R)


def _solid_side(spec: "CurvedWallSpec", geometry, x: np.ndarray) -> tuple[np.ndarray, bool]:
    """(on the solid side (N,) bool, fronts face out) of the centres x for a closed,
    consistently oriented one-sided mesh (its back: inside when its fronts face out, outside
    when they face in); all False for any other wall."""
    none = np.zeros(len(x), bool)
    if spec.kind != "mesh" or geometry.two_sided or not closed_and_oriented(geometry.faces):
        return none, True
    outward = signed_volume(geometry.vertices, geometry.faces) > 0
    inbox = np.flatnonzero(np.all((x >= geometry.vertices.min(axis=0))
                                  & (x <= geometry.vertices.max(axis=0)), axis=1))
    w = np.zeros(len(x), np.int64)
    w[inbox] = winding_numbers(geometry.vertices, geometry.faces, x[inbox])
    return (w > 0) if outward else (w > -1), outward


def check_curved_walls_scene(model: "Model", bodies: "Bodies | None",
                             index: Sequence[int] | None = None) -> None:
    """Each mesh and surface wall read once: its size against the particles' (warnings,
    :func:`warn_mesh_size`), then the particles of ``bodies`` (of ``index``, default all;
    None: none) against it (:func:`check_bodies_against_curved_wall`): the exact spheres,
    then the NURBS particles (:func:`nurbs_crossings`)."""
    if not model.curved_walls:
        return
    from .io.deck_curved import curved_wall_geometry, sphere_radii
    idx = np.zeros(0, np.int64)
    if bodies is not None and len(bodies):
        idx = np.arange(len(bodies)) if index is None else np.asarray(index, np.int64)
    r = np.zeros(0)
    nurbs = np.zeros(0, np.int64)
    if len(idx):
        radius, sphere = sphere_radii(model, bodies.shape_id[idx])
        idx, r, nurbs = idx[sphere], radius[sphere], idx[~sphere]
    x = np.ascontiguousarray(bodies.position[idx], float) if len(idx) else np.zeros((0, 3))
    sizes = _particle_sizes(model)
    for spec in model.curved_walls:
        _, geometry = curved_wall_geometry(spec, _where(model, spec))
        if spec.kind == "mesh":
            warn_mesh_size(model, spec, geometry.size, sizes)
        if len(idx):
            check_bodies_against_curved_wall(model, bodies, idx, x, r, spec, geometry)
        if len(nurbs):
            _check_nurbs_against_curved_wall(model, bodies, nurbs, spec, geometry)


def _check_nurbs_against_curved_wall(model: "Model", bodies: "Bodies", idx: np.ndarray,
                                     spec: "CurvedWallSpec", geometry) -> None:
    """:func:`check_bodies_against_curved_wall` for the NURBS particles ``idx``: their depths
    by :func:`nurbs_crossings`, their accepted overlap that of their bounding radii."""
    shapes = [model.shapes[int(bodies.shape_id[i])].shape for i in idx]
    r = np.array([float(s.bounding_radius) for s in shapes])
    x = np.ascontiguousarray(bodies.position[idx], float)
    R = bodies.rotation_matrices()[idx]
    depths = _box_filtered(geometry, x, r, lambda k: nurbs_crossings(
        geometry, [shapes[j] for j in k], x[k], R[k]))
    check_bodies_against_curved_wall(model, bodies, idx, x, r, spec, geometry, depths)


def _box_filtered(geometry, x: np.ndarray, r: np.ndarray, crossings):
    """(front, back) (N,) of ``crossings`` (of the indices into x) for the particles whose
    bounding boxes (x ± r) meet the wall's box, 0 for the others."""
    from .contact.wall_kinds import kind_of
    near = _near_box(x, r, *kind_of(geometry).box_points(geometry))
    front, back = np.zeros(len(x)), np.zeros(len(x))
    if len(near):
        front[near], back[near] = crossings(near)
    return front, back


def check_bodies_against_curved_wall(model: "Model", bodies: "Bodies", idx: np.ndarray,
                                     x: np.ndarray, r: np.ndarray, spec: "CurvedWallSpec",
                                     geometry, depths=None) -> None:
    """Raise at the deck line of the first exact sphere (bodies ``idx``, centres x (N,3) m,
    radii r (N,) m) that lies on the solid side of the closed one-sided mesh ``geometry``,
    crosses the wall from behind, or crosses it deeper than the resting overlap (module
    docstring); warn of an accepted deep crossing.  ``depths``: the (front, back) crossings
    when given (NURBS particles, x their centroids), else the spheres'."""
    solid, outward = _solid_side(spec, geometry, x)
    if solid.any():
        k = int(np.flatnonzero(solid)[0])
        raise model.error(_solid_text(bodies, int(idx[k]), x[k], spec, outward),
                          int(bodies.line[idx[k]]))
    front, back = sphere_crossings(geometry, x, r) if depths is None else depths
    from .check_rules import pile_mass
    pile = None             # the particles' mass, once a crossing needs it
    for k in np.flatnonzero((front > 0) | (back > 0)).tolist():
        if pile is None:
            pile = pile_mass(model, bodies)
        _judge(model, bodies, int(idx[k]), x[k], float(r[k]), spec, float(front[k]),
               float(back[k]), pile)


def _judge(model: "Model", bodies: "Bodies", i: int, x: np.ndarray, r: float,
           spec: "CurvedWallSpec", front: float, back: float, pile: float) -> None:
    """Raise for a crossing deeper than the resting overlap (``pile``: the particles' mass,
    kg, :func:`~nurbsdem.check_rules.pile_mass`); warn of an accepted deep one."""
    from .check_rules import (OVERLAP_TOLERANCE, _allowed_rule, _body_mass, _warn_deep,
                             allowed_overlap, static_overlap)
    depth = max(front, back)
    if depth <= OVERLAP_TOLERANCE * r:
        return
    resting = static_overlap(model, "particle-wall", (int(bodies.material_id[i]),),
                             _body_mass(model, bodies, i), r, spec.material_id)
    tol = allowed_overlap(r, resting, static_overlap(
        model, "particle-wall", (int(bodies.material_id[i]),), pile, r, spec.material_id))
    line = int(bodies.line[i])
    if back > tol:
        from .contact.wall_kinds import kind_named
        kind = kind_named(spec.kind)
        side, fix = kind.front_rule, kind.two_sided_hint
        raise model.error(
            f"particle {bodies.id[i]} (centre {_vec(x)} m) is behind one-sided {_title(spec)} "
            f"(on the side {side} faces away from) and crosses its surface by {back:.3g} m; at "
            f"most {tol:.3g} m is accepted: the wall acts on its front side only and would let "
            f"the particle through; move the particle in front of it{fix}", line)
    if front > tol:
        raise model.error(
            f"particle {bodies.id[i]} (centre {_vec(x)} m) penetrates {_title(spec)} by "
            f"{front:.3g} m; at most {tol:.3g} m is accepted ({_allowed_rule()}); move it at "
            f"least {front - tol:.3g} m away from the wall", line)
    _warn_deep(model, line, f"particle {bodies.id[i]} penetrates {_title(spec)}", depth, r,
               resting)


def _solid_text(bodies: "Bodies", i: int, x: np.ndarray, spec: "CurvedWallSpec",
                outward: bool) -> str:
    where, face, acts = (("inside", "out", "outside") if outward
                         else ("outside", "in", "inside"))
    return (f"particle {bodies.id[i]} (centre {_vec(x)} m) is {where} the closed one-sided "
            f"{_title(spec)}, whose triangles' fronts (vertex order) face {face}wards: it acts "
            f"on particles {acts} it only; reverse the triangles' vertex order or make the wall "
            f"two-sided (OneSided no)")


# ---------------------------------------------------------------------------- files, strokes


def rest_points(model: "Model", spec: "CurvedWallSpec") -> np.ndarray:
    """Points (P,3) m of a wall at rest: those its kind bounds it by (a mesh's vertices, a
    surface's start samples: :meth:`~nurbsdem.contact.wall_kinds.WallKind.box_points`)."""
    from .contact.wall_kinds import kind_named
    from .io.deck_curved import curved_wall_geometry
    _, geometry = curved_wall_geometry(spec, _where(model, spec))
    return kind_named(spec.kind).box_points(geometry)[0]


def used_shapes(model: "Model") -> set[int]:
    """The ids of the defined shapes that the particles, groups and inlets use."""
    used = {p.shape_id for p in model.particles}
    used |= {s for g in model.random_groups for s in g.shape_ids}
    used |= {s for i in model.inlets for s in getattr(i, "shapes", ())}
    return {s for s in used if s in model.shapes}


def _particle_sizes(model: "Model") -> list[float]:
    """Bounding diameters (m) of the shapes the particles, groups and inlets use."""
    return [2.0 * float(model.shapes[s].bounding_radius) for s in used_shapes(model)]


def warn_mesh_size(model: "Model", spec: "CurvedWallSpec", size: float,
                   sizes: list[float]) -> None:
    """A warning at the wall's line when the mesh (bounding-box diagonal ``size``, m) is more
    than 1e3 times larger than the largest particle or smaller than the smallest (particle
    diameters ``sizes``, m; :func:`~nurbsdem.io.meshfile.size_mismatch`)."""
    import logging
    from .io.meshfile import size_mismatch
    if not sizes:
        return
    scale = f", Scale {spec.scale:g}" if spec.scale != 1 else ""
    label = f"Mesh {spec.id} ({spec.path.name if spec.path else spec.file}{scale})"
    text = (size_mismatch(size, max(sizes), label) if size > max(sizes)
            else size_mismatch(size, min(sizes), label))
    if text is not None:
        loc = f"{model.path}:{spec.line}: " if model.path and spec.line else ""
        logging.getLogger("nurbsdem").warning(f"{loc}{text}")


def _pose_after(step, R: np.ndarray, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The pose (R, t: x = R x_rest + t) after a MoveWall step that began at (R, t): turned by
    ω T about the centre (where it is at the step's start), then translated."""
    d = step.net_displacement()
    table = step.table
    if not step.rotate and (table is None or table.rotation is None):
        return R, t + d
    from scipy.spatial.transform import Rotation
    turn = (table.rotation[-1] if table is not None else
            np.asarray(step.angular_velocity, float) * float(step.duration))
    rot = Rotation.from_rotvec(turn).as_matrix()
    c = np.asarray(step.center, float)
    return rot @ R, rot @ (t - c) + c + d


def check_curved_wall_strokes(model: "Model", points: dict) -> None:
    """Raise at the line of the first MoveWall step that carries a mesh or surface wall
    through a flat wall (module docstring); ``points``: each wall's :func:`rest_points`."""
    from .model import MoveWallStep
    from .check_rules import _inside_rectangle, wall_plane
    planes = [(w, *wall_plane(w)) for w in model.walls]
    curved = {w.name: w for w in model.curved_walls}
    pose: dict[str, tuple[np.ndarray, np.ndarray]] = {}
    moves = [(s, m) for s in model.steps if isinstance(s, MoveWallStep) and not s.to_contact
             for m in s.moves()]
    for _, s in moves:
        if s.wall not in curved:
            continue
        R, t = _pose_after(s, *pose.get(s.wall, (np.eye(3), np.zeros(3))))
        pose[s.wall] = (R, t)
        rest = points[s.wall]
        end = rest @ R.T + t
        tol = PLANE_TOLERANCE * float(np.linalg.norm(rest.max(axis=0) - rest.min(axis=0)))
        for w, o, a, b, n in planes:
            h0, h1 = (rest - o) @ n, (end - o) @ n
            through = (h0 >= -tol) & (h1 < -tol) & _inside_rectangle(end, o, a, b,
                                                                     np.zeros(len(end)))
            if through.any():
                of = " of the Box" if w.kind == "box" else ""
                depth = float(-h1[through].min())
                raise model.error(
                    f"Step {s.id}: {_title(curved[s.wall])} would be {depth:.4g} m behind "
                    f"wall {w.name!r}{of} by the end of this step, carried through it "
                    f"from the side it faces: the particles between would be crushed through it",
                    s.line)


def check_curved_walls_model(model: "Model") -> None:
    """The checks of mesh and surface walls that need no placed particles: the strokes of
    their MoveWall steps."""
    curved = {w.name for w in model.curved_walls}
    if not any(m.wall in curved for s in model.steps if hasattr(s, "moves")
               for m in s.moves()):
        return
    check_curved_wall_strokes(model, {w.name: rest_points(model, w)
                                      for w in model.curved_walls})

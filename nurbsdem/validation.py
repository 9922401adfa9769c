"""Whole-scene validation: what ``nurbsdem check`` refuses before anything runs.

:func:`validate_scene` checks a placed model (``model.bodies``) and raises
:class:`~nurbsdem.errors.InputError` at the deck line of the first problem:

* **bodies against each other**: an overlap deeper than the contact law carries at rest
  (:func:`allowed_overlap`: :data:`RESTING_LOADS` static overlaps of the pair's contact under
  the heavier body's weight, at most :data:`MAX_RESTING_FRACTION` of the smaller bounding
  radius, and at least :data:`OVERLAP_TOLERANCE` of it), found by bounding spheres then the
  exact LCP (:func:`nurbsdem.contact.detect`); two bodies whose centroids are closer than
  :data:`COINCIDENT_FRACTION` of the smaller radius overlap outright (a convex body contains
  its centroid, and the LCP of two identical poses is degenerate);
* **bodies against walls**: a body behind a wall (on the side its normal points away from;
  for a ``Box`` that means outside the box) or penetrating one deeper than the same rule
  allows (exact support point along the wall's normal, paper Eq. 8);
* **walls**: finite control points and a finite, non-zero normal;
* **mesh and surface walls** (:mod:`nurbsdem.wall_checks`): exact spheres crossing them
  deeper than the same rule, behind a one-sided one, or inside the solid of a closed
  one-sided mesh (in :func:`validate_scene`, with warnings of mesh sizes far from the
  particles'); their ``MoveWall`` strokes (in :func:`check_model`).
* **inlets**: a region partly behind a flat wall, or too small for the particles of one
  segment, is a warning (:func:`nurbsdem.flow_checks.warn_flow`; the errors of inlets and
  outlets are the deck's and the API's own, :mod:`nurbsdem.io.deck_flow`);
* **output**: ParaView samples larger than the free space of their disk are a warning
  (:func:`nurbsdem.output_checks.warn_output_size`);
* **surface walls tighter than the particles**: a wall that curves toward the particles more
  tightly than a NURBS particle's flattest part is a warning
  (:func:`nurbsdem.curvature_checks.warn_tight_surfaces`).

Random groups are placed with disjoint bounding spheres, so only explicit ``Particle``
bodies are tested against each other; every body is tested against every wall.
"""
from __future__ import annotations

import math
from typing import TYPE_CHECKING, Iterator, Sequence

import numpy as np

from .check_rules import (MAX_RESTING_FRACTION, OVERLAP_TOLERANCE, RESTING_LOADS,
                          SOFT_FRACTION, WARN_OVERLAP_FRACTION, _allowed_rule, _body_mass,
                          _inside_rectangle, _warn_deep, allowed_overlap, pile_mass,
                          static_overlap, wall_plane)
from .dynamics.stepcontrol import critical_step
from .errors import InputError, vector_text as _vec
from .output_checks import (gib, max_particle_count, output_line as _output_line,
                            warn_output_size)

if TYPE_CHECKING:  # pragma: no cover
    from .geometry.shape import Shape
    from .model import Bodies, Model

#: Centroids closer than this fraction of the smaller bounding radius: coincident bodies.
COINCIDENT_FRACTION = 1e-3


# ---------------------------------------------------------------------------- body pairs


def _pose(shape: "Shape", centroid_world: np.ndarray, R: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The (position, R) pose of a body given its centroid in the world."""
    return np.asarray(centroid_world, float) - R @ np.asarray(shape.centroid, float), R


def _world_point(shape: "Shape", centroid_world, R, point_file: np.ndarray) -> np.ndarray:
    """Where ``point_file`` (m, the shape's file frame) lies in the world (m) for a body of
    ``shape`` with its centroid at ``centroid_world`` and file-to-world rotation ``R``."""
    position, R = _pose(shape, centroid_world, R)
    return position + R @ np.asarray(point_file, float)


def pair_penetration(shape_a: "Shape", pos_a, R_a, shape_b: "Shape", pos_b, R_b) -> float:
    """Penetration depth (m) of two bodies: > 0 overlap, <= 0 separated or touching.

    pos_*: centroids in the world (m); R_*: (3, 3) file-to-world rotations. Bounding
    spheres first; coincident centroids give ``inf``; two exact spheres by their centres'
    distance (a deck of spheres needs no LCP, so it does not compile one); otherwise the
    exact LCP, and the surface-sample test of
    :func:`nurbsdem.geometry.overlap.bodies_overlap` when the LCP fails.
    """
    from .contact import detect, table_of
    from .geometry.overlap import bodies_overlap

    ra, rb = float(shape_a.bounding_radius), float(shape_b.bounding_radius)
    d = float(np.linalg.norm(np.asarray(pos_a, float) - np.asarray(pos_b, float)))
    if d >= ra + rb:
        return -(d - ra - rb)
    if d < COINCIDENT_FRACTION * min(ra, rb):
        return math.inf
    sphere_a, sphere_b = table_of(shape_a).spheres[0], table_of(shape_b).spheres[0]
    if sphere_a is not None and sphere_b is not None:
        gap = np.linalg.norm(_world_point(shape_a, pos_a, R_a, sphere_a[0])
                             - _world_point(shape_b, pos_b, R_b, sphere_b[0]))
        return sphere_a[1] + sphere_b[1] - float(gap)
    res = detect(shape_a, _pose(shape_a, pos_a, R_a), shape_b, _pose(shape_b, pos_b, R_b))
    if res.failed or not math.isfinite(res.signed_distance):
        return math.inf if bodies_overlap(shape_a, pos_a, R_a, shape_b, pos_b, R_b) else 0.0
    return -float(res.signed_distance)


def close_pairs(position: np.ndarray, radii: np.ndarray) -> Iterator[tuple[int, int]]:
    """Pairs (i < j) whose bounding spheres overlap (k-d tree, then exact radii)."""
    n = len(position)
    if n < 2:
        return
    from scipy.spatial import cKDTree

    tree = cKDTree(position)
    for i, j in sorted(tree.query_pairs(2.0 * float(np.max(radii)))):
        if np.linalg.norm(position[i] - position[j]) < radii[i] + radii[j]:
            yield int(i), int(j)


def check_body_overlaps(model: "Model", bodies: "Bodies", index: Sequence[int] | None = None) -> None:
    """Raise at the deck line of the first pair of overlapping bodies among ``index``
    (default: all bodies)."""
    idx = np.arange(len(bodies)) if index is None else np.asarray(index, np.int64)
    if len(idx) < 2:
        return
    shapes = [model.shapes[int(bodies.shape_id[i])].shape for i in idx]
    radii = np.array([float(s.bounding_radius) for s in shapes])
    pos = bodies.position[idx]
    R = bodies.rotation_matrices()[idx]
    pile = None             # the particles' mass, once an overlap needs it
    for a, b in close_pairs(pos, radii):
        depth = pair_penetration(shapes[a], pos[a], R[a], shapes[b], pos[b], R[b])
        r = min(radii[a], radii[b])
        if depth <= OVERLAP_TOLERANCE * r:
            continue
        i, j = int(idx[a]), int(idx[b])
        if bodies.line[i] < bodies.line[j]:
            i, j = j, i
        mats = (int(bodies.material_id[i]), int(bodies.material_id[j]))
        reduced = radii[a] * radii[b] / (radii[a] + radii[b])
        resting = 0.0 if math.isinf(depth) else static_overlap(
            model, "particle-particle", mats,
            max(_body_mass(model, bodies, i), _body_mass(model, bodies, j)), reduced)
        if pile is None:
            pile = pile_mass(model, bodies)
        tol = allowed_overlap(r, resting, 0.0 if math.isinf(depth) else static_overlap(
            model, "particle-particle", mats, pile, reduced))
        if depth > tol:
            raise model.error(_overlap_text(bodies, i, j, depth, tol), int(bodies.line[i]))
        _warn_deep(model, int(bodies.line[i]), f"particle {bodies.id[i]} overlaps particle "
                   f"{bodies.id[j]}", depth, r, resting)


def _overlap_text(bodies: "Bodies", i: int, j: int, depth: float, tol: float) -> str:
    what = ("is at the same place as" if math.isinf(depth)
            else "overlaps particle")
    if math.isinf(depth):
        return (f"particle {bodies.id[i]} {what} particle {bodies.id[j]} (their centroids "
                f"coincide)")
    return (f"particle {bodies.id[i]} {what} {bodies.id[j]} by {depth:.3g} m; at most "
            f"{tol:.3g} m is accepted ({_allowed_rule()})")


# ---------------------------------------------------------------------------- walls


def check_walls(model: "Model") -> None:
    """Every wall has finite corners and a finite, non-zero normal."""
    for w in model.walls:
        try:
            wall_plane(w)
        except ValueError as exc:
            of = " of the Box" if w.kind == "box" else ""
            raise model.error(f"wall {w.name!r}{of}: {exc}", w.line) from None


def plane_support_distance(shape: "Shape", centroid: np.ndarray, R: np.ndarray,
                           point: np.ndarray, n: np.ndarray) -> float:
    """Signed distance (m) along the unit normal n from the plane through ``point`` to the
    body's deepest point (its support point along -n, paper Eq. 8): < 0 penetration."""
    from .contact.flat_wall import detect_wall

    t1 = np.cross(n, [1.0, 0.0, 0.0])
    if np.linalg.norm(t1) < 0.5:
        t1 = np.cross(n, [0.0, 1.0, 0.0])
    t1 /= np.linalg.norm(t1)
    t2 = np.cross(n, t1)
    r = float(shape.bounding_radius)
    shift = float(n @ (centroid - point))
    big = 4.0 * r
    o = centroid - shift * n - big * (t1 + t2)   # a probe square under the body, in the plane
    res = detect_wall(shape, _pose(shape, centroid, R), (o, 2 * big * t1, 2 * big * t2))
    if res.failed or not math.isfinite(res.signed_distance):
        return shift - r   # conservative: the bounding sphere
    return float(res.signed_distance)


def check_bodies_against_walls(model: "Model", bodies: "Bodies",
                               index: Sequence[int] | None = None,
                               line: int | None = None, label: str = "",
                               reference: Sequence[int] | None = None) -> None:
    """Raise when a body (of ``index``, default all) is behind a wall or penetrates one.

    line, label: report at this deck line with this prefix (e.g. a Replicate step) instead
    of the body's own line.  reference: for each indexed body, a body whose penetration of
    the same wall it may share (a replicated copy inherits the small penalty penetration of
    its settled original; only a deeper one is an error).
    """
    if not model.walls or not len(bodies):
        return
    idx = np.arange(len(bodies)) if index is None else np.asarray(index, np.int64)
    if not len(idx):
        return
    shapes = [model.shapes[int(bodies.shape_id[i])].shape for i in idx]
    radii = np.array([float(s.bounding_radius) for s in shapes])
    pos = bodies.position[idx]
    R = bodies.rotation_matrices()[idx]
    pile = None             # the particles' mass, once a penetration needs it
    for w in model.walls:
        o, a, b, n = wall_plane(w)
        h = (pos - o) @ n                     # centroid height above the wall's plane
        inside = _inside_rectangle(pos, o, a, b, radii)
        behind = (h < 0) & (inside | (w.kind == "box"))
        for k in np.nonzero(behind)[0]:
            i = int(idx[k])
            where = ("outside the box (behind its wall " f"{w.name!r})" if w.kind == "box"
                     else f"behind wall {w.name!r}, on the side its Normal points away from "
                          f"(a wall's Normal must point towards the particles)")
            raise model.error(f"{label}particle {bodies.id[i]} (centroid {_vec(pos[k])} m) "
                              f"is {where}", int(bodies.line[i]) if line is None else line)
        under = _inside_rectangle(pos, o, a, b, np.zeros(len(pos)))
        near = np.nonzero(under & (h >= 0) & (h < radii))[0]
        for k in near:
            sd = plane_support_distance(shapes[k], pos[k], R[k], o, n)
            if sd >= -OVERLAP_TOLERANCE * radii[k]:
                continue
            i = int(idx[k])
            resting = static_overlap(model, "particle-wall", (int(bodies.material_id[i]),),
                                     _body_mass(model, bodies, i), radii[k], w.material_id)
            if pile is None:
                pile = pile_mass(model, bodies)
            tol = allowed_overlap(radii[k], resting, static_overlap(
                model, "particle-wall", (int(bodies.material_id[i]),), pile, radii[k],
                w.material_id))
            if sd < -tol and reference is not None:
                j = int(reference[k])
                tol -= min(0.0, plane_support_distance(
                    model.shapes[int(bodies.shape_id[j])].shape, bodies.position[j],
                    bodies.rotation_matrices()[j], o, n))
            at = int(bodies.line[i]) if line is None else line
            if sd < -tol:
                raise model.error(
                    f"{label}particle {bodies.id[i]} penetrates wall {w.name!r} by "
                    f"{-sd:.3g} m; at most {tol:.3g} m is accepted ({_allowed_rule()}); move "
                    f"it at least {-sd - tol:.3g} m along the wall's normal {_vec(n)}", at)
            _warn_deep(model, at, f"{label}particle {bodies.id[i]} penetrates wall {w.name!r}",
                       -sd, radii[k], resting)


# ---------------------------------------------------------------------------- the model

#: A deck step must not be shorter than this fraction of its step's Duration.
MIN_STEP_FRACTION = 1e-9
#: Refuse runs that would need more internal time steps than this (years of computing).
MAX_INTERNAL_STEPS = 10 ** 10
#: Rough memory per particle in the solver (state, contact search, histories), bytes.
BYTES_PER_BODY = 16 * 1024
#: Bytes per tessellation vertex of a VTK frame (points, point data, quads, meshio copies).
BYTES_PER_VERTEX = 400


def available_memory() -> int:
    """Physical memory of this machine (bytes); 16 GiB when it cannot be read."""
    import os
    try:
        return int(os.sysconf("SC_PAGE_SIZE")) * int(os.sysconf("SC_PHYS_PAGES"))
    except (ValueError, OSError, AttributeError):  # pragma: no cover - not POSIX
        return 16 * 1024 ** 3


def check_nothing_to_solve(model: "Model") -> None:
    """A deck must define particles (or an inlet that creates them) and at least one step."""
    if not model.steps:
        raise model.error("the deck defines no solution steps (a Steps block with e.g. "
                          "'Step 1 Dynamic Duration T TimeStep DT'): nothing to solve", None)
    if model.particle_count == 0 and not model.inlets:
        raise model.error("the deck defines no particles (a Particles block with Particle or "
                          "Random entries, or a Flow block with an Inlet): nothing to solve",
                          None)


def check_time_steps(model: "Model") -> None:
    """Every timed step has TimeStep >= :data:`MIN_STEP_FRACTION` x Duration and a Duration
    that is a whole number of TimeSteps (else the solver would stop when it gets there)."""
    for s in model.steps:
        dur, dt = float(getattr(s, "duration", 0.0) or 0.0), float(getattr(s, "time_step", 0.0) or 0.0)
        if dur > 0 and dt > 0 and dt < MIN_STEP_FRACTION * dur:
            raise model.error(
                f"Step {s.id}: TimeStep {dt:g} s is below {MIN_STEP_FRACTION:g} of the Duration "
                f"{dur:g} s: {dur / dt:.3g} time steps would never finish", s.line)
        if dur > 0 and dt > 0:
            n = max(1, round(dur / dt))
            if abs(n * dt - dur) > 1e-9 * dur:   # the solver's rule, known before it runs
                raise model.error(
                    f"Step {s.id}: Duration {dur:g} s is not a whole number of TimeStep {dt:g} s "
                    f"({dur / dt:.6g} steps); use e.g. TimeStep {dur / max(1, math.ceil(dur / dt)):.6g}",
                    s.line)


def check_memory(model: "Model") -> None:
    """Refuse particle counts (Counts, Replicate Layers) and VTK resolutions whose memory
    would exceed this machine's, saying how much they would need."""
    have = available_memory()
    n, line = max_particle_count(model)
    need = n * BYTES_PER_BODY
    if need > have:
        where = line if line is not None else _first_particle_line(model)
        raise model.error(f"{n:.4g} particles would need about {gib(need)} of memory; this "
                          f"machine has {gib(have)}", where)
    out = model.output
    if out is None or not model.shapes:
        return
    patches = max(len(e.shape.patches) for e in model.shapes.values())
    verts = n * patches * (int(out.vtk_resolution) + 1) ** 2
    need = verts * BYTES_PER_VERTEX
    if need > have / 2:
        raise model.error(f"VTK Resolution {out.vtk_resolution} would need about {gib(need)} "
                          f"for one frame of {n:.4g} particles ({verts:.3g} vertices); this "
                          f"machine has {gib(have)}: lower Resolution", _output_line(model))


def _first_particle_line(model: "Model") -> int | None:
    lines = [g.line for g in model.random_groups] + [p.line for p in model.particles]
    return min(lines) if lines else None


def _particle_masses(model: "Model") -> dict[int, float]:
    """Smallest effective particle mass (kg) per material id used by particles: the mass,
    or the rotational inertia seen at the bounding radius when that is smaller."""
    out: dict[int, float] = {}
    uses = [(g.material_id, sid) for g in model.random_groups for sid in g.shape_ids]
    uses += [(p.material_id, p.shape_id) for p in model.particles]
    for mid, sid in uses:
        if mid in model.materials and sid in model.shapes:
            entry, rho = model.shapes[sid], model.materials[mid].density
            m = entry.mass(rho)
            # a contact at the bounding radius R also drives rotation: J_min / R^2
            j_min = float(np.linalg.eigvalsh(entry.mass_inertia(rho))[0])
            m_rot = j_min / entry.bounding_radius ** 2 if j_min > 0 else 0.0
            out[mid] = min(out.get(mid, math.inf), m, m_rot)
    return out


def check_step_count(model: "Model") -> None:
    """Refuse a run whose explicit integration would need more than
    :data:`MAX_INTERNAL_STEPS` internal time steps (the stiffest contact law on the lightest
    particle, translational modes only: an optimistic estimate)."""
    masses = _particle_masses(model)
    if not masses:
        return
    dt_cr, worst = math.inf, None
    for itf in model.interfaces:
        if itf.model != "linear":
            continue      # Hertz: no constant stiffness (the solver's own estimate applies)
        for mid, m in masses.items():
            for k, c in ((itf.normal_penalty, itf.normal_damping),
                         (itf.tangential_penalty, itf.tangential_damping)):
                dt = critical_step(k, c, 0.5 * m)[2]
                if dt < dt_cr:
                    dt_cr, worst = dt, (itf, mid, m)
    if worst is None:
        return
    run = sum(s.duration_s for s in model.steps)
    steps = run / (0.5 * dt_cr) if dt_cr > 0 else math.inf
    if steps > MAX_INTERNAL_STEPS:
        itf, mid, m = worst
        raise model.error(
            f"Interface {itf.id}: with material {mid} (smallest effective mass {m:.3g} kg) the "
            f"explicit critical time step is about {dt_cr:.3g} s, so the {run:g} s of the run "
            f"would need about {steps:.3g} internal time steps (at most "
            f"{MAX_INTERNAL_STEPS:.0e}): lower the penalties or damping, or raise the Density",
            itf.line)


def check_impacts(model: "Model") -> None:
    """Refuse a particle so fast that it would sink deeper than its own size into what it
    hits: v sqrt(m / en) > bounding radius (undamped normal spring), which no time step can
    resolve."""
    for p in model.particles:
        v = float(np.linalg.norm(p.velocity))
        if p.shape_id in model.shapes:   # surface speed of the spin
            v += float(np.linalg.norm(p.angular_velocity)) * model.shapes[p.shape_id].bounding_radius
        if v == 0 or p.shape_id not in model.shapes or p.material_id not in model.materials:
            continue
        entry = model.shapes[p.shape_id]
        m = entry.mass(model.materials[p.material_id].density)
        ens = [i.normal_penalty for i in model.interfaces if i.model == "linear"
               and (i.materials is None or p.material_id in i.materials)]
        if not ens:
            continue
        en = min(ens)
        r = entry.bounding_radius
        depth = v * math.sqrt(m / en)
        if depth > r:
            raise model.error(
                f"Particle {p.id}: at {v:.3g} m/s (centroid plus spin) it would sink about {depth:.3g} m into what it "
                f"hits (mass {m:.3g} kg, NormalPenalty {en:g} N/m), more than its size "
                f"({r:.3g} m), which no time step can resolve: lower its speed below "
                f"{r * math.sqrt(en / m):.3g} m/s or raise NormalPenalty above "
                f"{m * v * v / (r * r):.3g} N/m", p.line)


def check_soft_contacts(model: "Model") -> None:
    """Refuse a contact too soft to carry a particle's weight: a static overlap
    (:func:`static_overlap`, the particle resting on a wall or on a particle of its own
    material) beyond :data:`SOFT_FRACTION` of its bounding radius, which would sink it
    through what carries it before the run stops as unstable. Raised at the Interface's
    line with the numbers and the stiffness that would carry the load."""
    if model.gravity is None or not float(np.linalg.norm(model.gravity)) > 0:
        return
    uses = {(p.material_id, p.shape_id) for p in model.particles}
    uses |= {(g.material_id, s) for g in model.random_groups for s in g.shape_ids}
    wall_mats = {w.material_id for w in model.walls}
    for mid, sid in sorted(uses, key=lambda u: (u[0], u[1])):
        if mid not in model.materials or sid not in model.shapes:
            continue
        entry = model.shapes[sid]
        m, r = entry.mass(model.materials[mid].density), float(entry.bounding_radius)
        cases = [("particle-wall", (mid,), r, wm) for wm in sorted(wall_mats, key=str)]
        if model.particle_count > 1:
            cases.append(("particle-particle", (mid, mid), 0.5 * r, None))
        for kind, mats, radius, wm in cases:
            d = static_overlap(model, kind, mats, m, radius, wm)
            if d > SOFT_FRACTION * r:
                raise model.error(_soft_text(model, kind, mats, m, r, d),
                                  model.interface(kind, mats).line)


def _soft_text(model: "Model", kind: str, mats: tuple[int, ...], m: float, r: float,
               d: float) -> str:
    itf = model.interface(kind, mats)
    g = float(np.linalg.norm(model.gravity))
    if itf.model == "linear":
        law = (f"m g / NormalPenalty = {m:.3g} kg x {g:.3g} m/s^2 / {itf.normal_penalty:g} N/m; "
               f"raise NormalPenalty above {m * g / (SOFT_FRACTION * r):.3g} N/m")
    else:
        law = ("the Hertz overlap under that weight; raise the materials' YoungModulus "
               f"about {(d / (SOFT_FRACTION * r)) ** 1.5:.3g} times")
    on = "a wall" if kind == "particle-wall" else "another"
    return (f"Interface {itf.id}: the contact is too soft for the load: a particle of material "
            f"{mats[0]} ({m:.3g} kg) resting on {on} "
            f"sinks {d:.3g} m into it under gravity, more than {SOFT_FRACTION:g} of its bounding "
            f"radius {r:.3g} m ({law})")


def check_replicate_spacing(model: "Model") -> None:
    """A Replicate step whose layer spacing Height / (Layers - 1) is below the smallest
    vertical extent a particle can have, V / (pi R^2) (volume over the largest projected
    area), stacks copies into each other whatever the particles do before it."""
    from .model import ReplicateStep
    used = {sid for g in model.random_groups for sid in g.shape_ids}
    used |= {p.shape_id for p in model.particles}
    extents = [(model.shapes[s].shape.volume / (math.pi * model.shapes[s].bounding_radius ** 2), s)
               for s in used if s in model.shapes]
    if not extents:
        return
    extent, sid = max(extents)
    for s in model.steps:
        if isinstance(s, ReplicateStep) and s.layers > 1:
            spacing = s.height / (s.layers - 1)
            if spacing < extent:
                raise model.error(
                    f"Step {s.id}: the layers would be {spacing:.3g} m apart (Height / (Layers - "
                    f"1)), less than the {extent:.3g} m that any particle of shape {sid} extends "
                    f"vertically: the copies would overlap; use Height >= "
                    f"{extent * (s.layers - 1):.4g} m", s.line)


#: Random sequential placement of spheres jams at about this volume fraction.
JAMMING_FRACTION = 0.38


def check_random_fill(model: "Model") -> None:
    """Refuse a ``Random`` group whose bounding spheres would fill more of its region than
    random sequential placement can reach (it would try for a long time, then fail)."""
    for g in model.random_groups:
        if any(s not in model.shapes for s in g.shape_ids):
            continue
        vol = float(np.prod(np.asarray(g.region_hi, float) - np.asarray(g.region_lo, float)))
        spheres = sum(n * 4.0 / 3.0 * math.pi * model.shapes[s].bounding_radius ** 3
                      for s, n in zip(g.shape_ids, g.counts))
        if vol > 0 and spheres > JAMMING_FRACTION * vol:
            raise model.error(
                f"Random {g.id}: the bounding spheres of its {g.total} particles fill "
                f"{100 * spheres / vol:.0f} % of the Region, but random placement jams at about "
                f"{100 * JAMMING_FRACTION:.0f} %: enlarge Region to at least "
                f"{spheres / JAMMING_FRACTION:.3g} m^3 or reduce Counts", g.line)


def check_wall_moves(model: "Model") -> None:
    """A ``MoveWall ... ToContact Direction d`` must move a flat wall towards the particles
    (d . normal > 0); otherwise no travel reaches them."""
    from .model import MoveWallStep
    for s in model.steps:
        if not (isinstance(s, MoveWallStep) and s.to_contact and s.direction is not None):
            continue
        if s.wall not in [w.name for w in model.walls]:
            continue                           # unknown, or a mesh or surface wall
        n = wall_plane(model.wall(s.wall))[3]
        if float(np.asarray(s.direction, float) @ n) <= 1e-12:
            raise model.error(f"Step {s.id}: Direction {_vec(s.direction)} does not move wall "
                              f"{s.wall!r} towards the particles (its normal is {_vec(n)})",
                              s.line)


def check_wall_strokes(model: "Model") -> None:
    """A ``MoveWall ... Displacement`` must not drive a wall past a wall facing it (e.g. a lid
    through the floor): the travel along its normal, summed over the steps (ToContact moves
    only add to it and are not counted), must stay below their initial distance."""
    from .model import MoveWallStep
    planes = {w.name: wall_plane(w) for w in model.walls}
    travel: dict[str, float] = {}
    for s in model.steps:
        if not (isinstance(s, MoveWallStep) and not s.to_contact):
            continue
        for m in s.moves():
            if m.wall not in planes:
                continue
            o, _, _, n = planes[m.wall]
            before = travel.get(m.wall, 0.0)
            travel[m.wall] = before + float(m.net_displacement() @ n)
            peak = (before + float(np.max(m.table.displacement @ n)) if m.table is not None
                    else travel[m.wall])        # a table's farthest row
            for other, (o2, _, _, n2) in planes.items():
                if other == m.wall or float(n @ n2) > -0.9:
                    continue
                gap = float((o2 - o) @ n)
                if gap > 0 and peak >= gap:
                    raise model.error(
                        f"Step {s.id}: wall {m.wall!r} would have moved {peak:.4g} m towards "
                        f"the particles in this step, past wall {other!r} that faces it "
                        f"{gap:.4g} m away: the particles would be crushed through it", m.line)


def check_scale(model: "Model") -> None:
    """Positions must be resolvable at particle scale: the largest coordinate of the scene
    at most 1e9 times the smallest particle's bounding radius."""
    radii = [e.bounding_radius for e in model.shapes.values()]
    if not radii:
        return
    coords = [np.abs(p.position).max() for p in model.particles]
    coords += [max(np.abs(g.region_lo).max(), np.abs(g.region_hi).max()) for g in model.random_groups]
    coords += [float(np.abs(w.patch.control_points).max()) for w in model.walls]
    if coords and max(coords) > 1e9 * min(radii):
        raise model.error(f"the scene extends {max(coords):.3g} m from the origin but the "
                          f"smallest particle is {min(radii):.3g} m across: float64 positions "
                          f"cannot resolve its contacts (ratio at most 1e9)", None)


def check_model(model: "Model") -> None:
    """Everything that can be judged before placing particles: something to solve, time
    steps, memory, explicit stability, contacts too soft for the weight, impacts, Replicate
    spacing, scale, wall strokes, the periodic cell."""
    from .periodic_checks import check_periodic
    from .wall_checks import check_curved_walls_model
    check_nothing_to_solve(model)
    check_time_steps(model)
    check_memory(model)
    check_walls(model)
    check_scale(model)
    check_random_fill(model)
    check_wall_moves(model)
    check_wall_strokes(model)
    check_curved_walls_model(model)
    check_step_count(model)
    check_soft_contacts(model)
    check_impacts(model)
    check_replicate_spacing(model)
    check_periodic(model)


# ---------------------------------------------------------------------------- the scene


def validate_scene(model: "Model", bodies: "Bodies | None" = None) -> None:
    """Check the placed scene (default ``model.bodies``): walls, bodies in the periodic cell,
    bodies against walls (mesh and surface walls too), explicit bodies against each other; warn
    of inlets that reach behind a wall or cannot hold a segment's particles, of ParaView
    samples that would not fit their disk (:mod:`nurbsdem.output_checks`) and of surface
    walls that curve more tightly than a particle (:mod:`nurbsdem.curvature_checks`).
    Raises :class:`InputError` (deck file and line)."""
    from .curvature_checks import warn_tight_surfaces
    from .flow_checks import warn_flow
    from .periodic_checks import check_periodic_bodies
    from .wall_checks import check_curved_walls_scene
    bodies = model.bodies if bodies is None else bodies
    check_walls(model)
    check_periodic_bodies(model, bodies, plane_support_distance)
    warn_flow(model)
    warn_output_size(model)
    warn_tight_surfaces(model)
    if bodies is not None and len(bodies):
        explicit = {p.id for p in model.particles}
        index = [i for i in range(len(bodies)) if int(bodies.id[i]) in explicit]
        check_body_overlaps(model, bodies, index)
        check_bodies_against_walls(model, bodies)
    check_curved_walls_scene(model, bodies)


__all__ = ["OVERLAP_TOLERANCE", "COINCIDENT_FRACTION", "RESTING_LOADS", "MAX_RESTING_FRACTION",
           "SOFT_FRACTION", "WARN_OVERLAP_FRACTION", "static_overlap", "allowed_overlap",
           "check_soft_contacts", "pair_penetration", "close_pairs",
           "check_body_overlaps", "check_walls", "check_bodies_against_walls",
           "plane_support_distance", "validate_scene", "check_model", "wall_plane", "InputError"]

"""Initial particle placement and layer replication (of :class:`nurbsdem.model.Bodies`).

* :func:`initial_bodies` — the deck's ``Particle`` and ``Random`` entries as a
  :class:`Bodies` (sorted by id).
* :func:`place_random_group` — ``Random`` groups: uniform positions inside the region (the
  whole bounding sphere inside the region box), uniform random orientations, no two
  bounding spheres overlapping (conservative), reproducible from the seed
  (``numpy.random.default_rng(seed)``), largest bodies first.
* :func:`replicate_layers` — the ``Replicate`` step.

Orientation convention: unit quaternion ``q = (w, x, y, z)`` (scalar first) whose rotation
matrix ``R`` maps the shape's file frame to the world; a body's surface point is
``x_world = position + R @ (x_file - centroid_file)`` where ``position`` is the centroid in
the world (see docs/conventions.md: pose position = position - R @ centroid_file).
"""
from __future__ import annotations

from typing import TYPE_CHECKING, Mapping, Sequence

import numpy as np
from numba import njit

from .errors import InputError
from .geometry.overlap import bodies_overlap, sampled_surface as _sampled
from .geometry.rotation import quat_from_rotvec, random_quaternions
from .geometry.sphere_grid import add_sphere, add_spheres, is_clear, sphere_grid
from .model import Bodies

if TYPE_CHECKING:  # pragma: no cover
    from .geometry.shape import Shape
    from .model import Model, RandomGroup, ReplicateStep


def first_overlap(bodies: Bodies, shapes: Mapping[int, "Shape"],
                  candidates: Sequence[int] | None = None,
                  others: Sequence[int] | None = None) -> tuple[int, int] | None:
    """The first pair (i, j) of overlapping bodies (indices into ``bodies``), or None.

    candidates, others: restrict the test to pairs (i in candidates, j in others, i != j);
    by default all pairs i < j.
    """
    R = bodies.rotation_matrices()
    n = len(bodies)
    if others is None:
        cand = range(n) if candidates is None else candidates
        pairs = ((i, j) for i in cand for j in range(i + 1, n))
    else:
        cand = range(n) if candidates is None else candidates
        pairs = ((i, j) for i in cand for j in others if j != i)
    for i, j in pairs:
        if bodies_overlap(shapes[int(bodies.shape_id[i])], bodies.position[i], R[i],
                          shapes[int(bodies.shape_id[j])], bodies.position[j], R[j]):
            return int(i), int(j)
    return None


# ---------------------------------------------------------------------------- placement


def _shape_map(model: "Model") -> dict[int, "Shape"]:
    return {sid: e.shape for sid, e in model.shapes.items()}


def explicit_bodies(model: "Model") -> Bodies:
    """The deck's ``Particle`` entries as :class:`Bodies` (deck order)."""
    ps = model.particles
    if not ps:
        return Bodies.empty()
    return Bodies(
        id=[p.id for p in ps], shape_id=[p.shape_id for p in ps],
        material_id=[p.material_id for p in ps],
        position=np.array([p.position for p in ps]),
        quaternion=quat_from_rotvec(np.array([p.rotation for p in ps])),
        velocity=np.array([p.velocity for p in ps]),
        angular_velocity=np.array([p.angular_velocity for p in ps]),
        line=[p.line for p in ps])


def check_explicit_overlaps(model: "Model", bodies: Bodies) -> None:
    """Raise ``deck:LINE: particle I overlaps particle J ...`` for the first overlapping pair
    of explicit bodies (LINE is the later of the two entries): bounding spheres, then the
    exact LCP (:func:`nurbsdem.validation.check_body_overlaps`; coincident bodies included)."""
    from .validation import check_body_overlaps
    check_body_overlaps(model, bodies)


# ---------------------------------------------------------------------------- random placement
#: outcomes of :func:`_place_from`
_PLACED, _NEEDS_DRAWS, _FAILED = 0, 1, 2
#: uniform numbers drawn at a time for the random placement (3 per attempt)
_DRAW_BLOCK = 3 * 4096


@njit(cache=True)
def _place_from(grid, order: np.ndarray, radii: np.ndarray, lo: np.ndarray, hi: np.ndarray,
                draws: np.ndarray, at: int, start: int, tried: int, max_attempts: int,
                first_sphere: int, position: np.ndarray) -> tuple[int, int, int, int]:
    """Place the bodies order[start:] (radii (n,), m) one by one at uniform positions with
    the sphere inside [lo + r, hi − r] and clear of the grid's spheres, up to max_attempts
    each (the body order[start] has had ``tried`` already), taking three uniform numbers
    of ``draws`` from ``at`` per attempt: x = (lo + r) + ((hi − r) − (lo + r)) u, the
    arithmetic of ``Generator.uniform(lo + r, hi − r)``.  Placed bodies go into position
    (n,3) and into the grid (as sphere first_sphere + their rank in order).  Returns
    (the rank in order reached, its attempts so far, the next draw, _PLACED / _NEEDS_DRAWS /
    _FAILED)."""
    for p in range(start, order.shape[0]):
        k = order[p]
        r = radii[k]
        attempts = tried if p == start else 0
        ok = False
        x = y = z = 0.0
        while attempts < max_attempts:
            if at + 3 > draws.shape[0]:
                return p, attempts, at, _NEEDS_DRAWS
            x0, y0, z0 = lo[0] + r, lo[1] + r, lo[2] + r
            x = x0 + ((hi[0] - r) - x0) * draws[at]
            y = y0 + ((hi[1] - r) - y0) * draws[at + 1]
            z = z0 + ((hi[2] - r) - z0) * draws[at + 2]
            at += 3
            attempts += 1
            if is_clear(grid, x, y, z, r):
                ok = True
                break
        if not ok:
            return p, attempts, at, _FAILED
        position[k, 0], position[k, 1], position[k, 2] = x, y, z
        add_sphere(grid, first_sphere + p, x, y, z, r)
    return order.shape[0], 0, at, _PLACED


def place_random_group(model: "Model", group: "RandomGroup",
                       obstacles: tuple[np.ndarray, np.ndarray]) -> Bodies:
    """Place one ``Random`` group.

    Parameters
    ----------
    obstacles: (centres (K, 3), radii (K,)) of bounding spheres already placed (m).

    Each body is tried up to ``group.max_attempts`` times at a uniform position with its
    bounding sphere inside the region and clear of every bounding sphere placed so far;
    larger bodies are placed first. Bodies get ids ``group.id ..`` in ``Shapes`` order,
    velocities zero. Raises :class:`InputError` at the group's line when that fails.
    """
    rng = np.random.default_rng(group.seed)
    shape_ids = np.repeat(np.array(group.shape_ids, np.int64), group.counts)
    n = len(shape_ids)
    radii = np.array([model.shapes[int(s)].bounding_radius for s in shape_ids])
    lo, hi = np.asarray(group.region_lo, float), np.asarray(group.region_hi, float)
    for sid, r in zip(group.shape_ids, [model.shapes[s].bounding_radius for s in group.shape_ids]):
        if np.any(hi - lo < 2 * r):
            raise model.error(f"Random {group.id}: the region is too small for shape {sid} "
                              f"(bounding radius {r:.4g} m needs at least {2 * r:.4g} m in "
                              f"each direction)", group.line)
    centres = np.asarray(obstacles[0], float).reshape(-1, 3)
    obstacle_radii = np.asarray(obstacles[1], float).reshape(-1)
    radii_all = np.concatenate([obstacle_radii, radii])
    grid = sphere_grid(radii_all.shape[0], 2.0 * float(radii_all.max()) if radii_all.size
                        else 1.0)
    add_spheres(grid, centres, obstacle_radii)
    position = np.zeros((n, 3))
    quats = random_quaternions(rng, n)
    order = np.argsort(-radii, kind="stable")
    # the uniform numbers of rng.uniform(lo + r, hi - r) per attempt, drawn by the block
    draws, at, placed, tried, outcome = rng.random(_DRAW_BLOCK), 0, 0, 0, _NEEDS_DRAWS
    while outcome == _NEEDS_DRAWS:
        placed, tried, at, outcome = _place_from(grid, order, radii, lo, hi, draws, at, placed,
                                                 tried, int(group.max_attempts),
                                                 centres.shape[0], position)
        if outcome == _NEEDS_DRAWS:
            draws, at = np.concatenate([draws[at:], rng.random(_DRAW_BLOCK)]), 0
    if outcome == _FAILED:
        k = order[placed]
        raise model.error(
            f"Random {group.id}: could not place particle {group.id + k} (shape "
            f"{shape_ids[k]}) without overlap after {group.max_attempts} attempts "
            f"({placed} of {n} placed); enlarge Region or reduce Counts", group.line)
    z = np.zeros((n, 3))
    return Bodies(id=np.arange(group.id, group.id + n), shape_id=shape_ids,
                  material_id=np.full(n, group.material_id), position=position,
                  quaternion=quats, velocity=z, angular_velocity=z.copy(),
                  line=np.full(n, group.line))


def initial_bodies(model: "Model") -> Bodies:
    """All particles of the deck, sorted by id: explicit ``Particle`` bodies (checked for
    overlap with each other by :func:`bodies_overlap`), then each ``Random`` group placed
    around them (bounding spheres). Raises :class:`InputError` with the deck line."""
    explicit = explicit_bodies(model)
    check_explicit_overlaps(model, explicit)
    parts = [explicit]
    centres = explicit.position.copy()
    radii = np.array([model.shapes[int(s)].bounding_radius for s in explicit.shape_id])
    for g in model.random_groups:
        b = place_random_group(model, g, (centres, radii))
        parts.append(b)
        centres = np.concatenate([centres, b.position])
        radii = np.concatenate([radii, [model.shapes[int(s)].bounding_radius for s in b.shape_id]])
    return Bodies.concatenate(parts).sorted_by_id()


# ---------------------------------------------------------------------------- replicate


def replicate_layers(bodies: Bodies, layers: int, height: float,
                     axis: Sequence[float] = (0.0, 0.0, 1.0)) -> Bodies:
    """Stack copies of the current particles (the ``Replicate`` step).

    The current bodies are layer 0 and stay where they are; layer k = 1 .. layers-1 is a
    copy shifted by ``k * height / (layers - 1)`` along ``axis`` (default +z): the layers are
    spread over ``height`` (m) — the paper's "replicated eight times over a height of 50 cm"
    — from the original (bottom) layer to the last copy. Copies keep the orientations
    and shapes; their ids continue after the largest current id, layer by layer in the
    current body order. All velocities (including layer 0's) are zeroed. So 14 bodies with
    layers = 8 become 112.
    """
    if layers < 1:
        raise ValueError("layers must be >= 1")
    dz = float(height) / (layers - 1) if layers > 1 else 0.0
    ax = np.asarray(axis, float)
    ax = ax / np.linalg.norm(ax)
    n = len(bodies)
    base = bodies.copy()
    base.velocity[:] = 0.0
    base.angular_velocity[:] = 0.0
    parts = [base]
    next_id = int(base.id.max()) + 1 if n else 1
    for k in range(1, layers):
        c = base.copy()
        c.position = c.position + k * dz * ax
        c.id = np.arange(next_id, next_id + n, dtype=np.int64)
        next_id += n
        parts.append(c)
    return Bodies.concatenate(parts)


def layer_thickness(bodies: Bodies, shapes: Mapping[int, "Shape"],
                    axis: Sequence[float] = (0.0, 0.0, 1.0)) -> float:
    """Extent (m) of the bodies along ``axis``, from their sampled surfaces."""
    if not len(bodies):
        return 0.0
    ax = np.asarray(axis, float) / np.linalg.norm(axis)
    R = bodies.rotation_matrices()
    lo, hi = np.inf, -np.inf
    for i in range(len(bodies)):
        s = _sampled(shapes[int(bodies.shape_id[i])])
        h = bodies.position[i] @ ax + s.points @ (R[i].T @ ax)
        lo, hi = min(lo, h.min()), max(hi, h.max())
    return float(hi - lo)


def replicate_step(model: "Model", bodies: Bodies, step: "ReplicateStep") -> Bodies:
    """:func:`replicate_layers` for a deck step, refusing copies that would overlap.

    Layer 0 is tested against every copy (translation makes every other pair of layers a
    repeat of those); an overlap raises ``deck:LINE: Step ID: ...`` at the step's line.
    """
    out = replicate_layers(bodies, step.layers, step.height)
    n = len(bodies)
    if n == 0 or step.layers == 1:
        return out
    shapes = _shape_map(model)
    hit = first_overlap(out, shapes, candidates=range(n), others=range(n, len(out)))
    if hit is not None:
        t = layer_thickness(bodies, shapes)
        i, j = hit
        raise model.error(
            f"Step {step.id}: replicated layers overlap (particle {out.id[j]} of layer "
            f"{j // n} overlaps particle {out.id[i]}): the layer is {t:.4g} m thick but "
            f"Height / (Layers - 1) = {step.height / (step.layers - 1):.4g} m; use Height >= "
            f"{t * (step.layers - 1):.4g} m", step.line)
    from .validation import check_bodies_against_walls
    check_bodies_against_walls(model, out, index=range(n, len(out)), line=step.line,
                               label=f"Step {step.id}: after replication, ",
                               reference=[k % n for k in range(n, len(out))])
    return out


def bounding_sphere_overlaps(bodies: Bodies, radii: np.ndarray) -> list[tuple[int, int]]:
    """Pairs (i < j) whose bounding spheres overlap (for tests and diagnostics)."""
    d = np.linalg.norm(bodies.position[:, None] - bodies.position[None], axis=-1)
    rr = radii[:, None] + radii[None]
    i, j = np.nonzero(np.triu(d < rr, 1))
    return list(zip(i.tolist(), j.tolist()))


__all__ = ["Bodies", "initial_bodies", "place_random_group", "explicit_bodies",
           "check_explicit_overlaps", "replicate_layers", "replicate_step", "layer_thickness",
           "bodies_overlap", "first_overlap", "InputError"]

"""What the pre-run checks share (:mod:`nurbsdem.validation` for particles and flat walls,
:mod:`nurbsdem.wall_checks` for mesh and surface walls): the overlap a contact law carries at
rest, which decides how deep a starting overlap or wall penetration may be, and the planes of
flat walls.  Lengths in metres, masses in kilograms."""
from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:  # pragma: no cover
    from .model import Bodies, Model, WallSpec

#: Overlaps (and wall penetrations) up to this fraction of the smaller bounding radius are
#: accepted as touching (round-off of positions written with a few digits).
OVERLAP_TOLERANCE = 1e-6
#: An overlap up to this many static overlaps (:func:`static_overlap`, the depth at which the
#: contact carries the heavier body's weight) is a state the contact law holds at rest (a
#: settled pack's lowest contacts carry the weight of the column above them), so a settled
#: state written back into a deck runs; so is the overlap at which the contact carries the
#: weight of all the particles (a tall pile's lowest contacts carry more than 20 weights);
#: capped by :data:`MAX_RESTING_FRACTION`.
RESTING_LOADS = 20.0
#: Largest overlap accepted, as a fraction of the smaller bounding radius, whatever the load.
MAX_RESTING_FRACTION = 0.05
#: Accepted overlaps deeper than this fraction of the smaller bounding radius are reported
#: with a warning (the contact starts with a large force).
WARN_OVERLAP_FRACTION = 0.01
#: A contact whose static overlap under one particle's weight exceeds this fraction of the
#: particle's bounding radius is too soft for the load: the particle sinks into what carries
#: it by a tenth of its size, and a few stacked on it push it through.
SOFT_FRACTION = 0.1


# ---------------------------------------------------------------------------- resting overlaps


def static_overlap(model: "Model", kind: str, materials: tuple[int, ...], mass: float,
                   radius: float, wall_material: int | None = None) -> float:
    """Overlap (m) at which the contact law of a pair carries the weight m |g| at rest.

    kind, materials: the pair (:meth:`Model.interface`); mass (kg): the body it carries;
    radius (m): the pair's reduced bounding radius (Hertz: the radius of curvature).
    Linear penalty: m g / NormalPenalty; Hertz: (3 m g / (4 E* sqrt(R)))^(2/3) (the Hertz
    force 4/3 E* sqrt(R) d^(3/2) equal to the weight). 0 without gravity, without an
    interface for the pair, or for a law whose stiffness is not known here.
    """
    g = float(np.linalg.norm(model.gravity)) if model.gravity is not None else 0.0
    itf = model.interface(kind, tuple(materials))
    if g == 0 or itf is None or not mass > 0:
        return 0.0
    if itf.model == "linear":
        return mass * g / itf.normal_penalty if itf.normal_penalty > 0 else math.inf
    if itf.model != "hertz" or not radius > 0:
        return 0.0
    e_star = _hertz_modulus(model, materials, wall_material)
    if not e_star > 0 or not math.isfinite(e_star):
        return 0.0
    return (3.0 * mass * g / (4.0 * e_star * math.sqrt(radius))) ** (2.0 / 3.0)


def _hertz_modulus(model: "Model", materials: tuple[int, ...],
                   wall_material: int | None) -> float:
    """E* (Pa) of a pair's materials (a wall without material: rigid); 0 where a
    material lacks YoungModulus (the interface check says so)."""
    from .dynamics.laws.hertz_mindlin import effective_moduli
    mats = list(materials) + ([wall_material] if len(materials) == 1 else [])
    consts = []
    for mid in mats:
        if mid is None:
            consts.append((math.inf, 0.0))
            continue
        mat = model.materials.get(mid)
        if mat is None or mat.young_modulus is None:
            return 0.0
        consts.append((float(mat.young_modulus), float(mat.poisson_ratio or 0.0)))
    return effective_moduli(*consts[0], *consts[1])[0]


def _body_mass(model: "Model", bodies: "Bodies", i: int) -> float:
    entry = model.shapes[int(bodies.shape_id[i])]
    mat = model.materials.get(int(bodies.material_id[i]))
    return entry.mass(mat.density) if mat is not None else 0.0


def allowed_overlap(radius: float, resting: float, pile: float = 0.0) -> float:
    """The deepest overlap (m) accepted for a contact of smaller bounding radius ``radius``
    whose static overlap is ``resting`` (m) under the heavier body's weight and ``pile`` (m)
    under the weight of all the particles (:func:`pile_mass`): round-off, or up to the larger
    of :data:`RESTING_LOADS` static overlaps and ``pile``, but at most
    :data:`MAX_RESTING_FRACTION` of the radius."""
    return max(OVERLAP_TOLERANCE * radius,
               min(max(RESTING_LOADS * resting, pile), MAX_RESTING_FRACTION * radius))


def pile_mass(model: "Model", bodies: "Bodies") -> float:
    """The mass (kg) of all the particles of ``bodies``: the most a contact of a pile at rest
    under gravity carries (walls holding the rest)."""
    kinds, counts = np.unique(np.stack([np.asarray(bodies.shape_id, np.int64),
                                        np.asarray(bodies.material_id, np.int64)], axis=1),
                              axis=0, return_counts=True)
    total = 0.0
    for (shape, material), n in zip(kinds.tolist(), counts.tolist()):
        mat = model.materials.get(material)
        total += n * (model.shapes[shape].mass(mat.density) if mat is not None else 0.0)
    return total


def _warn_deep(model: "Model", line: int | None, text: str, depth: float, radius: float,
               resting: float) -> None:
    """One warning on the ``nurbsdem`` logger for an accepted overlap deeper than
    :data:`WARN_OVERLAP_FRACTION` of the radius."""
    if depth <= WARN_OVERLAP_FRACTION * radius:
        return
    import logging
    loc = f"{model.path}:{line}: " if model.path and line else ""
    load = f"; {depth / resting:.3g} x the overlap that carries its weight" if resting > 0 else ""
    logging.getLogger("nurbsdem").warning(
        f"{loc}{text} by {depth:.3g} m ({100 * depth / radius:.2g} % of its size{load}): "
        f"accepted, it starts with a large contact force")


def _allowed_rule() -> str:
    return (f"{RESTING_LOADS:g} x the overlap at which the contact carries the heavier "
            f"body's weight, or the overlap at which it carries all the particles' weight, at "
            f"most {MAX_RESTING_FRACTION:g} of the bounding radius")


# ---------------------------------------------------------------------------- flat walls


def wall_plane(wall: "WallSpec") -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(corner o, edge a, edge b, unit normal n) of a flat wall; raises ValueError when the
    wall is not finite or degenerate."""
    cp = np.asarray(wall.patch.control_points, float)
    if not np.isfinite(cp).all():
        raise ValueError("its corners are not finite numbers")
    o = cp[0, 0]
    a, b = cp[-1, 0] - o, cp[0, -1] - o
    from .ranges import RANGES
    shortest = RANGES["Size"].lo
    la, lb = _length(a), _length(b)
    if min(la, lb) < shortest:
        raise ValueError(f"its sides are {la:.3g} m and {lb:.3g} m long: each must be at "
                         f"least {shortest:g} m ({RANGES['Size'].reason})")
    scale = max(float(np.abs(a).max()), float(np.abs(b).max()), 1e-300)
    n = np.cross(a / scale, b / scale)
    norm = float(np.linalg.norm(n))
    if not (math.isfinite(norm) and norm > 1e-12):
        raise ValueError("its normal is zero or not a finite number")
    return o, a, b, n / norm


def _length(v: np.ndarray) -> float:
    """|v| without underflow for subnormal components (m)."""
    big = float(np.abs(v).max())
    return big * float(np.linalg.norm(v / big)) if big > 0 else 0.0


def _inside_rectangle(p: np.ndarray, o: np.ndarray, a: np.ndarray, b: np.ndarray,
                      margin: np.ndarray) -> np.ndarray:
    """Whether points p (N, 3) project inside the parallelogram o + s a + t b, widened by
    ``margin`` (N,) metres."""
    d = p - o
    la, lb = float(np.linalg.norm(a)), float(np.linalg.norm(b))
    s = d @ a / la
    t = d @ b / lb
    return (s >= -margin) & (s <= la + margin) & (t >= -margin) & (t <= lb + margin)

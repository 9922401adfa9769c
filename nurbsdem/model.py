"""The simulation model read from an input deck (see :mod:`nurbsdem.io.deck`).

Plain dataclasses, SI units throughout (m, kg, s, N). Every entry remembers the deck
line it came from (``line``) so later stages (placement, the solver) can raise
:class:`~nurbsdem.errors.InputError` pointing at it: ``model.error(msg, line)``.

Identifiers
-----------
* Particle ids are body numbers: ``Particle 15`` is body 15; ``Random 1 ... Counts 5 3 6``
  makes bodies 1..14 (its id is the id of its first body, then consecutive, in the order of
  its ``Shapes`` list). Ids never overlap.
* Wall ids likewise: ``Box 1`` makes walls 1..5 (``bottom, x_min, x_max, y_min, y_max``;
  6 with ``Top yes``: ``top``), ``Wall 6 Name lid`` is wall 6. Walls are referred to by name.

Mass properties
---------------
A body of shape S and material M has mass ``density * volume`` and mass inertia about its
centroid ``density * S.inertia`` (file frame) unless the shape entry overrides them:
``Volume V`` (m^3) replaces the volume; ``Inertia Jxx Jyy Jzz Jxy Jxz Jyz`` gives the MASS
inertia tensor in kg m^2 about the centroid, file frame, as tensor components (the matrix
``[[Jxx, Jxy, Jxz], [Jxy, Jyy, Jyz], [Jxz, Jyz, Jzz]]``, i.e. products of inertia already
carry their minus sign, like the paper's Table 1). An ``Inertia`` override is used as is
for every body of that shape, whatever its material (it is a property of the physical
particle, like the companion file of the authors' code).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, fields, is_dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, Mapping, Sequence

import numpy as np

from .errors import InputError
from .geometry.rotation import quat_to_matrix

if TYPE_CHECKING:  # pragma: no cover
    from .geometry.nurbs import Patch
    from .geometry.shape import Shape

#: Pair kinds a contact interface may be restricted to.
PAIR_KINDS = ("particle-particle", "particle-wall")


@dataclass
class Material:
    """``Material ID Density RHO [YoungModulus E] [PoissonRatio NU]``: density in kg/m^3;
    Young's modulus E (Pa, None: not given, needed by a HertzMindlin interface) and Poisson's
    ratio (-, default 0)."""

    id: int
    density: float
    line: int = 0
    young_modulus: float | None = None
    poisson_ratio: float = 0.0


@dataclass
class ShapeEntry:
    """``Shape ID File PATH`` | ``Sphere Radius R`` | ``Ellipsoid SemiAxes A B C`` (m),
    optionally ``Volume V`` (m^3) and ``Inertia Jxx Jyy Jzz Jxy Jxz Jyz`` (kg m^2, mass
    inertia about the centroid, file frame; see the module docstring).

    Attributes
    ----------
    kind: ``"file"``, ``"sphere"`` or ``"ellipsoid"``.
    source: the file as written in the deck (``kind == "file"``), else ``None``.
    file: the resolved file path, else ``None``.
    params: the generator's parameters (m): ``(R,)`` or ``(A, B, C)``.
    shape: the loaded :class:`~nurbsdem.geometry.shape.Shape` (file frame).
    volume_override: m^3 or ``None``.  inertia_override: (3, 3) kg m^2 or ``None``.
    """

    id: int
    kind: str
    shape: "Shape"
    source: str | None = None
    file: Path | None = None
    params: tuple[float, ...] = ()
    volume_override: float | None = None
    inertia_override: np.ndarray | None = None
    line: int = 0

    @property
    def name(self) -> str:
        """A label: the shape file's ``name``, else the generator description."""
        if self.shape.name:
            return str(self.shape.name)
        return self.source or self.kind

    @property
    def volume(self) -> float:
        """Volume (m^3): the override if given, else the shape's."""
        return float(self.volume_override if self.volume_override is not None
                     else self.shape.volume)

    @property
    def centroid(self) -> np.ndarray:
        """Centroid in the file frame (m)."""
        return np.asarray(self.shape.centroid, float)

    @property
    def bounding_radius(self) -> float:
        """Bounding-sphere radius about the centroid (m), paper Eq. 3."""
        return float(self.shape.bounding_radius)

    def mass(self, density: float) -> float:
        """Mass (kg) of a body of this shape with the given density (kg/m^3)."""
        return float(density) * self.volume

    def mass_inertia(self, density: float) -> np.ndarray:
        """Mass inertia tensor (3, 3) about the centroid, file frame, kg m^2.

        The ``Inertia`` override if given (independent of density), else
        ``density * shape.inertia``, scaled by ``volume_override / shape.volume`` when only
        the volume is overridden (so mass and inertia stay consistent).
        """
        if self.inertia_override is not None:
            return np.array(self.inertia_override, float)
        scale = self.volume / float(self.shape.volume)
        return float(density) * scale * np.asarray(self.shape.inertia, float)


@dataclass
class RandomGroup:
    """``Random ID Shapes S1 S2.. Counts N1 N2.. Material M Region x0 y0 z0 x1 y1 z1 Seed K``.

    Bodies ``id .. id + total - 1`` are placed at random (see :mod:`nurbsdem.placement`):
    counts[i] bodies of shape shape_ids[i], in that order. Region in m.
    """

    id: int
    shape_ids: tuple[int, ...]
    counts: tuple[int, ...]
    material_id: int
    region_lo: np.ndarray
    region_hi: np.ndarray
    seed: int = 0
    max_attempts: int = 20000
    line: int = 0

    @property
    def total(self) -> int:
        """Number of bodies in the group."""
        return int(sum(self.counts))

    @property
    def ids(self) -> range:
        """The body ids of the group."""
        return range(self.id, self.id + self.total)


@dataclass
class ParticleSpec:
    """``Particle ID Shape S Material M Position x y z [Rotation rx ry rz]
    [Velocity vx vy vz] [AngularVelocity wx wy wz]``.

    position: the centroid in the world (m). rotation: rotation vector (rad) of the file frame
    relative to the world. velocity (m/s) and angular_velocity (rad/s): world frame.
    """

    id: int
    shape_id: int
    material_id: int
    position: np.ndarray
    rotation: np.ndarray = field(default_factory=lambda: np.zeros(3))
    velocity: np.ndarray = field(default_factory=lambda: np.zeros(3))
    angular_velocity: np.ndarray = field(default_factory=lambda: np.zeros(3))
    line: int = 0


@dataclass
class WallSpec:
    """One wall: a NURBS patch in the world (its normal S_u x S_v points to the particles side).

    Made by ``Box ID Min x y z Max x y z [Top yes|no]`` (names bottom, x_min, x_max, y_min,
    y_max [, top]) or ``Wall ID Name N Point x y z Normal nx ny nz Size Lu Lv
    [Axis ax ay az]`` (a flat rectangle centred at Point, m); both take ``[Material m]``
    (material_id; None: rigid, for Hertz–Mindlin interfaces).
    """

    id: int
    name: str
    patch: "Patch"
    kind: str = "wall"
    line: int = 0
    material_id: int | None = None

    @property
    def normal(self) -> np.ndarray:
        """Unit normal at the patch's parametric centre (towards the particles)."""
        u0, u1, v0, v1 = self.patch.domain
        return np.asarray(self.patch.normals(0.5 * (u0 + u1), 0.5 * (v0 + v1)), float)

    @property
    def center(self) -> np.ndarray:
        """Point at the patch's parametric centre (m)."""
        u0, u1, v0, v1 = self.patch.domain
        return np.asarray(self.patch.points(0.5 * (u0 + u1), 0.5 * (v0 + v1)), float)


@dataclass
class PeriodicSpec:
    """A periodic cell, ``Periodic [X lo hi] [Y lo hi] [Z lo hi]`` (block Environment): the
    box [lo, hi) (m) repeats along the axes given (``axes`` (3,) bool; lo and hi are 0 on
    the others).  Particles leaving through a face come back through the opposite one and
    touch the particles near it (:mod:`nurbsdem.contact.periodic`)."""

    lo: np.ndarray
    hi: np.ndarray
    axes: np.ndarray
    line: int = 0

    def cell(self):
        """The :class:`~nurbsdem.contact.periodic.PeriodicCell` (the axes that do not repeat
        take a unit placeholder interval, unused)."""
        from .contact.periodic import make_cell
        return make_cell(np.where(self.axes, self.lo, 0.0), np.where(self.axes, self.hi, 1.0),
                         self.axes)


@dataclass
class CurvedWallSpec:
    """A wall of triangles or of NURBS patches, placed in the world (for exact spheres and
    NURBS particles).

    Made by ``Mesh ID Name n File f.stl [Scale s] [Position x y z] [Rotation rx ry rz]
    [Material m] [OneSided yes|no]`` (kind ``"mesh"``: an STL, OBJ or PLY surface, read by
    :func:`nurbsdem.io.meshfile.read_wall_mesh`; two-sided unless ``one_sided``) or
    ``Surface ID Name n File f.yaml [Position ..] [Rotation ..] [Material m]`` (kind
    ``"surface"``: the open patches of a shape file, their front S_u x S_v facing the
    particles).  ``x_world = R(rotation) (scale x_file) + position``; scale (-), position
    (m), rotation: a rotation vector (rad); file as written in the deck, resolved against
    the deck's folder (``path``).
    """

    id: int
    name: str
    kind: str
    file: str
    path: Path | None = None
    scale: float = 1.0
    position: np.ndarray = field(default_factory=lambda: np.zeros(3))
    rotation: np.ndarray = field(default_factory=lambda: np.zeros(3))
    material_id: int | None = None
    one_sided: bool = False
    line: int = 0


@dataclass
class Interface:
    """``Interface ID [Model LinearPenalty] NormalPenalty en [TangentialPenalty et]
    [NormalDamping cn] [TangentialDamping ct] [Friction mu] [RollingFriction mu_r]
    [RollingDamping eta_r] [Between particle-particle|particle-wall]
    [Materials m1 m2 | Materials m]``  (paper Eqs. 16-17), or
    ``Interface ID Model HertzMindlin Restitution e [Friction mu] [RollingFriction mu_r] [Between ..]
    [Materials ..]``
    (Hertz–Mindlin with the exact local curvature, :mod:`nurbsdem.dynamics.laws.hertz_mindlin`; the elastic
    constants come from the materials' YoungModulus and PoissonRatio).

    model: the law's ``model`` id (:mod:`nurbsdem.dynamics.laws`: ``"linear"``, the default, or
    ``"hertz"``); restitution: coefficient of restitution (Hertz only, 0 < e <= 1); params: the
    keys of a law that are not fields here (by their Python name; a law added at run time).
    Built by :func:`nurbsdem.dynamics.laws.interface.build_interface` for the deck and the
    Python API alike.

    normal_penalty (N/m), tangential_penalty (N/m), normal_damping (N s/m),
    tangential_damping (N s/m), friction (Coulomb coefficient, -), rolling_friction (the
    rolling-resistance coefficient μ_r, -: :mod:`nurbsdem.dynamics.rolling`; 0 none),
    rolling_damping (the rolling spring's damping ratio η_r, -; 0 none).
    between: ``None`` (all pairs) or one of :data:`PAIR_KINDS`.
    materials: ``None`` (any), ``(m1, m2)`` (particle-particle pairs of these materials,
    unordered) or ``(m,)`` (particle-wall pairs whose particle has material m).
    """

    id: int
    normal_penalty: float
    tangential_penalty: float = 0.0
    normal_damping: float = 0.0
    tangential_damping: float = 0.0
    friction: float = 0.0
    between: str | None = None
    materials: tuple[int, ...] | None = None
    line: int = 0
    model: str = "linear"
    restitution: float = 1.0
    params: dict[str, float] = field(default_factory=dict)
    rolling_friction: float = 0.0
    rolling_damping: float = 0.0

    def applies(self, kind: str, materials: tuple[int, ...]) -> bool:
        """Whether this interface covers a pair of the given kind and material ids
        (``(ma, mb)`` for particle-particle, ``(m,)`` for particle-wall)."""
        if self.between is not None and self.between != kind:
            return False
        if self.materials is None:
            return True
        if len(self.materials) != len(materials):
            return False
        return sorted(self.materials) == sorted(materials)


@dataclass(frozen=True)
class MaterialPair:
    """What a contact law may read of the two materials of an interface's pair, besides its
    own keys (``from_interface`` of the laws in :mod:`nurbsdem.dynamics.laws`).

    E_a, nu_a, E_b, nu_b: Young's moduli (Pa, ``inf``: rigid) and Poisson's ratios of the
    particle material A and of B (a particle material, or a wall's); m_eff (kg), radius (m):
    the reduced mass and the reduced bounding radius of the lightest particles of those
    materials (``inf`` and 0 where the deck places none); speed (m/s): a reference impact speed
    of the scene (:func:`material_pair`)."""

    E_a: float
    nu_a: float
    E_b: float
    nu_b: float
    m_eff: float
    radius: float
    speed: float


def material_pair(model: "Model", itf: Interface, law_name: str, mat_a: int, mat_b: int | None,
                  wall_material: int | None = None) -> MaterialPair:
    """The :class:`MaterialPair` of interface ``itf`` between particle materials mat_a and
    mat_b (deck ids; mat_b None: a wall of material ``wall_material``, None: rigid).  The
    reference speed is the largest of 1 m/s, the particles' initial speeds and the free-fall
    speed over the scene's height.  A material without YoungModulus is an input error at the
    interface's line (the laws that read the materials need it)."""
    mats = model.materials

    def elastic(mid: int) -> tuple[float, float]:
        mat = mats[mid]
        if mat.young_modulus is None:
            raise model.error(f"Interface {itf.id} (Model {law_name}) needs YoungModulus on "
                              f"Material {mat.id} (line {mat.line})", itf.line)
        return float(mat.young_modulus), float(mat.poisson_ratio or 0.0)

    E_a, nu_a = elastic(mat_a)
    if mat_b is None:
        E_b, nu_b = (math.inf, 0.0) if wall_material is None else elastic(wall_material)
    else:
        E_b, nu_b = elastic(mat_b)
    light = _lightest(model)
    m_a, r_a = light.get(mat_a, (math.inf, 0.0))
    if mat_b is None:
        m_eff, r = m_a, r_a
    else:
        m_b, r_b = light.get(mat_b, (math.inf, 0.0))
        m_eff = m_a * m_b / (m_a + m_b) if math.isfinite(m_a + m_b) else min(m_a, m_b)
        r = r_a * r_b / (r_a + r_b) if r_a + r_b > 0 else 0.0
    return MaterialPair(E_a, nu_a, E_b, nu_b, m_eff, r, _reference_speed(model))


def _lightest(model: "Model") -> dict[int, tuple[float, float]]:
    """Per particle material id: (smallest mass kg, the bounding radius of that shape m)."""
    out: dict[int, tuple[float, float]] = {}
    pairs = [(s, g.material_id) for g in model.random_groups for s in g.shape_ids]
    pairs += [(p.shape_id, p.material_id) for p in model.particles]
    for sid, mid in pairs:
        if sid not in model.shapes or mid not in model.materials:
            continue
        entry = model.shapes[sid]
        m = entry.mass(model.materials[mid].density)
        if m < out.get(mid, (math.inf, 0.0))[0]:
            out[mid] = (m, float(entry.bounding_radius))
    return out


def _reference_speed(model: "Model") -> float:
    """The largest of 1 m/s, the particles' initial speeds (centroid plus rotation at the
    bounding radius) and the free-fall speed over the scene's height (m/s)."""
    v = 1.0
    for p in model.particles:
        r = model.shapes[p.shape_id].bounding_radius if p.shape_id in model.shapes else 0.0
        v = max(v, float(np.linalg.norm(p.velocity)) + float(np.linalg.norm(p.angular_velocity)) * r)
    g = np.asarray(model.gravity, float)
    gn = float(np.linalg.norm(g))
    if gn > 0:
        pts = [np.asarray(w.center, float) for w in model.walls]
        pts += [np.asarray(gr.region_lo, float) for gr in model.random_groups]
        pts += [np.asarray(gr.region_hi, float) for gr in model.random_groups]
        pts += [np.asarray(p.position, float) for p in model.particles]
        if len(pts) > 1:
            h = np.asarray(pts) @ (g / gn)
            v = max(v, math.sqrt(2.0 * gn * float(h.max() - h.min())))
    return v


@dataclass
class Step:
    """Base of the solution steps (run in deck order). ``kind`` names the step type."""

    id: int
    line: int

    kind = "step"

    @property
    def duration_s(self) -> float:
        """Simulated time the step takes (s); 0 for instantaneous steps."""
        return float(getattr(self, "duration", 0.0) or 0.0)


#: ``Damping`` of a timed step: how the normal dashpots are integrated
DAMPING_SCHEMES = ("explicit", "implicit")


@dataclass
class DynamicStep(Step):
    """``Step ID Dynamic Duration T TimeStep DT [Damping Explicit|Implicit] [Accuracy η]
    [Safety f]``:
    integrate T seconds with deck step DT (s); ``damping`` "implicit" takes the normal
    dashpots at the velocity after each force evaluation's two half kicks
    (:mod:`nurbsdem.dynamics.implicit`), so that they do not limit the stable step;
    ``accuracy`` η (-, None: off) repeats a deck step whose energy-balance error grows by
    more than η × the energy scale with twice the sub-steps
    (:mod:`nurbsdem.dynamics.accuracy`); ``safety`` f (-, None: the solver's, 0.5): the
    sub-step is f × the contact network's stability limit
    (:mod:`nurbsdem.dynamics.stepcontrol`, Eq. 1)."""

    duration: float = 0.0
    time_step: float = 0.0
    damping: str = "explicit"
    accuracy: float | None = None
    safety: float | None = None
    kind = "dynamic"


@dataclass
class ReplicateStep(Step):
    """``Step ID Replicate Layers L Height H``: instantaneous; the current particles become
    layer 0 and copies shifted up by k * H / (L - 1) (k = 1..L-1) are added; all velocities are
    zeroed (see :func:`nurbsdem.placement.replicate_layers`). H in m."""

    layers: int = 1
    height: float = 0.0
    kind = "replicate"


@dataclass
class MoveWallStep(Step):
    """``Step ID MoveWall NAME ...`` — three forms:

    * ``ToContact [Gap g] [Direction dx dy dz]``: instantaneous; translate the wall along
      ``direction`` (default: its normal, i.e. towards the particles; a mesh or surface
      wall needs one, :mod:`nurbsdem.curved_to_contact`) until its distance to the nearest
      particle is ``gap`` (m, default 0). No time passes.
    * ``Displacement dx dy dz Duration T TimeStep DT``: the wall translates by the given
      vector (m) at constant velocity over T seconds while the particles move (a dynamic
      step with a prescribed wall motion; ``[Damping Explicit|Implicit] [Accuracy η]
      [Safety f]`` as for Dynamic). Any wall: flat, mesh or surface.
    * ``Rotate AngularVelocity .. Center .. [Displacement ..] Duration T TimeStep DT``: a
      mesh or surface wall turns (``rotate`` below), translating by the displacement as
      well when one is given, its centre with it.
    * ``Table FILE [Center ..] [Duration T] TimeStep DT``: the wall follows a CSV table in
      time (:mod:`nurbsdem.wall_tables`). Further ``Step`` lines of the id move more walls
      (``also``; :mod:`nurbsdem.io.deck_moves`).
    * ``Force F MaxSpeed v Gain g Duration T TimeStep DT``: a flat wall servo-controlled
      to the push F (N) of the particles along its normal (:mod:`nurbsdem.wall_servo`).
    """

    wall: str = ""
    to_contact: bool = False
    gap: float = 0.0
    direction: np.ndarray | None = None
    displacement: np.ndarray | None = None
    duration: float = 0.0
    time_step: float = 0.0
    damping: str = "explicit"
    accuracy: float | None = None
    safety: float | None = None
    #: ``Rotate AngularVelocity wx wy wz Center cx cy cz Duration T TimeStep DT``: a mesh or
    #: surface wall turns at the constant angular velocity (rad/s, world frame) about the
    #: centre (m; where it is at the step's start) for T seconds, then stays where it turned
    #: to; with a ``displacement`` the wall and its centre translate by it meanwhile
    rotate: bool = False
    angular_velocity: np.ndarray | None = None
    center: np.ndarray | None = None
    #: the tabulated motion (:class:`~nurbsdem.wall_tables.WallTable`; None: none)
    table: Any = None
    #: ``Force``: the target push (N) of the particles on the wall along its normal (None:
    #: no servo); the wall translates along its normal at a speed set each deck step from
    #: the push's error, ``gain`` (m/(s N)) times it, at most ``max_speed`` (m/s)
    force: float | None = None
    max_speed: float = 0.0
    gain: float = 0.0
    #: the other walls this step moves: MoveWallSteps of one wall and motion, this timing
    also: list = field(default_factory=list)
    kind = "movewall"

    def moves(self) -> list["MoveWallStep"]:
        """This step's wall motion, then those of the other walls it moves (:attr:`also`)."""
        return [self, *self.also]

    def net_displacement(self) -> np.ndarray:
        """The wall's displacement by the step's end (m): the table's last or the step's."""
        d = self.table.displacement[-1] if self.table is not None else self.displacement
        return np.zeros(3) if d is None else np.asarray(d, float)


@dataclass
class Output:
    """``Output`` block, with its defaults.

    directory: results folder (``results`` next to the deck).
    vtk_every (s), vtk_resolution (quads per patch direction), monitors_every (s),
    results_every (s; samples of ``results.h5``, default = vtk_every),
    checkpoint_every (s of simulated time).
    """

    directory: Path
    vtk_every: float = 0.01
    vtk_resolution: int = 8
    monitors_every: float = 1e-3
    results_every: float | None = None
    checkpoint_every: float = 0.1

    @property
    def results_interval(self) -> float:
        """Sampling interval of results.h5 (s)."""
        return float(self.results_every if self.results_every is not None else self.vtk_every)


@dataclass
class Bodies:
    """The state of N particles (arrays, row i = one body).

    id, shape_id, material_id, line: int64 (N,) — deck body id, shape id, material id, and
    the deck line that defined it. position: (N, 3) centroid, world, m. quaternion: (N, 4)
    (w, x, y, z). velocity: (N, 3) m/s, angular_velocity: (N, 3) rad/s, world frame.
    """

    id: np.ndarray
    shape_id: np.ndarray
    material_id: np.ndarray
    position: np.ndarray
    quaternion: np.ndarray
    velocity: np.ndarray
    angular_velocity: np.ndarray
    line: np.ndarray

    def __post_init__(self) -> None:
        for name in ("id", "shape_id", "material_id", "line"):
            setattr(self, name, np.asarray(getattr(self, name), np.int64).reshape(-1))
        for name, k in (("position", 3), ("quaternion", 4), ("velocity", 3),
                        ("angular_velocity", 3)):
            setattr(self, name, np.asarray(getattr(self, name), float).reshape(-1, k))

    def __len__(self) -> int:
        return int(self.id.shape[0])

    @classmethod
    def empty(cls) -> "Bodies":
        """No bodies."""
        z = np.zeros(0, np.int64)
        return cls(z, z, z, np.zeros((0, 3)), np.zeros((0, 4)), np.zeros((0, 3)),
                   np.zeros((0, 3)), z)

    def rotation_matrices(self) -> np.ndarray:
        """(N, 3, 3) file-to-world rotation matrices."""
        return quat_to_matrix(self.quaternion) if len(self) else np.zeros((0, 3, 3))

    def copy(self) -> "Bodies":
        """A deep copy."""
        return Bodies(**{f.name: getattr(self, f.name).copy() for f in fields(self)})

    def take(self, index) -> "Bodies":
        """The bodies at ``index`` (array of indices or boolean mask)."""
        return Bodies(**{f.name: getattr(self, f.name)[index] for f in fields(self)})

    @staticmethod
    def concatenate(parts: Sequence["Bodies"]) -> "Bodies":
        """All bodies of ``parts``, in order."""
        parts = [p for p in parts if len(p)]
        if not parts:
            return Bodies.empty()
        return Bodies(**{f.name: np.concatenate([getattr(p, f.name) for p in parts])
                         for f in fields(Bodies)})

    def sorted_by_id(self) -> "Bodies":
        """The bodies in increasing id order."""
        return self.take(np.argsort(self.id, kind="stable"))

    def as_dict(self) -> dict[str, np.ndarray]:
        """The arrays by field name (e.g. for a checkpoint)."""
        return {f.name: getattr(self, f.name) for f in fields(self)}

    @classmethod
    def from_dict(cls, d: Mapping[str, np.ndarray]) -> "Bodies":
        """Inverse of :meth:`as_dict`."""
        return cls(**{f.name: np.asarray(d[f.name]) for f in fields(cls)})



@dataclass
class Model:
    """Everything an input deck defines.

    Attributes
    ----------
    path: the deck as the user named it (used in error messages).
    text: the deck's text (stored as an attribute of results.h5).
    gravity: (3,) m/s^2.
    periodic: the periodic cell (:class:`PeriodicSpec`; None: none).
    materials, shapes: dicts id -> entry.
    random_groups, particles: particle definitions (ids do not overlap).
    walls: list of :class:`WallSpec` in id order.
    curved_walls: list of :class:`CurvedWallSpec` (mesh and surface walls) in deck order;
        they are the walls after the flat ones (wall indices len(walls) ...).
    interfaces: contact interfaces in deck order (later ones override earlier ones).
    steps: solution steps in deck order.
    inlets, outlets: :class:`~nurbsdem.flow_spec.InletSpec` and
        :class:`~nurbsdem.flow_spec.OutletSpec` in deck order (block ``Flow``).
    output: :class:`Output`.
    bodies: the initial particle state (:class:`Bodies`), filled by
        :func:`nurbsdem.io.deck.parse_deck` (``place=True``).
    """

    path: str
    text: str
    gravity: np.ndarray = field(default_factory=lambda: np.zeros(3))
    periodic: PeriodicSpec | None = None
    materials: dict[int, Material] = field(default_factory=dict)
    shapes: dict[int, ShapeEntry] = field(default_factory=dict)
    random_groups: list[RandomGroup] = field(default_factory=list)
    particles: list[ParticleSpec] = field(default_factory=list)
    walls: list[WallSpec] = field(default_factory=list)
    curved_walls: list[CurvedWallSpec] = field(default_factory=list)
    interfaces: list[Interface] = field(default_factory=list)
    steps: list[Step] = field(default_factory=list)
    inlets: list = field(default_factory=list)
    outlets: list = field(default_factory=list)
    output: Output | None = None
    bodies: "Bodies | None" = None

    # ------------------------------------------------------------------ helpers
    @property
    def directory(self) -> Path:
        """The folder of the deck (relative paths in the deck are relative to it)."""
        return Path(self.path).resolve().parent

    def error(self, message: str, line: int | None = None) -> InputError:
        """An :class:`InputError` located in the deck (``raise model.error(...)``)."""
        return InputError(message, path=self.path, line=line)

    def wall(self, name: str) -> WallSpec:
        """The wall of that name (KeyError if none)."""
        for w in self.walls:
            if w.name == name:
                return w
        raise KeyError(name)

    @property
    def wall_names(self) -> list[str]:
        """Wall names: the flat walls in id order, then the mesh and surface walls."""
        return [w.name for w in self.walls] + [w.name for w in self.curved_walls]

    @property
    def particle_count(self) -> int:
        """Number of particles defined by the deck (before any Replicate)."""
        return sum(g.total for g in self.random_groups) + len(self.particles)

    @property
    def total_time(self) -> float:
        """Simulated time of all steps (s)."""
        return float(sum(s.duration_s for s in self.steps))

    def interface(self, kind: str, materials: tuple[int, ...] = ()) -> Interface | None:
        """The contact interface of a pair: the last entry that applies.

        kind: ``"particle-particle"`` (materials = (ma, mb)) or ``"particle-wall"``
        (materials = (m,) of the particle). ``None`` if no entry applies.
        """
        if kind not in PAIR_KINDS:
            raise ValueError(f"kind must be one of {PAIR_KINDS}")
        found = None
        for itf in self.interfaces:
            if itf.applies(kind, tuple(materials)):
                found = itf
        return found

    def particle_materials(self) -> set[int]:
        """Material ids used by particles (those inlets create included)."""
        return ({g.material_id for g in self.random_groups} | {p.material_id for p in self.particles}
                | {i.material_id for i in self.inlets})

    # ------------------------------------------------------------------ summary
    def summary(self) -> str:
        """A human-readable description (printed by ``nurbsdem check``)."""
        from .model_summary import summary_text
        return summary_text(self)

    def as_dict(self) -> dict[str, Any]:
        """A few headline numbers (for logs and tests)."""
        return {"particles": self.particle_count, "walls": len(self.walls),
                "shapes": len(self.shapes), "steps": len(self.steps),
                "total_time": self.total_time}


_NOT_PHYSICS = {"line", "path", "text", "output", "bodies", "file", "source"}


def _canonical(x: Any) -> Any:
    """A hashable, comparable form of a model value (dataclasses, arrays, patches, shapes)."""
    if is_dataclass(x) and not isinstance(x, type):
        return (type(x).__name__,) + tuple(
            (f.name, _canonical(getattr(x, f.name))) for f in fields(x) if f.name not in _NOT_PHYSICS)
    if hasattr(x, "patches") and hasattr(x, "volume"):       # a Shape: its geometry
        return ("shape", tuple(_canonical(p) for p in x.patches))
    if hasattr(x, "control_points") and hasattr(x, "knots_u"):  # a Patch
        return ("patch", int(x.degree_u), int(x.degree_v), _canonical(x.knots_u),
                _canonical(x.knots_v), _canonical(x.control_points), _canonical(x.weights))
    if isinstance(x, np.ndarray):
        return ("array", x.shape, tuple(np.ravel(x).tolist()))
    if isinstance(x, dict):
        return tuple(sorted((k, _canonical(v)) for k, v in x.items()))
    if isinstance(x, (list, tuple)):
        return tuple(_canonical(v) for v in x)
    if isinstance(x, np.generic):
        return x.item()
    return x


#: The parts of a model compared by :func:`model_differences`, with their names.
MODEL_PARTS = (("gravity", "Environment"), ("periodic", "Environment (Periodic)"), ("materials", "Materials"), ("shapes", "Shapes"),
               ("random_groups", "Particles (Random)"), ("particles", "Particles (Particle)"),
               ("walls", "Walls"), ("interfaces", "Contact"), ("steps", "Steps"))


def model_differences(a: Model, b: Model) -> list[str]:
    """The deck blocks in which two models differ physically (ignoring comments, layout,
    line numbers, the order of blocks and the Output block); empty when they simulate the
    same thing."""
    return [name for attr, name in MODEL_PARTS
            if _canonical(getattr(a, attr)) != _canonical(getattr(b, attr))]

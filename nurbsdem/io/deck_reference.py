"""The deck reference, generated from the parser's schema.

:data:`nurbsdem.io.deck_schema.SCHEMA` says which blocks, entries and keys the parser accepts and how
many values of which kind each key takes; this module adds what a user needs besides — units,
default and meaning — in :data:`ENTRIES` (one line per entry) and :data:`KEYS` (one
:class:`KeyDoc` per key), and renders both into ``docs/deck-reference.md``::

    python -m nurbsdem.io.deck_reference            # writes docs/deck-reference.md
    python -m nurbsdem.io.deck_reference --check    # exit 1 if the file differs

Because the tables are keyed by the schema, :func:`undocumented` and :func:`unknown` list
what drifted apart (``tests/test_deck_reference.py`` fails on either, and on a
``docs/deck-reference.md`` that is not the rendered text).
"""
from __future__ import annotations

import argparse
import sys
from dataclasses import dataclass
from pathlib import Path

from ..ranges import RANGES
from .deck_schema import SCHEMA, Arg, EntrySpec

#: The key under which a setting's own values (``Gravity gx gy gz``) are documented.
HEAD = "(values)"


@dataclass(frozen=True)
class KeyDoc:
    """units: SI unit ('-' for a pure number, '' for names and flags); default: the value
    taken when the key is absent ('required', or what happens); meaning: one or two
    sentences."""

    units: str
    default: str
    meaning: str


#: What each entry is, by (block, entry).
ENTRIES: dict[tuple[str, str], str] = {
    ("Environment", "Gravity"): "The gravitational acceleration, a vector in the world frame.",
    ("Environment", "Periodic"): (
        "A periodic cell: the box [lo, hi) repeats along each axis given (at least one). A "
        "particle leaving through a face comes back through the opposite one and touches the "
        "particles near it; positions are wrapped into the cell. Each periodic length is at "
        "least twice the contact reach (the largest sum of two bounding radii plus the skin). "
        "Flat walls lie along every periodic axis and cover the cell along it, plus the "
        "largest bounding radius and the skin beyond each face (a floor with normal z under "
        "a cell periodic in x and y). An inlet's region lies inside the cell along its "
        "periodic axes. A mesh or surface wall may lie in the cell as a flat one does, "
        "staying or translating, not turning."),
    ("Materials", "Material"): "A material; particles, walls and interfaces name it by its id.",
    ("Shapes", "Shape"): (
        "A particle shape: exactly one of `File`, `Sphere`, `Ellipsoid`. Mass and inertia "
        "follow from the exact surface and the particle's material density unless "
        "`Volume` / `Inertia` override them (like the paper's Table 1)."),
    ("Particles", "Random"): (
        "A group of particles placed at random in a region with disjoint bounding spheres; "
        "its particles take the ids ID, ID+1, ... in the order of `Shapes`."),
    ("Particles", "Particle"): "One particle at a given pose and velocity.",
    ("Walls", "Box"): (
        "Five flat walls (six with `Top yes`) bounding an axis-aligned box, facing inwards, "
        "named bottom, x_min, x_max, y_min, y_max (and top)."),
    ("Walls", "Wall"): (
        "A flat one-sided rectangular wall; the particles must lie on the side its "
        "`Normal` points to."),
    ("Walls", "Mesh"): (
        "A wall of triangles from an STL, OBJ or PLY file (open or closed, convex or not; a "
        "thin two-sided shell unless `OneSided yes`). Spheres and NURBS particles: one "
        "contact per flat or convex region, one per face in a concave fold."),
    ("Walls", "Surface"): (
        "A wall of open NURBS patches from a shape file (`nurbsdem shape cylinder|cone|plane` "
        "writes them); their front S_u x S_v faces the particles. Spheres and NURBS "
        "particles (a particle where the wall curves more tightly than it stops the run)."),
    ("Contact", "Interface"): (
        "A contact law. The last interface that applies to a pair (by `Between` and "
        "`Materials`) is the one used; a pair no interface covers does not interact."),
    ("Steps", "Step"): (
        "A solution step, run in deck order: `Dynamic`, `Replicate`, or `MoveWall NAME` "
        "with `ToContact` (instantaneous; any wall), `Displacement` (timed; any wall) or "
        "`Rotate` (timed; mesh and surface walls, with or without a `Displacement`) or "
        "`Table` (timed; any wall) or `Force` (timed; any wall: a servo). A `Step` line "
        "with the previous step's id moves one more wall in that MoveWall step (`Step 3 "
        "MoveWall floor Displacement 0 0 0.01`): it names the wall and its motion only, the "
        "first line gives the timing. A timed step is split "
        "into internal sub-steps below the contact network's stability limit."),
    ("Flow", "Inlet"): (
        "Particles created during every timed step in a box or a disc at a rate (counted "
        "from the start of each timed step) until a count: a mix of shapes by number "
        "fractions, random orientations, a given velocity, never overlapping the bounding "
        "spheres present (a full inlet waits). At the end of each `Every` seconds and of "
        "each timed step the due particles enter and the system is built anew; "
        "`monitors/inlet_<name>.csv` counts them. `check` refuses a region wholly behind a "
        "flat wall or caught by an outlet, and warns of one partly behind a wall or too "
        "small for the particles of one segment."),
    ("Flow", "Outlet"): (
        "Particles removed at the end of each `Every` seconds and of every timed step when "
        "their centroid lies in a box or beyond a plane; `monitors/outlet_<name>.csv` "
        "counts them and their mass."),
    ("Output", "Directory"): "The results folder, relative to the deck.",
    ("Output", "VTK"): "ParaView series of particles, walls and contact points.",
    ("Output", "Monitors"): "CSV monitors (`monitors/*.csv`): energies, contacts, wall loads.",
    ("Output", "Results"): "Samples of every body's state in `results.h5`.",
    ("Output", "Checkpoint"): "The checkpoint that `nurbsdem solve --restart` continues from.",
}

_DAMPING = ("`Explicit` (the dashpots act at the half-step velocity) or `Implicit` (the "
            "normal dashpots act at the velocity at the end of each interval, backward Euler: "
            "strong damping no longer shortens the stable step, at first-order accuracy in the "
            "damping; on several MPI ranks every rank solves the whole network's dashpots)")

#: Units, default and meaning of each key, by (block, entry, key).
KEYS: dict[tuple[str, str, str], KeyDoc] = {
    ("Environment", "Gravity", HEAD): KeyDoc("m/s^2", "0 0 0", "gx gy gz."),
    ("Environment", "Periodic", "X"): KeyDoc("m", "not periodic",
                                             "lo hi: the cell along x, lo < hi."),
    ("Environment", "Periodic", "Y"): KeyDoc("m", "not periodic",
                                             "lo hi: the cell along y, lo < hi."),
    ("Environment", "Periodic", "Z"): KeyDoc("m", "not periodic",
                                             "lo hi: the cell along z, lo < hi."),

    ("Materials", "Material", "Density"): KeyDoc("kg/m^3", "required", "Mass density."),
    ("Materials", "Material", "YoungModulus"): KeyDoc(
        "Pa", "none", "Young's modulus; required for a material under a `HertzMindlin` "
        "interface or named on a wall."),
    ("Materials", "Material", "PoissonRatio"): KeyDoc(
        "-", "0", "Poisson's ratio, in (-1, 0.5); used by `HertzMindlin` interfaces."),

    ("Shapes", "Shape", "File"): KeyDoc(
        "", "-", "A shape file (YAML, as written by `nurbsdem shape`, `fit`, `import-giraffe`, "
        "`import-3dm`), relative to the deck; quote a path with blanks."),
    ("Shapes", "Shape", "Sphere"): KeyDoc(
        "", "-", "An exact sphere of `Radius` (six rational patches)."),
    ("Shapes", "Shape", "Ellipsoid"): KeyDoc(
        "", "-", "An exact ellipsoid of `SemiAxes`."),
    ("Shapes", "Shape", "Radius"): KeyDoc("m", "required by `Sphere`", "The sphere's radius."),
    ("Shapes", "Shape", "SemiAxes"): KeyDoc(
        "m", "required by `Ellipsoid`", "a b c along the shape's x, y, z axes."),
    ("Shapes", "Shape", "Volume"): KeyDoc(
        "m^3", "the shape's", "Volume used for the mass (density x volume); the inertia "
        "scales with it unless `Inertia` is given."),
    ("Shapes", "Shape", "Inertia"): KeyDoc(
        "kg m^2", "density x the shape's", "Jxx Jyy Jzz Jxy Jxz Jyz: the mass inertia tensor "
        "about the centroid in the shape's frame (its entries; positive definite)."),
    ("Shapes", "Shape", "ConvexityTolerance"): KeyDoc(
        "-", "1e-4", "`File` shapes: the accepted non-convexity (largest height of the surface "
        "above its own tangent planes) relative to the particle size; 0 is strict."),

    ("Particles", "Random", "Shapes"): KeyDoc("", "required", "Shape ids s1 s2 ..."),
    ("Particles", "Random", "Counts"): KeyDoc(
        "", "required", "n1 n2 ...: how many particles of each shape in `Shapes`."),
    ("Particles", "Random", "Material"): KeyDoc("", "required", "Material id of the group."),
    ("Particles", "Random", "Region"): KeyDoc(
        "m", "required", "x0 y0 z0 x1 y1 z1: the box the bounding spheres are placed in; "
        "their volume may fill at most 38 % of it."),
    ("Particles", "Random", "Seed"): KeyDoc(
        "", "0", "Seed of the random positions and orientations (the same seed gives the same "
        "placement)."),
    ("Particles", "Random", "MaxAttempts"): KeyDoc(
        "", "20000", "Attempts per particle before the placement is refused."),

    ("Particles", "Particle", "Shape"): KeyDoc("", "required", "Shape id."),
    ("Particles", "Particle", "Material"): KeyDoc("", "required", "Material id."),
    ("Particles", "Particle", "Position"): KeyDoc(
        "m", "required", "x y z of the centroid in the world."),
    ("Particles", "Particle", "Rotation"): KeyDoc(
        "rad", "0 0 0", "Rotation vector of the shape's frame relative to the world."),
    ("Particles", "Particle", "Velocity"): KeyDoc(
        "m/s", "0 0 0", "Velocity of the centroid, world frame."),
    ("Particles", "Particle", "AngularVelocity"): KeyDoc(
        "rad/s", "0 0 0", "Angular velocity, world frame."),

    ("Walls", "Box", "Min"): KeyDoc("m", "required", "The box's lower corner x y z."),
    ("Walls", "Box", "Max"): KeyDoc("m", "required", "The box's upper corner x y z."),
    ("Walls", "Box", "Top"): KeyDoc("", "no", "`yes`: also a top wall (named top)."),
    ("Walls", "Box", "Material"): KeyDoc(
        "", "none (rigid)", "Material id of the box's walls, for `HertzMindlin` interfaces."),

    ("Walls", "Mesh", "Name"): KeyDoc(
        "", "wallID", "The name `MoveWall` steps and `monitors/wall_NAME.csv` use."),
    ("Walls", "Mesh", "File"): KeyDoc(
        "", "required", "The mesh file (.stl, .obj, .ply), relative to the deck."),
    ("Walls", "Mesh", "Scale"): KeyDoc(
        "-", "1", "Factor on the file's coordinates (0.001 reads millimetres as metres)."),
    ("Walls", "Mesh", "Position"): KeyDoc(
        "m", "0 0 0", "Translation after scaling and rotating: x = R (s x_file) + Position."),
    ("Walls", "Mesh", "Rotation"): KeyDoc(
        "rad", "0 0 0", "Rotation vector applied to the scaled file coordinates."),
    ("Walls", "Mesh", "Material"): KeyDoc(
        "", "none (rigid)", "Material id of the wall, for `HertzMindlin` interfaces."),
    ("Walls", "Mesh", "OneSided"): KeyDoc(
        "", "no", "`yes`: only the front of each triangle (its vertex order's normal) acts."),
    ("Walls", "Surface", "Name"): KeyDoc(
        "", "wallID", "The name `MoveWall` steps and `monitors/wall_NAME.csv` use."),
    ("Walls", "Surface", "File"): KeyDoc(
        "", "required", "The shape file (YAML) of the open patches, relative to the deck."),
    ("Walls", "Surface", "Position"): KeyDoc(
        "m", "0 0 0", "Translation after rotating: x = R x_file + Position."),
    ("Walls", "Surface", "Rotation"): KeyDoc(
        "rad", "0 0 0", "Rotation vector applied to the file's coordinates."),
    ("Walls", "Surface", "Material"): KeyDoc(
        "", "none (rigid)", "Material id of the wall, for `HertzMindlin` interfaces."),

    ("Walls", "Wall", "Name"): KeyDoc(
        "", "wallID", "The name `MoveWall` steps and `monitors/wall_NAME.csv` use."),
    ("Walls", "Wall", "Point"): KeyDoc("m", "required", "Centre of the rectangle."),
    ("Walls", "Wall", "Normal"): KeyDoc(
        "-", "required", "Direction towards the particles' side (its length is irrelevant)."),
    ("Walls", "Wall", "Size"): KeyDoc(
        "m", "required", "Lu Lv: the side lengths along `Axis` and along Normal x Axis."),
    ("Walls", "Wall", "Axis"): KeyDoc(
        "-", "the global axis least aligned with Normal", "In-plane direction of the first "
        "side (projected onto the wall's plane)."),
    ("Walls", "Wall", "Material"): KeyDoc(
        "", "none (rigid)", "Material id of the wall, for `HertzMindlin` interfaces."),

    ("Contact", "Interface", "Model"): KeyDoc(
        "", "LinearPenalty", "`LinearPenalty` (the paper's law, Eqs. 16-17) or `HertzMindlin` "
        "(elliptical Hertz from both surfaces' principal curvatures, Mindlin tangential "
        "stiffness, damping from `Restitution`; E and nu from the materials)."),
    ("Contact", "Interface", "NormalPenalty"): KeyDoc(
        "N/m", "required by LinearPenalty", "Normal penalty stiffness (paper's epsilon_n)."),
    ("Contact", "Interface", "TangentialPenalty"): KeyDoc(
        "N/m", "0", "Tangential spring stiffness (paper's epsilon_t)."),
    ("Contact", "Interface", "NormalDamping"): KeyDoc(
        "N s/m", "0", "Normal dashpot (paper's c_n); no adhesion: the normal force is never "
        "negative."),
    ("Contact", "Interface", "TangentialDamping"): KeyDoc(
        "N s/m", "0", "Tangential dashpot (paper's c_t)."),
    ("Contact", "Interface", "Friction"): KeyDoc("-", "0", "Coulomb friction coefficient."),
    ("Contact", "Interface", "RollingFriction"): KeyDoc(
        "-", "0 (none)", "Rolling-resistance coefficient mu_r, both laws: an elastic-plastic "
        "rolling spring (stiffness 2.25 mu_r^2 R_r^2 k_n) whose torque is limited to "
        "mu_r R_r f_n, R_r the contact's equivalent radius (a sphere on a wall: its radius), "
        "at most the lever arms' combination (centroid to contact point). "
        "A sphere rests on an incline while tan(angle) <= mu_r; rolling, it decelerates at "
        "5/7 mu_r g. Supported up to 0.4."),
    ("Contact", "Interface", "RollingDamping"): KeyDoc(
        "-", "0 (none)", "Damping ratio eta_r of the rolling spring of RollingFriction, both "
        "laws: a viscous torque C_r w_r, C_r = 2 eta_r sqrt(I_r k_r) with I_r = 1.4 m l^2 "
        "(l the lever arm), while the spring holds (as LIGGGHTS' epsd); a sphere's rocking "
        "on a floor then decays with the damping ratio eta_r. Supported up to 0.3."),
    ("Contact", "Interface", "Restitution"): KeyDoc(
        "-", "required by HertzMindlin", "Coefficient of restitution e in (0, 1] of a normal "
        "impact, independent of the impact speed."),
    ("Contact", "Interface", "Between"): KeyDoc(
        "", "all pairs", "`particle-particle` or `particle-wall`."),
    ("Contact", "Interface", "Materials"): KeyDoc(
        "", "any", "`m1 m2`: particle-particle pairs of these materials (either order); `m`: "
        "particle-wall pairs whose particle has material m."),

    ("Steps", "Step", "Dynamic"): KeyDoc(
        "", "-", "Integrate the particles' motion for `Duration` with deck step `TimeStep`."),
    ("Steps", "Step", "Replicate"): KeyDoc(
        "", "-", "Instantaneous: the particles become layer 0 and `Layers` - 1 copies are added, "
        "shifted up by `Height` / (`Layers` - 1) each; all velocities are set to zero."),
    ("Steps", "Step", "Rotate"): KeyDoc(
        "", "no", "With `MoveWall NAME`: the mesh or surface wall turns at `AngularVelocity` "
        "about `Center` for `Duration`, then stays where it turned to; with a `Displacement` "
        "it translates as well, the centre with it."),
    ("Steps", "Step", "Table"): KeyDoc(
        "", "-", "With `MoveWall NAME`: a CSV file (relative to the deck's folder) of rows "
        "`t,x,y,z` or `t,x,y,z,rx,ry,rz` (an optional header of these names; `#` comments): "
        "times (s, from 0, increasing), the wall's displacement (m) from where it is at the "
        "step's start and, mesh and surface walls only, its rotation vector (rad, axis x "
        "angle) about `Center`; interpolated linearly in time, the wall at each row's values "
        "exactly at its time and still after the last row. `Duration` defaults to the last "
        "time."),
    ("Steps", "Step", "Force"): KeyDoc(
        "N", "-", "With `MoveWall NAME`: a servo. The wall translates along its normal (a "
        "mesh or surface wall: along `Direction`, required) so that the particles push it "
        "with F along it: once per deck step its velocity is set to `Gain` x (F - the push "
        "at the end of the deck step before; the reaction of `monitors/wall_NAME.csv` along "
        "that axis), towards the particles while they push less, at most `MaxSpeed`."),
    ("Steps", "Step", "MaxSpeed"): KeyDoc(
        "m/s", "required with Force", "The servo wall's greatest speed, > 0."),
    ("Steps", "Step", "Gain"): KeyDoc(
        "m/(s N)", "required with Force", "The servo's speed per newton of force error, >= 0; "
        "1 / (N k DT) closes the error in about N deck steps DT against a contact stiffness "
        "k (N/m) (N ~ 100: smooth; N below ~2 oscillates)."),
    ("Steps", "Step", "AngularVelocity"): KeyDoc(
        "rad/s", "required with Rotate", "The wall's angular velocity, world frame."),
    ("Steps", "Step", "Center"): KeyDoc(
        "m", "0 0 0", "A point of the rotation axis at the step's start (`Rotate`), or the "
        "centre a `Table` turns the wall about (the wall's torque in its monitor is about it "
        "while it turns)."),
    ("Steps", "Step", "MoveWall"): KeyDoc(
        "", "-", "The name of the wall to move (with `ToContact`, `Displacement`, "
        "`Rotate`, `Table` or `Force`)."),
    ("Steps", "Step", "Duration"): KeyDoc(
        "s", "required by timed steps", "Simulated time; a whole number of `TimeStep`s."),
    ("Steps", "Step", "TimeStep"): KeyDoc(
        "s", "required by timed steps", "The deck step: monitors and output are sampled on it; "
        "the solver divides it into internal sub-steps for stability (the log says how many "
        "and why)."),
    ("Steps", "Step", "Layers"): KeyDoc("", "required by `Replicate`", "Number of layers, >= 1."),
    ("Steps", "Step", "Height"): KeyDoc(
        "m", "required by `Replicate`", "Height from layer 0 to the top layer."),
    ("Steps", "Step", "ToContact"): KeyDoc(
        "", "-", "Instantaneous: translate the wall until its distance to the nearest particle "
        "is `Gap` (a mesh or surface wall: the first such place coming from far behind along "
        "`Direction`)."),
    ("Steps", "Step", "Gap"): KeyDoc("m", "0", "`ToContact`: the distance left."),
    ("Steps", "Step", "Direction"): KeyDoc(
        "-", "the wall's normal", "`ToContact` and `Force`: the direction of travel "
        "(towards the particles; made unit). A mesh or surface wall requires it; "
        "on a flat wall it must have a positive component along the normal."),
    ("Steps", "Step", "Displacement"): KeyDoc(
        "m", "-", "dx dy dz: the wall (flat, mesh or surface) translates by this vector at "
        "constant velocity over `Duration` while the particles move; with `Rotate`, while "
        "it turns."),
    ("Steps", "Step", "Damping"): KeyDoc("", "Explicit", _DAMPING + "."),
    ("Steps", "Step", "Accuracy"): KeyDoc(
        "-", "off", "eta: a deck step whose energy-balance error grows by more than eta x the "
        "energy scale is repeated with twice the sub-steps (up to 16 x)."),
    ("Steps", "Step", "Safety"): KeyDoc(
        "-", "0.5", "The sub-step as a fraction of the contact network's stability limit, "
        "0.01 to 0.95."),

    ("Flow", "Inlet", "Name"): KeyDoc(
        "", "inlet<ID>", "Names `monitors/inlet_<name>.csv` (the wall names' rule)."),
    ("Flow", "Inlet", "Shapes"): KeyDoc("", "required", "Shape ids s1 s2 ... of the mix."),
    ("Flow", "Inlet", "Fractions"): KeyDoc(
        "-", "1 (one shape)", "f1 f2 ...: the number fraction of each shape in `Shapes`, "
        ">= 0, summing to 1."),
    ("Flow", "Inlet", "Material"): KeyDoc("", "required", "Material id of the new particles."),
    ("Flow", "Inlet", "Box"): KeyDoc(
        "m", "Disc", "x0 y0 z0 x1 y1 z1: the box the new particles lie wholly inside; "
        "it may not lie wholly behind a flat wall (partly: a warning)."),
    ("Flow", "Inlet", "Disc"): KeyDoc(
        "m", "Box", "cx cy cz: the centre of the disc the new particles' centroids lie in "
        "(with `Normal` and `Radius`), each bounding sphere within its rim."),
    ("Flow", "Inlet", "Normal"): KeyDoc(
        "-", "with Disc", "The disc's axis (only the direction matters)."),
    ("Flow", "Inlet", "Radius"): KeyDoc("m", "with Disc", "The disc's radius."),
    ("Flow", "Inlet", "Thickness"): KeyDoc(
        "m", "0", "The disc's thickness along `Normal`: 0 puts the centroids in its plane."),
    ("Flow", "Inlet", "Rate"): KeyDoc(
        "1/s", "required", "Particles per second, counted from the start of each timed step; "
        "a region that cannot hold one segment's particles at 30 % of its volume (random "
        "loose packing of the bounding spheres) is a warning: the inlet waits."),
    ("Flow", "Inlet", "Count"): KeyDoc("", "required", "How many particles in all, >= 1."),
    ("Flow", "Inlet", "Velocity"): KeyDoc(
        "m/s", "0 0 0", "Velocity of every new particle, world frame."),
    ("Flow", "Inlet", "Seed"): KeyDoc(
        "", "0", "Seed of the inlet's own random shapes, positions and orientations."),
    ("Flow", "Inlet", "Every"): KeyDoc(
        "s", "0.01", "Segment length: particles enter at the end of each and of the step; "
        "a timed step takes the smallest `Every` of its inlets and outlets, rounded to whole "
        "TimeSteps."),
    ("Flow", "Outlet", "Name"): KeyDoc(
        "", "outlet<ID>", "Names `monitors/outlet_<name>.csv` (the wall names' rule)."),
    ("Flow", "Outlet", "Box"): KeyDoc(
        "m", "Point and Normal", "x0 y0 z0 x1 y1 z1: particles whose centroid is inside "
        "leave."),
    ("Flow", "Outlet", "Point"): KeyDoc(
        "m", "Box", "A point of the outlet plane (with `Normal`)."),
    ("Flow", "Outlet", "Normal"): KeyDoc(
        "-", "Box", "Points out of the scene: particles whose centroid is beyond the plane "
        "on this side leave."),
    ("Flow", "Outlet", "Every"): KeyDoc(
        "s", "0.01", "Segment length: particles leave at the end of each and of the step (as "
        "the Inlet's)."),

    ("Output", "Directory", HEAD): KeyDoc("", "results", "Folder of the result files."),
    ("Output", "VTK", "Every"): KeyDoc("s", "0.01", "Interval of the ParaView samples."),
    ("Output", "VTK", "Resolution"): KeyDoc(
        "", "8", "Quads per patch and direction of the particles' tessellation."),
    ("Output", "Monitors", "Every"): KeyDoc("s", "1e-3", "Interval of the monitor rows."),
    ("Output", "Results", "Every"): KeyDoc(
        "s", "VTK Every", "Interval of the samples in `results.h5`."),
    ("Output", "Checkpoint", "Every"): KeyDoc(
        "s", "0.1", "Interval of the checkpoints (simulated time); one is also written at the "
        "end of every step."),
}

_HEADER = """\
# Deck reference

<!-- Generated by `python -m nurbsdem.io.deck_reference` from the parser's schema
(nurbsdem/io/deck_schema.py) and the descriptions in nurbsdem/io/deck_reference.py: edit those, not
this file. tests/test_deck_reference.py checks that the two agree. -->

A deck is a text file of blocks. A block opens with its keyword alone on a line
(`Environment`, `Materials`, ...; any order, a block may appear more than once); inside a
block, one entry per line: `Keyword [ID] Key value ... Key value ...`. Numbered entries carry
an integer id after the keyword; settings take their own values directly. `#` starts a
comment anywhere, `//` at the start of a line or after a blank; values may be quoted
(`File "my shapes/A.yaml"`). Keywords are case-insensitive; names and paths are kept as
written. SI units throughout; paths are relative to the deck's folder. `nurbsdem check
CASE.inp` validates a deck without running it; every mistake is reported as one line
`file:line: what is wrong`.

Below, each entry's first line lists every key the parser accepts, in any order after the
keyword (and its ID); its table says which are required, what the others default to, and the
magnitudes the parser accepts (|x| at most the upper bound; positive values at least the lower
one; `nurbsdem check` names the reason for each bound).
"""


def keys_of(schema: dict[str, dict[str, EntrySpec]] = SCHEMA) -> list[tuple[str, str, str]]:
    """Every (block, entry, key) of a schema, in schema order; a setting's own values are
    the key :data:`HEAD`."""
    out = []
    for block, entries in schema.items():
        for name, spec in entries.items():
            if spec.head is not None:
                out.append((block, name, HEAD))
            out.extend((block, name, key) for key in spec.keys)
    return out


def undocumented(schema: dict[str, dict[str, EntrySpec]] = SCHEMA,
                 keys: dict = KEYS, entries: dict = ENTRIES) -> list[str]:
    """Entries and keys of the schema without a description, as 'Block/Entry[/Key]'."""
    missing = [f"{b}/{e}" for b, ents in schema.items() for e in ents if (b, e) not in entries]
    return missing + ["/".join(k) for k in keys_of(schema) if k not in keys]


def unknown(schema: dict[str, dict[str, EntrySpec]] = SCHEMA,
            keys: dict = KEYS, entries: dict = ENTRIES) -> list[str]:
    """Descriptions of entries or keys the schema does not have, as 'Block/Entry[/Key]'."""
    have = set(keys_of(schema))
    known = {(b, e) for b, ents in schema.items() for e in ents}
    return ([f"{b}/{e}" for (b, e) in entries if (b, e) not in known]
            + ["/".join(k) for k in keys if k not in have])


def values_text(arg: Arg) -> str:
    """What follows a key, in words: '3 numbers', 'integers', 'yes/no', '-' for a flag."""
    if arg.kind == "flag":
        return "-"
    if arg.kind == "bool":
        return "yes/no"
    word = {"float": "number", "int": "integer", "str": "word"}[arg.kind]
    if arg.count is None:
        return f"{word}s (one or more)"
    return word if arg.count == 1 else f"{arg.count} {word}s"


def _number(x: float) -> str:
    return f"{x:g}" if isinstance(x, float) else (str(x) if abs(x) < 10 ** 15 else f"{x:.0e}")


def range_text(block: str, entry: str, key: str) -> str:
    """The magnitudes the parser accepts for a key (:data:`nurbsdem.ranges.RANGES`; a
    setting's own values under its keyword), '' where it checks none: 'at most 1e+06' for
    |x| <= hi, '1e-09 … 1e+06' where positive values must also reach lo."""
    rng = RANGES.get(entry if key == HEAD else key)
    if rng is None:
        return ""
    unit = f" {rng.unit}" if rng.unit else ""
    if not rng.lo:
        return f"at most {_number(rng.hi)}{unit}"
    return f"{_number(rng.lo)} … {_number(rng.hi)}{unit}"


def _synopsis(name: str, spec: EntrySpec) -> str:
    parts = [name] + (["ID"] if spec.numbered else [])
    if spec.head is not None:
        parts.append(f"<{values_text(spec.head)}>")
    parts += [k if a.kind == "flag" else f"{k} <{values_text(a)}>" for k, a in spec.keys.items()]
    return " ".join(parts)


def _cell(text: str) -> str:
    return text.replace("|", "\\|")


def render(schema: dict[str, dict[str, EntrySpec]] = SCHEMA, keys: dict = KEYS,
           entries: dict = ENTRIES) -> str:
    """The markdown of ``docs/deck-reference.md``: per block and entry its synopsis (the keys
    the parser accepts, in schema order) and a table of values, units, default and meaning.
    Raises ValueError when a description is missing (see :func:`undocumented`)."""
    missing = undocumented(schema, keys, entries)
    if missing:
        raise ValueError("undocumented deck keys: " + ", ".join(missing))
    out = [_HEADER]
    for block, ents in schema.items():
        out.append(f"## {block}\n")
        for name, spec in ents.items():
            out.append(f"### {name}\n")
            out.append(f"`{_synopsis(name, spec)}`\n")
            out.append(entries[(block, name)] + "\n")
            rows = ["| key | values | units | default | accepted range | meaning |",
                    "|---|---|---|---|---|---|"]
            args = ([(HEAD, spec.head)] if spec.head is not None else []) + list(spec.keys.items())
            for key, arg in args:
                d = keys[(block, name, key)]
                label = "(after the keyword)" if key == HEAD else f"`{key}`"
                rows.append(f"| {label} | {values_text(arg)} | {_cell(d.units) or '-'} | "
                            f"{_cell(d.default)} | {range_text(block, name, key) or '-'} | "
                            f"{_cell(d.meaning)} |")
            out.append("\n".join(rows) + "\n")
    return "\n".join(out)


#: Where the rendered reference lives in the repository.
REFERENCE_PATH = Path(__file__).resolve().parents[2] / "docs" / "deck-reference.md"


def main(argv: list[str] | None = None) -> int:
    """Write (or with ``--check`` compare) ``docs/deck-reference.md``."""
    ap = argparse.ArgumentParser(description="Render docs/deck-reference.md from the schema.")
    ap.add_argument("--output", type=Path, default=REFERENCE_PATH)
    ap.add_argument("--check", action="store_true", help="exit 1 if the file is not current")
    a = ap.parse_args(argv)
    text = render()
    if a.check:
        current = a.output.read_text(encoding="utf-8") if a.output.is_file() else ""
        if current != text:
            print(f"{a.output} is not current: run python -m nurbsdem.io.deck_reference",
                  file=sys.stderr)
            return 1
        return 0
    a.output.parent.mkdir(parents=True, exist_ok=True)
    a.output.write_text(text, encoding="utf-8")
    print(f"wrote {a.output}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

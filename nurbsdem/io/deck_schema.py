"""The deck's vocabulary: every block, entry and key the parser accepts (:data:`SCHEMA`), and
a parsed entry (:class:`Entry`).

:mod:`nurbsdem.io.deck` reads deck text against :data:`SCHEMA`, :mod:`nurbsdem.io.deck_build`
turns the entries into a model, :mod:`nurbsdem.io.deck_format` writes a model back as deck
text, and :mod:`nurbsdem.io.deck_reference` documents every key (``docs/deck-reference.md``).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any


@dataclass(frozen=True)
class Arg:
    """What follows a keyword: ``count`` values of ``kind`` (``None`` = one or more).

    kind: ``float``, ``int``, ``str``, ``bool`` or ``flag`` (no value).
    """

    kind: str
    count: int | None = 1


F1, F2, F3, F6, FN = (Arg("float", 1), Arg("float", 2), Arg("float", 3), Arg("float", 6),
                      Arg("float", None))
I1, IN, S1, B1, FLAG = Arg("int", 1), Arg("int", None), Arg("str", 1), Arg("bool", 1), Arg("flag", 0)


@dataclass(frozen=True)
class EntrySpec:
    """An entry kind: numbered (integer id after the keyword) or a setting whose own values
    (``head``) follow the keyword directly; then ``Key value`` pairs from ``keys``."""

    numbered: bool
    keys: dict[str, Arg] = field(default_factory=dict)
    head: Arg | None = None


SCHEMA: dict[str, dict[str, EntrySpec]] = {
    "Environment": {"Gravity": EntrySpec(False, head=F3),
                    "Periodic": EntrySpec(False, {"X": F2, "Y": F2, "Z": F2})},
    "Materials": {"Material": EntrySpec(True, {"Density": F1, "YoungModulus": F1,
                                               "PoissonRatio": F1})},
    "Shapes": {"Shape": EntrySpec(True, {
        "File": S1, "Sphere": FLAG, "Ellipsoid": FLAG, "Radius": F1, "SemiAxes": F3,
        "Volume": F1, "Inertia": F6, "ConvexityTolerance": F1})},
    "Particles": {
        "Random": EntrySpec(True, {"Shapes": IN, "Counts": IN, "Material": I1, "Region": F6,
                                   "Seed": I1, "MaxAttempts": I1}),
        "Particle": EntrySpec(True, {"Shape": I1, "Material": I1, "Position": F3,
                                     "Rotation": F3, "Velocity": F3, "AngularVelocity": F3}),
    },
    "Walls": {
        "Box": EntrySpec(True, {"Min": F3, "Max": F3, "Top": B1, "Material": I1}),
        "Wall": EntrySpec(True, {"Name": S1, "Point": F3, "Normal": F3, "Size": F2, "Axis": F3,
                                 "Material": I1}),
        "Mesh": EntrySpec(True, {"Name": S1, "File": S1, "Scale": F1, "Position": F3,
                                 "Rotation": F3, "Material": I1, "OneSided": B1}),
        "Surface": EntrySpec(True, {"Name": S1, "File": S1, "Position": F3, "Rotation": F3,
                                    "Material": I1}),
    },
    "Contact": {"Interface": EntrySpec(True, {
        "NormalPenalty": F1, "TangentialPenalty": F1, "NormalDamping": F1,
        "TangentialDamping": F1, "Friction": F1, "Between": S1, "Materials": IN,
        "Model": S1, "Restitution": F1, "RollingFriction": F1,
        "RollingDamping": F1})},
    "Flow": {
        "Inlet": EntrySpec(True, {"Name": S1, "Shapes": IN, "Fractions": FN, "Material": I1,
                                  "Box": F6, "Disc": F3, "Normal": F3, "Radius": F1,
                                  "Thickness": F1, "Rate": F1, "Count": I1, "Velocity": F3,
                                  "Seed": I1, "Every": F1}),
        "Outlet": EntrySpec(True, {"Name": S1, "Box": F6, "Point": F3, "Normal": F3,
                                   "Every": F1}),
    },
    "Steps": {"Step": EntrySpec(True, {
        "Dynamic": FLAG, "Replicate": FLAG, "MoveWall": S1, "Duration": F1, "TimeStep": F1,
        "Layers": I1, "Height": F1, "ToContact": FLAG, "Gap": F1, "Direction": F3,
        "Displacement": F3, "Damping": S1, "Accuracy": F1, "Safety": F1, "Rotate": FLAG,
        "AngularVelocity": F3, "Center": F3, "Table": S1, "Force": F1, "MaxSpeed": F1,
        "Gain": F1})},
    "Output": {
        "Directory": EntrySpec(False, head=S1),
        "VTK": EntrySpec(False, {"Every": F1, "Resolution": I1}),
        "Monitors": EntrySpec(False, {"Every": F1}),
        "Results": EntrySpec(False, {"Every": F1}),
        "Checkpoint": EntrySpec(False, {"Every": F1}),
    },
}


@dataclass
class Entry:
    """One deck line: keyword, id (numbered entries), head values, key values; ``comment``:
    the text after ``#`` of a line written by :mod:`nurbsdem.io.deck_format` (the reader
    drops comments)."""

    block: str
    keyword: str
    line: int
    id: int | None = None
    head: Any = None
    values: dict[str, Any] = field(default_factory=dict)
    comment: str = ""

    def get(self, key: str, default: Any = None) -> Any:
        return self.values.get(key, default)

    def has(self, key: str) -> bool:
        return key in self.values


class LineError(Exception):
    """A deck mistake with the line it is on (``line`` None: the deck as a whole)."""

    def __init__(self, msg: str, line: int | None) -> None:
        super().__init__(msg)
        self.line = line

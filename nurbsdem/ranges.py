"""The supported magnitudes of the values of a deck (and of the Python API): per key the
range, its unit and the reason for it (:data:`RANGES`), the largest ellipsoid aspect ratio and
the largest id.  A module of data below the solver: the deck reader checks every value
against it (:func:`nurbsdem.io.deck.check_range`), the geometry checks and the scene checks
read it without importing the deck reader."""
from __future__ import annotations

from dataclasses import dataclass

#: Largest ratio of an ellipsoid's longest to shortest semi-axis.
ASPECT_MAX = 1e3

#: Largest id of a numbered entry (ids are stored as 64-bit integers and a Replicate step
#: numbers its copies after the largest id).
ID_MAX = 10 ** 9

_COORD = "float64 positions this far out cannot resolve contacts at particle scale"
_SIZE = "the geometric tolerances of the contact search assume sizes in this range"
_MATERIAL = "outside any real material; masses and critical time steps leave floating-point range"


@dataclass(frozen=True)
class Range:
    """The supported magnitudes of a value: ``|x| <= hi`` and, for ``x > 0``, ``x >= lo``
    (zero and negative values are judged by the entry's own rules), with the reason."""

    lo: float
    hi: float
    unit: str
    reason: str
    #: negative values are wrong whatever their size: left to the entry's ">= 0" rule
    nonnegative: bool = False


#: Supported magnitudes by key (or ``Keyword`` for a setting's own values).
RANGES: dict[str, Range] = {
    **{k: Range(0.0, 1e6, "m", _COORD) for k in ("Position", "Region", "Min", "Max", "Point",
                                                  "Displacement", "Height", "Gap", "Center",
                                                  "Box", "Disc", "X", "Y", "Z")},
    **{k: Range(1e-9, 1e6, "m", _SIZE) for k in ("Radius", "SemiAxes", "Size", "Thickness")},
    **{k: Range(0.0, 1e6, "", "only the direction matters; keep its components moderate")
       for k in ("Normal", "Axis", "Direction")},
    "Scale": Range(1e-9, 1e9, "", "a mesh drawn in micrometres or kilometres is read with a "
                   "scale within 1e-9 .. 1e9; beyond, the file's units are not lengths"),
    "Gravity": Range(0.0, 1e6, "m/s^2", "a million times the Earth's gravity is beyond any "
                     "granular flow"),
    "Velocity": Range(0.0, 1e4, "m/s", "beyond any granular flow; contacts cannot be resolved"),
    "AngularVelocity": Range(0.0, 1e6, "rad/s", "beyond any granular flow; contacts cannot be "
                             "resolved"),
    "Density": Range(1e-3, 1e6, "kg/m^3", _MATERIAL),
    "YoungModulus": Range(1.0, 1e13, "Pa", "beyond the stiffest solids (diamond: 1.2e12 Pa) "
                          "and softer than any gel"),
    "Volume": Range(1e-27, 1e18, "m^3", _SIZE),
    "Inertia": Range(0.0, 1e30, "kg m^2", _MATERIAL),
    "NormalPenalty": Range(0.0, 1e15, "N/m", _MATERIAL),
    "TangentialPenalty": Range(0.0, 1e15, "N/m", _MATERIAL),
    "NormalDamping": Range(0.0, 1e12, "N s/m", _MATERIAL),
    "TangentialDamping": Range(0.0, 1e12, "N s/m", _MATERIAL),
    "Friction": Range(0.0, 100.0, "", "Coulomb coefficients of real materials are below ~2"),
    "RollingFriction": Range(0.0, 0.4, "", "calibrated rolling-friction coefficients lie "
                             "below ~0.3; above 0.42 the rolling spring (k_r = 2.25 μ_r² R_r² "
                             "k_n), which the time-step control does not see, turns a sphere "
                             "faster than its normal spring"),
    "RollingDamping": Range(0.0, 0.3, "", "the damping ratio of the rolling spring, which the "
                            "time-step control does not see: up to 0.3 its step stays stable "
                            "at RollingFriction 0.4"),
    "ConvexityTolerance": Range(0.0, 0.1, "", "a surface further than a tenth of its size from "
                                "convex is not a convex particle: the contact search finds one "
                                "contact point per pair", nonnegative=True),
    "Accuracy": Range(1e-12, 0.1, "", "a relative energy error per deck step beyond 0.1 "
                      "controls nothing; below 1e-12 it is round-off"),
    "Safety": Range(0.01, 0.95, "", "a fraction of the stability limit: at 1 the explicit "
                    "step is unstable, and 0.95 leaves no margin for the linearisation; below "
                    "0.01 a smaller TimeStep says the same"),
    "Duration": Range(0.0, 1e7, "s", "a simulated time of months is beyond a DEM run"),
    "TimeStep": Range(1e-15, 1e7, "s", "below a femtosecond nothing granular happens"),
    "Every": Range(1e-12, 1e7, "s", "output, inflow and outflow intervals beyond this range "
                   "are meaningless"),
    "Rate": Range(1e-9, 1e9, "1/s", "a billion particles a second do not fit in memory; fewer "
                  "than one in thirty years never enter a DEM run"),
    "Count": Range(0, 10 ** 8, "", "more particles do not fit in memory"),
    "Fractions": Range(0.0, 1.0, "", "a fraction of the particles an inlet creates"),
    "MaxAttempts": Range(1, 10 ** 7, "", "more attempts take hours without placing the particle"),
    "Seed": Range(0, 2 ** 63 - 1, "", "seeds are 64-bit integers"),
    "Resolution": Range(1, 10 ** 4, "", "finer tessellations than this do not fit in memory"),
    "Counts": Range(0, 10 ** 8, "", "more particles do not fit in memory"),
    "Shapes": Range(0, ID_MAX, "", f"ids are at most {ID_MAX:g}"),
    "Shape": Range(0, ID_MAX, "", f"ids are at most {ID_MAX:g}"),
    "Material": Range(0, ID_MAX, "", f"ids are at most {ID_MAX:g}"),
    "Materials": Range(0, ID_MAX, "", f"ids are at most {ID_MAX:g}"),
}

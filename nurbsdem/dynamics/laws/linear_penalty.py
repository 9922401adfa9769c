"""The linear penalty law of the paper (Eq. 16–17): ``Interface ID [Model LinearPenalty]
NormalPenalty en [TangentialPenalty et] [NormalDamping cn] [TangentialDamping ct]
[Friction mu] [RollingFriction mu_r] [RollingDamping eta_r]``.

Normal force f_n = εn d + cn ḋ (clipped at 0 by the kernel), elastic energy ½ εn d²; the
tangential spring εt with dashpot ct and the Coulomb return mapping are the kernel's common
part (:mod:`nurbsdem.dynamics.forces`).  Its row holds the constants themselves, which are
also the time-step control's linearisation.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit

from ...errors import InputError
from .keys import LawKey
from .table import CN, CT, EN, ET, MODEL, MU, NCOL, RD, RF

#: the law's code in the table's MODEL column
CODE = 0

_STIFF = "a penalty stiffness; the critical time step scales as sqrt(m/k)"
_DAMP = "a dashpot dissipates energy; a negative one would create it"
_MU = "a Coulomb coefficient; a negative one would push along the sliding velocity"

#: the Friction key, common to the built-in laws
FRICTION = LawKey("Friction", "friction", "", 0.0, _MU)
#: the RollingFriction key, common to the built-in laws (:mod:`nurbsdem.dynamics.rolling`)
ROLLING_FRICTION = LawKey("RollingFriction", "rolling_friction", "", 0.0,
                          "a rolling-resistance coefficient (the torque limit over the rolling "
                          "radius and the normal force); a negative one would drive the rolling",
                          written_at_default=False)
#: the RollingDamping key, common to the built-in laws (:mod:`nurbsdem.dynamics.rolling`)
ROLLING_DAMPING = LawKey("RollingDamping", "rolling_damping", "", 0.0,
                         "a damping ratio of the rolling spring; a negative one would drive "
                         "the rolling", written_at_default=False)


@dataclass(frozen=True)
class LinearPenalty:
    """Penalty law of one interface (paper Eq. 16–17; the example: 1e5, 1e2, 1e4, 0, 0.5).

    en: normal penalty εn (N/m); cn: normal damping (N s/m); et: tangential penalty εt (N/m);
    ct: tangential damping (N s/m); mu: Coulomb friction coefficient (-); mu_r, eta_r: the
    rolling friction coefficient and the rolling spring's damping ratio (-,
    :mod:`nurbsdem.dynamics.rolling`).
    """

    en: float
    cn: float = 0.0
    et: float = 0.0
    ct: float = 0.0
    mu: float = 0.0
    mu_r: float = 0.0
    eta_r: float = 0.0

    #: deck name, the Interface's ``model``, the code of its table rows
    name = "LinearPenalty"
    model = "linear"
    code = CODE
    #: the kernel needs no contact radius for it
    needs_contact_radius = False
    #: its from_interface reads the materials (:class:`~nurbsdem.model.MaterialPair`)
    uses_materials = False
    #: deck keys (``Friction`` is common to the laws)
    keys = (LawKey("NormalPenalty", "normal_penalty", "N/m", 0.0,
                   _STIFF + "; without one nothing stops the bodies' overlap", lo_open=True,
                   required=True),
            LawKey("TangentialPenalty", "tangential_penalty", "N/m", 0.0, _STIFF),
            LawKey("NormalDamping", "normal_damping", "N s/m", 0.0, _DAMP),
            LawKey("TangentialDamping", "tangential_damping", "N s/m", 0.0, _DAMP),
            FRICTION, ROLLING_FRICTION, ROLLING_DAMPING)
    #: what the law's row depends on besides its keys (for the messages)
    note = "its constants are its keys"

    def __post_init__(self) -> None:
        for name in ("en", "cn", "et", "ct", "mu", "mu_r", "eta_r"):
            val = getattr(self, name)
            if not (math.isfinite(val) and val >= 0):
                raise InputError(f"contact law: {name} must be finite and >= 0, got {val}")
        if self.en <= 0:
            raise InputError(f"contact law: normal penalty en must be > 0, got {self.en}")

    @classmethod
    def from_interface(cls, itf, pair) -> "LinearPenalty":
        """The law of an :class:`~nurbsdem.model.Interface` (``pair``, the materials'
        :class:`~nurbsdem.model.MaterialPair`, is not used: the constants are the keys)."""
        return cls(en=itf.normal_penalty, cn=itf.normal_damping, et=itf.tangential_penalty,
                   ct=itf.tangential_damping, mu=itf.friction, mu_r=itf.rolling_friction,
                   eta_r=itf.rolling_damping)

    def as_row(self) -> np.ndarray:
        row = np.zeros(NCOL)
        row[EN], row[CN], row[ET], row[CT], row[MU] = self.en, self.cn, self.et, self.ct, self.mu
        row[MODEL] = CODE
        row[RF] = self.mu_r
        row[RD] = self.eta_r
        return row


@njit(cache=True, inline="always")
def normal(table, ma, mb, d, radius, imass):
    """The normal part of the law for a contact of depth d (m) between materials ma, mb:
    (k_n, c_n, k_t, c_t, elastic normal force εn d (N), normal elastic energy ½ εn d² (J)).
    radius and imass (the contact radius, the pair's summed inverse masses) are not used."""
    en, cn = table[ma, mb, EN], table[ma, mb, CN]
    et, ct = table[ma, mb, ET], table[ma, mb, CT]
    fel = en * d
    eel_n = 0.5 * en * d * d
    return en, cn, et, ct, fel, eel_n


@njit(cache=True, inline="always")
def spring_scale(table, ma, mb, d, ddot, h, radius):
    """The factor on the rotated tangential spring before its increment: none for a constant
    εt (False, 1.0)."""
    return False, 1.0

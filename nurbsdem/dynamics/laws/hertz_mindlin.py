"""Hertz–Mindlin contact with the exact local curvature: ``Interface ID Model HertzMindlin
Restitution e [Friction mu] [RollingFriction mu_r] [RollingDamping eta_r]``.

Normal force (Hertz, elliptical contact)::

    f_n = (4/3) E* √R δ^{3/2}  +  c_n δ̇ ,   clipped at 0 (no tension, as the linear law)
    c_n = 2 ζ √(k_n m*),   k_n = df/dδ = 2 E* √(R δ)   (the tangent stiffness)

R is the force-equivalent radius of the elliptical contact from both surfaces' principal
curvatures and directions at their contact points (:mod:`nurbsdem.geometry.curvature`: exact
spheres 1/r, walls flat; degenerated contacts take the bounding-sphere radius and are counted),
E* = 1/((1−ν_A²)/E_A + (1−ν_B²)/E_B) (a rigid wall: E = inf), m* the reduced mass of the pair.

Damping: the viscous term ∝ δ^{1/4} δ̇ of Tsuji et al. (1992), in the form of LIGGGHTS/EDEM
(c_n = 2 ζ √(k_n m*) with the tangent stiffness).  Why this one: with it the coefficient of
restitution of a Hertz impact does not depend on the impact velocity (Antypov & Elliott 2011:
the impact equation becomes x'' = −x^{3/2} − 2√(3/2) ζ x^{1/4} x' in the units δ0 =
(m* v0² / K)^{2/5}, t0 = δ0/v0), which is what a restitution coefficient asks for; a constant
dashpot would make e fall with the speed.  The ζ of a given e is **not** taken from the linear
oscillator's β = −ln e / √(ln² e + π²) (√(5/6) β in LIGGGHTS/EDEM: with the no-tension clip it
returns e = 0.40 for 0.3, 0.55 for 0.5, 0.21 for 0.05); it is the root of that dimensionless
impact equation, solved once per interface (:func:`damping_ratio`, 0.2–0.6 s), with the same
no-tension clip as the force kernel, so an impact returns the deck's e to the accuracy of the
integration.

Tangential force (Mindlin, no-slip stiffness of the same contact size)::

    f_t = −k_t s − c_t w_t,   k_t = 8 G* a,   a = √(R δ),   c_t = 2 ζ √(k_t m*)

with G* = 1/((2−ν_A)/G_A + (2−ν_B)/G_B), G = E/(2(1+ν)), the existing spring history s
(rotated into the current tangent plane), and the Coulomb limit |f_t| <= μ f_n by the same
return mapping as the linear law.  a = √(R δ) is the radius of the circle with the normal
tangent stiffness of the ellipse (dP/dδ = 2E* a); Mindlin's elliptical compliance differs from
it by the (small) ellipticity terms, not modelled.  The history is incremental in the force,
as Mindlin–Deresiewicz with a growing contact asks (Thornton, Cummins & Cleary 2011): while the
overlap grows the force already built keeps its value and only the increment takes the new
stiffness (the stored s is scaled by k_t,old / k_t,new, with δ_old = δ − h δ̇); while it shrinks
s is kept, so the force falls with k_t and vanishes with the contact.  The plain total form
f_t = −k_t(δ) s (LIGGGHTS' shear history) creates energy while k_t grows: at 2° incidence in
Chung & Ooi's test 4 it returned e_t = 1.003 (tangential energy gained).  The energy ledger
stays closed either way: the friction dissipation is the exact spring work minus the stored
½ k_t |s|².

Elastic energies: (2/5) f_el δ normal (exact while R is constant), ½ k_t |s|² tangential.

Time-step control: the kernel returns per contact (k_n, c_n, k_t, c_t) with the **tangent**
normal stiffness (df/dδ, 1.5× the secant), which the network estimate of
:class:`~nurbsdem.dynamics.system.DemSystem` uses instead of the table's constants.  For the
a-priori estimate and the pairs not yet in contact, a Hertz law carries a linearisation at a
reference impact (:func:`reference_linearisation`) in the row's EN..CT columns.

The row: EN..CT that linearisation, MU, MODEL = :data:`CODE`, then E* (Pa), G* (Pa), ζ (-) in
the law's own columns (:data:`ESTAR`, :data:`GSTAR`, :data:`ZETA`).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import lru_cache

import numpy as np
from numba import njit

from ...errors import InputError
from .keys import LawKey
from .linear_penalty import FRICTION, ROLLING_DAMPING, ROLLING_FRICTION
from .table import CN, CT, EN, ET, MODEL, MU, NCOL, P0, P1, P2, RD, RF

#: the law's code in the table's MODEL column
CODE = 1
#: its own columns of the row: E* (Pa), G* (Pa), ζ (-)
ESTAR, GSTAR, ZETA = P0, P1, P2


# ---------------------------------------------------------------------------- material pairs
def effective_moduli(E_a: float, nu_a: float, E_b: float, nu_b: float) -> tuple[float, float]:
    """(E*, G*) (Pa) of two materials; E = inf is rigid."""
    def comp(E, nu, fac):
        return 0.0 if math.isinf(E) else fac / E
    g_a = math.inf if math.isinf(E_a) else E_a / (2.0 * (1.0 + nu_a))
    g_b = math.inf if math.isinf(E_b) else E_b / (2.0 * (1.0 + nu_b))
    e_star = 1.0 / (comp(E_a, nu_a, 1.0 - nu_a ** 2) + comp(E_b, nu_b, 1.0 - nu_b ** 2))
    g_star = 1.0 / (comp(g_a, nu_a, 2.0 - nu_a) + comp(g_b, nu_b, 2.0 - nu_b))
    return e_star, g_star


# ---------------------------------------------------------------------------- restitution
def _impact_restitution(zeta: float) -> float:
    """Restitution of the dimensionless damped Hertz impact x'' = −x^{3/2} − 2√1.5 ζ x^{1/4} x'
    (x(0) = 0, x'(0) = 1), with the force clipped at 0: |x'| when the force or x returns to 0."""
    from scipy.integrate import solve_ivp
    c = 2.0 * math.sqrt(1.5) * zeta

    def rhs(t, y):
        x = max(y[0], 0.0)
        f = x ** 1.5 + c * x ** 0.25 * y[1]
        return [y[1], -max(f, 0.0)]

    def ends(t, y):
        x = max(y[0], 0.0)
        if y[1] >= 0:
            return 1.0
        return x ** 1.5 + c * x ** 0.25 * y[1] if x > 0 else -1.0
    ends.terminal = True
    ends.direction = -1
    sol = solve_ivp(rhs, (0.0, 50.0), [0.0, 1.0], events=ends, rtol=1e-11, atol=1e-13,
                    max_step=0.01)
    if sol.t_events[0].size:
        return float(abs(sol.y_events[0][0][1]))
    return float(abs(sol.y[1, -1])) if sol.y[0, -1] <= 0 else 0.0


@lru_cache(maxsize=256)
def damping_ratio(e: float) -> float:
    """ζ of the Hertz law (module docstring) whose impact has the restitution e (0 < e <= 1)."""
    from scipy.optimize import brentq
    e = float(e)
    if not (0.0 < e <= 1.0):
        raise InputError(f"Restitution must be in (0, 1], got {e}")
    if e == 1.0:
        return 0.0
    hi = 1.0
    while _impact_restitution(hi) > e:
        hi *= 2.0
        if hi > 1e4:
            raise InputError(f"Restitution {e} is too small for the Hertz damping")
    return float(brentq(lambda z: _impact_restitution(z) - e, 0.0, hi, xtol=1e-12, rtol=1e-12))


def linear_beta_zeta(e: float) -> float:
    """The LIGGGHTS/EDEM damping ratio √(5/6) β, β = −ln e/√(ln²e + π²) (for comparison)."""
    le = math.log(e)
    return math.sqrt(5.0 / 6.0) * (-le) / math.sqrt(le * le + math.pi ** 2)


# ---------------------------------------------------------------------------- the law
def hertz_impact(e_star: float, radius: float, m_eff: float, v: float) -> dict:
    """Undamped Hertz impact theory (Johnson §11.4): max overlap (m), max force (N), duration (s)."""
    k = 4.0 / 3.0 * e_star * math.sqrt(radius)
    d_max = (1.25 * m_eff * v * v / k) ** 0.4
    f_max = k * d_max ** 1.5
    t_c = 2.0 * 1.4716 * d_max / v      # 2 ∫0^1 dx / √(1 − x^{5/2}) = 2 × 1.47164
    return {"overlap": d_max, "force": f_max, "duration": t_c}


def reference_linearisation(e_star: float, g_star: float, zeta: float, radius: float,
                            m_eff: float, v: float) -> tuple[float, float, float, float]:
    """(k_n, c_n, k_t, c_t) at the maximum overlap of an impact at speed v (m/s) of a reduced
    mass m_eff (kg) on a radius (m): the stiffest moment of such an impact."""
    d = hertz_impact(e_star, radius, m_eff, v)["overlap"]
    a = math.sqrt(radius * d)
    kn = 2.0 * e_star * a
    kt = 8.0 * g_star * a
    return kn, 2.0 * zeta * math.sqrt(kn * m_eff), kt, 2.0 * zeta * math.sqrt(kt * m_eff)


@dataclass(frozen=True)
class HertzMindlin:
    """Hertz–Mindlin law of one interface (module docstring).

    e_star, g_star (Pa); restitution (-); mu Coulomb coefficient; ref: the linearisation
    (k_n, c_n, k_t, c_t) used by the a-priori time-step estimate and for pairs not yet in
    contact (:func:`reference_linearisation`); mu_r, eta_r the rolling-friction coefficient
    and the rolling spring's damping ratio (-, :mod:`nurbsdem.dynamics.rolling`)."""

    e_star: float
    g_star: float
    restitution: float
    mu: float = 0.0
    ref: tuple = field(default=(0.0, 0.0, 0.0, 0.0))
    mu_r: float = 0.0
    eta_r: float = 0.0

    #: deck name, the Interface's ``model``, the code of its table rows
    name = "HertzMindlin"
    model = "hertz"
    code = CODE
    #: the kernel needs each contact's equivalent radius (exact curvatures)
    needs_contact_radius = True
    #: its from_interface reads the materials (:class:`~nurbsdem.model.MaterialPair`)
    uses_materials = True
    #: deck keys
    keys = (LawKey("Restitution", "restitution", "", 0.0,
                   "a coefficient of restitution: 0 needs an infinite dashpot, above 1 an "
                   "impact would gain energy", lo_open=True, hi=1.0, required=True),
            FRICTION, ROLLING_FRICTION, ROLLING_DAMPING)
    #: what the law's row depends on besides its keys (for the messages)
    note = ("its stiffness and damping come from the materials' YoungModulus, PoissonRatio "
            "and the Restitution")

    def __post_init__(self) -> None:
        if not (self.e_star > 0 and math.isfinite(self.e_star)):
            raise InputError(f"Hertz law: effective modulus must be finite and > 0 (a rigid pair "
                             f"needs a YoungModulus on one side), got {self.e_star}")
        if not (self.g_star > 0 and math.isfinite(self.g_star)):
            raise InputError(f"Hertz law: effective shear modulus must be finite and > 0, got "
                             f"{self.g_star}")
        if not (math.isfinite(self.mu) and self.mu >= 0):
            raise InputError(f"Hertz law: friction must be finite and >= 0, got {self.mu}")
        if not (math.isfinite(self.mu_r) and self.mu_r >= 0):
            raise InputError(f"Hertz law: rolling friction must be finite and >= 0, got "
                             f"{self.mu_r}")
        if not (math.isfinite(self.eta_r) and self.eta_r >= 0):
            raise InputError(f"Hertz law: rolling damping must be finite and >= 0, got "
                             f"{self.eta_r}")
        damping_ratio(self.restitution)

    @classmethod
    def from_interface(cls, itf, pair) -> "HertzMindlin":
        """The law of an :class:`~nurbsdem.model.Interface` between the materials of ``pair``
        (:class:`~nurbsdem.model.MaterialPair`: elastic constants, the lightest particles'
        reduced mass and radius, a reference speed), with its reference linearisation at an
        impact of that mass at that speed (none where the pair has no particle mass or
        radius)."""
        e_star, g_star = effective_moduli(pair.E_a, pair.nu_a, pair.E_b, pair.nu_b)
        zeta = damping_ratio(itf.restitution)
        ref = (0.0, 0.0, 0.0, 0.0)
        if math.isfinite(pair.m_eff) and pair.radius > 0 and math.isfinite(e_star):
            ref = reference_linearisation(e_star, g_star, zeta, pair.radius, pair.m_eff,
                                          pair.speed)
        return cls(e_star, g_star, float(itf.restitution), float(itf.friction), ref,
                   float(itf.rolling_friction), float(itf.rolling_damping))

    @property
    def zeta(self) -> float:
        return damping_ratio(self.restitution)

    # the a-priori estimate of DemSystem reads these (N/m, N s/m)
    en = property(lambda self: self.ref[0])
    cn = property(lambda self: self.ref[1])
    et = property(lambda self: self.ref[2])
    ct = property(lambda self: self.ref[3])

    def as_row(self) -> np.ndarray:
        row = np.zeros(NCOL)
        row[EN], row[CN], row[ET], row[CT] = self.ref
        row[MU], row[MODEL], row[ESTAR], row[GSTAR], row[ZETA] = (
            self.mu, CODE, self.e_star, self.g_star, self.zeta)
        row[RF] = self.mu_r
        row[RD] = self.eta_r
        return row


# ---------------------------------------------------------------------------- the kernel parts
@njit(cache=True, inline="always")
def normal(table, ma, mb, d, radius, imass):
    """The normal part of the law for a contact of depth d (m) and equivalent radius ``radius``
    (m) between materials ma, mb whose bodies' inverse masses sum to imass (1/kg):
    (k_n the tangent stiffness 2E*a, c_n, k_t = 8G*a, c_t, the elastic force (4/3)E*√R δ^{3/2}
    (N), the normal elastic energy (2/5) f δ (J)), a = √(R δ)."""
    dp = d if d > 0.0 else 0.0
    aa = math.sqrt(radius * dp)
    knt = 2.0 * table[ma, mb, ESTAR] * aa
    et = 8.0 * table[ma, mb, GSTAR] * aa
    meff = 1.0 / imass if imass > 0.0 else 0.0
    cn = 2.0 * table[ma, mb, ZETA] * math.sqrt(knt * meff)
    ct = 2.0 * table[ma, mb, ZETA] * math.sqrt(et * meff)
    fel = (2.0 / 3.0) * knt * dp          # (4/3) E* √R δ^{3/2}
    eel_n = 0.4 * fel * dp
    return knt, cn, et, ct, fel, eel_n


@njit(cache=True, inline="always")
def spring_scale(table, ma, mb, d, ddot, h, radius):
    """The factor on the rotated tangential spring before its increment (Mindlin–Deresiewicz,
    module docstring): while loading (ḋ > 0) the force so far keeps its value and the increment
    takes the new stiffness, k_t,old s = k_t,new s', with δ_old = δ − h ḋ (0 where δ_old <= 0);
    unloading keeps s, so the force falls with k_t.  Returns (whether to scale, the factor)."""
    dp = d if d > 0.0 else 0.0
    aa = math.sqrt(radius * dp)
    if ddot > 0.0 and aa > 0.0:
        d_old = dp - h * ddot
        sc = math.sqrt(radius * d_old) / aa if d_old > 0.0 else 0.0
        return True, sc
    return False, 1.0

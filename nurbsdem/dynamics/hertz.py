"""Hertz–Mindlin contact with the exact local curvature (``Interface ... Model HertzMindlin``).

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
reference impact (:func:`reference_linearisation`).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import lru_cache

import numpy as np

from ..errors import InputError
from .forces import CN, CT, EN, ET, ESTAR, GSTAR, HERTZ, MODEL, MU, ZETA

#: model ids in the table's MODEL column


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
class HertzMindlinLaw:
    """Hertz–Mindlin law of one interface (module docstring).

    e_star, g_star (Pa); restitution (-); mu Coulomb coefficient; ref: the linearisation
    (k_n, c_n, k_t, c_t) used by the a-priori time-step estimate and for pairs not yet in
    contact (:func:`reference_linearisation`)."""

    e_star: float
    g_star: float
    restitution: float
    mu: float = 0.0
    ref: tuple = field(default=(0.0, 0.0, 0.0, 0.0))

    def __post_init__(self) -> None:
        if not (self.e_star > 0 and math.isfinite(self.e_star)):
            raise InputError(f"Hertz law: effective modulus must be finite and > 0 (a rigid pair "
                             f"needs a YoungModulus on one side), got {self.e_star}")
        if not (self.g_star > 0 and math.isfinite(self.g_star)):
            raise InputError(f"Hertz law: effective shear modulus must be finite and > 0, got "
                             f"{self.g_star}")
        if not (math.isfinite(self.mu) and self.mu >= 0):
            raise InputError(f"Hertz law: friction must be finite and >= 0, got {self.mu}")
        damping_ratio(self.restitution)

    @property
    def zeta(self) -> float:
        return damping_ratio(self.restitution)

    # the a-priori estimate of DemSystem reads these (N/m, N s/m)
    en = property(lambda self: self.ref[0])
    cn = property(lambda self: self.ref[1])
    et = property(lambda self: self.ref[2])
    ct = property(lambda self: self.ref[3])

    def as_row(self) -> np.ndarray:
        row = np.zeros(9)
        row[EN], row[CN], row[ET], row[CT] = self.ref
        row[MU], row[MODEL], row[ESTAR], row[GSTAR], row[ZETA] = (
            self.mu, HERTZ, self.e_star, self.g_star, self.zeta)
        return row


def law_from_deck(model, itf, mat_a: int, mat_b: int | None,
                  wall_material: int | None = None) -> HertzMindlinLaw:
    """The Hertz–Mindlin law of deck interface ``itf`` between particle materials mat_a and
    mat_b (deck ids; mat_b None: a wall of material ``wall_material``, None: rigid), with its
    reference linearisation from the lightest particles of those materials, their bounding
    radii and a reference speed: the largest of 1 m/s, the particles' initial speeds and the
    free-fall speed over the scene's height."""
    mats = model.materials
    ma = mats[mat_a]
    E_a, nu_a = _elastic(model, ma, itf)
    if mat_b is None:
        wm = wall_material
        E_b, nu_b = (math.inf, 0.0) if wm is None else _elastic(model, mats[wm], itf)
    else:
        E_b, nu_b = _elastic(model, mats[mat_b], itf)
    e_star, g_star = effective_moduli(E_a, nu_a, E_b, nu_b)
    zeta = damping_ratio(itf.restitution)
    light = _lightest(model)
    m_a, r_a = light.get(mat_a, (math.inf, 0.0))
    if mat_b is None:
        m_eff, r = m_a, r_a
    else:
        m_b, r_b = light.get(mat_b, (math.inf, 0.0))
        m_eff = m_a * m_b / (m_a + m_b) if math.isfinite(m_a + m_b) else min(m_a, m_b)
        r = r_a * r_b / (r_a + r_b) if r_a + r_b > 0 else 0.0
    ref = (0.0, 0.0, 0.0, 0.0)
    if math.isfinite(m_eff) and r > 0 and math.isfinite(e_star):
        ref = reference_linearisation(e_star, g_star, zeta, r, m_eff, _reference_speed(model))
    return HertzMindlinLaw(e_star, g_star, float(itf.restitution), float(itf.friction), ref)


def _elastic(model, mat, itf) -> tuple[float, float]:
    E = getattr(mat, "young_modulus", None)
    if E is None:
        raise model.error(f"Interface {itf.id} (Model HertzMindlin) needs YoungModulus on "
                          f"Material {mat.id} (line {mat.line})", itf.line)
    return float(E), float(getattr(mat, "poisson_ratio", 0.0) or 0.0)


def _lightest(model) -> dict[int, tuple[float, float]]:
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


def _reference_speed(model) -> float:
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


# ---------------------------------------------------------------------------- the kernel
def has_hertz(table: np.ndarray) -> bool:
    """Whether a dense interface table (M, M, NCOL) holds a Hertz–Mindlin row."""
    return bool(table.shape[-1] > MODEL and np.any(table[..., MODEL] == HERTZ))

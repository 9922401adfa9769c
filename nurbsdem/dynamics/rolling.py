"""Rolling resistance: an elastic–plastic rolling spring per contact, common to all laws
(``Interface ... RollingFriction mu_r [RollingDamping eta_r]``; the interface table's ``RF``
and ``RD`` columns).

The model is the elastic–plastic spring with its viscous damper of Ai, Chen, Rotter & Ooi
(2011, "Assessment of rolling resistance models in discrete element simulations", Powder
Technol. 206, model C, the EPSD model of LIGGGHTS' ``epsd``).  Per contact, with n the unit
normal from A towards B and the contact's rolling radius R_r:

* relative rolling velocity (the twist about n excluded)::

      ω_r = ω_rel − (ω_rel·n) n,    ω_rel = ω_B − ω_A

* the rolling spring θ (rad, a vector in the tangent plane, stored with the tangential spring
  under the contact's key, :func:`nurbsdem.dynamics.forces.match_history`) is rotated into the
  current tangent plane keeping its length, as the tangential spring, then incremented::

      θ* = θ' + h ω_r,    M* = −k_r θ*     (torque on B; A receives −M)

* the plastic limit, a return mapping as Coulomb's::

      |M| <= M_max = μ_r R_r f_n:   else θ = θ* M_max/|M*|, M = M* M_max/|M*|

* while the spring holds (M* within the limit), the damper's torque joins it::

      M = M* − C_r ω_r,    C_r = 2 η_r √(I_r k_r)

  with I_r the rolling inertia: a sphere's about its contact point, 1.4 m ℓ² (ℓ the lever
  arm, :func:`rolling_geometry`), for a pair I_A I_B/(I_A + I_B), against a wall the
  particle's (Ai et al.'s and LIGGGHTS' choice); a sphere rocking on a floor on its rolling
  spring is then an oscillator of damping ratio η_r.  Once the spring has yielded, no damper
  acts (the torque is the plastic limit's), as in LIGGGHTS;

* stiffness k_r = 2.25 μ_r² R_r² k_n (Ai et al.'s choice for 3D, as in LIGGGHTS ``epsd``)
  with k_n the law's tangent normal stiffness: the spring yields at the rotation
  θ_y = M_max/k_r = f_n/(2.25 μ_r R_r k_n), for a linear law d/(2.25 μ_r R_r) (4e-4 rad for
  a 1 cm sphere of the tests at rest with μ_r = 0.1).

A rolling body thus meets a constant torque μ_r R_r f_n against its rolling once the spring has
yielded (the constant directional torque of Ai's model A), and a body at rest under a torque
below M_max stays at rest without chatter (the spring holds it, which model A cannot).

Rolling radius: the contact's equivalent radius that the Hertz–Mindlin law uses (the
force-equivalent radius of both surfaces' principal curvatures at the contact points,
:mod:`nurbsdem.geometry.curvature`: R_a R_b/(R_a + R_b) for two spheres, the sphere's radius
against a flat wall; a degenerated contact takes the bounding-sphere radius), at most the
lever arms' ℓ_A ℓ_B/(ℓ_A + ℓ_B), ℓ the distance from a particle's centroid to its contact
point (a wall's ℓ infinite: ℓ of the particle), the rolling radius of EDEM's rolling friction
(:func:`rolling_geometry`).  For spheres both are the radii's combination; on a flat or nearly
flat face of a NURBS particle the curvature radius grows without bound, the torque a rolling
spring could hold with it exceeds what the particle's size can carry, and the lever arm
bounds it.  A contact without a radius (a contact provider that gives none) has no rolling
resistance.

Energy: the rolling torque's work (the damper's included) enters the ledger as the tangential
spring's does (the exact discrete work of the half kicks,
:func:`nurbsdem.dynamics.integrator.kick_from`), its elastic energy ½ k_r |θ|² is booked with
the tangential spring's, so the plastic part and the damper's work appear as friction
dissipation (:mod:`nurbsdem.dynamics.energy`); against a turning wall the torque's work on the
wall's spin is that wall's external work (:func:`nurbsdem.dynamics.forces.add_rolling_work`).

Time step: the rolling spring is not in the time-step control's network.  Its frequency for a
sphere on a wall, √(k_r / I) with I = 2/5 m R², is 2.37 μ_r √(k_n/m): below the normal
spring's for μ_r < 0.42, the bound of the supported range (:data:`nurbsdem.ranges.RANGES`).
With the damper (damping ratio η_r) an explicit step is stable up to (2/ω)(√(1 + η_r²) − η_r),
so η_r is supported up to 0.3, where that still exceeds the step the normal spring allows at
μ_r = 0.4.

Layout: the springs are (K, :data:`NSPRING`), columns 0–2 the tangential spring (m), 3–5 the
rolling spring (rad); the tangential elastic forces ``f_el_t`` (K, 6) carry the rolling torque on
B (N m) in columns 3–5.  With μ_r = 0 those columns are zero and nothing else changes.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

#: columns of a contact's spring history: tangential (0–2, m), rolling (3–5, rad)
NSPRING = 6
#: first column of the rolling spring and of the rolling torque
ROLL = 3
#: k_r = ROLLING_STIFFNESS μ_r² R_r² k_n (Ai et al. 2011, 3D)
ROLLING_STIFFNESS = 2.25
#: a particle's rolling inertia ROLLING_INERTIA m ℓ² (a sphere's about its contact point:
#: 2/5 + 1; Ai et al. 2011, LIGGGHTS ``epsd``)
ROLLING_INERTIA = 1.4


@njit(cache=True, inline="always")
def spring_in_plane(spring, c, col, n0, n1, n2):
    """The spring spring[c, col:col+3] of contact c rotated into the tangent plane of the unit
    normal n, keeping its length (the tangential spring from column 0, the rolling spring from
    :data:`ROLL`)."""
    s0, s1, s2 = spring[c, col], spring[c, col + 1], spring[c, col + 2]
    smag = math.sqrt(s0 * s0 + s1 * s1 + s2 * s2)
    sn = s0 * n0 + s1 * n1 + s2 * n2
    s0, s1, s2 = s0 - sn * n0, s1 - sn * n1, s2 - sn * n2
    spm = math.sqrt(s0 * s0 + s1 * s1 + s2 * s2)
    if spm > 0.0:
        sc = smag / spm
        s0, s1, s2 = s0 * sc, s1 * sc, s2 * sc
    return s0, s1, s2


@njit(cache=True, inline="always")
def rolling_geometry(c, radius, a, b, point_a, point_b, pos, inv_mass):
    """(R_r m, I_r kg m²) of contact c between bodies a and b (module docstring): the rolling
    radius, the contact's equivalent radius ``radius`` (m) at most ℓ_A ℓ_B/(ℓ_A + ℓ_B), and
    the rolling inertia, 1.4 m ℓ² per particle combined as I_A I_B/(I_A + I_B); ℓ the
    distance from a particle's centroid (pos (B,3) m) to its contact point (point_a, point_b
    (K,3) m), inv_mass (B,) 1/kg; a wall (inv_mass 0) has neither an arm nor an inertia."""
    la = math.sqrt((point_a[c, 0] - pos[a, 0]) ** 2 + (point_a[c, 1] - pos[a, 1]) ** 2
                   + (point_a[c, 2] - pos[a, 2]) ** 2)
    lb = math.sqrt((point_b[c, 0] - pos[b, 0]) ** 2 + (point_b[c, 1] - pos[b, 1]) ** 2
                   + (point_b[c, 2] - pos[b, 2]) ** 2)
    if inv_mass[a] == 0.0:
        cap = lb
        inertia = ROLLING_INERTIA * lb * lb / inv_mass[b]
    elif inv_mass[b] == 0.0:
        cap = la
        inertia = ROLLING_INERTIA * la * la / inv_mass[a]
    else:
        cap = la * lb / (la + lb)
        ia = ROLLING_INERTIA * la * la / inv_mass[a]
        ib = ROLLING_INERTIA * lb * lb / inv_mass[b]
        inertia = ia * ib / (ia + ib)
    return min(radius, cap), inertia


@njit(cache=True, inline="always")
def rolling_result(c, mu_r, eta_r, kn, fn, radius, inertia, n0, n1, n2, a, b, omg, h, spring,
                   f_el_t, e_el):
    """The rolling spring and damper of contact c (module docstring): updates spring[c, 3:6]
    (rad), writes the torque on B into f_el_t[c, 3:6] (N m) and adds ½ k_r |θ|² to e_el[c, 1]
    (J).  mu_r, eta_r (-); kn the law's tangent normal stiffness (N/m); fn the normal force
    (N); radius, inertia the rolling radius (m) and inertia (kg m²); n the unit normal; a, b
    the bodies (omg (B,3) rad/s); h (s)."""
    kr = ROLLING_STIFFNESS * mu_r * mu_r * radius * radius * kn
    r0, r1, r2 = spring_in_plane(spring, c, ROLL, n0, n1, n2)
    o0 = omg[b, 0] - omg[a, 0]
    o1 = omg[b, 1] - omg[a, 1]
    o2 = omg[b, 2] - omg[a, 2]
    on = o0 * n0 + o1 * n1 + o2 * n2
    w0, w1, w2 = o0 - on * n0, o1 - on * n1, o2 - on * n2
    r0, r1, r2 = r0 + h * w0, r1 + h * w1, r2 + h * w2
    m0, m1, m2 = -kr * r0, -kr * r1, -kr * r2
    mm = math.sqrt(m0 * m0 + m1 * m1 + m2 * m2)
    mmax = mu_r * radius * fn
    if mm > mmax:
        alpha = mmax / mm
        r0, r1, r2 = alpha * r0, alpha * r1, alpha * r2
        m0, m1, m2 = alpha * m0, alpha * m1, alpha * m2
    elif eta_r > 0.0:                   # the damper, while the spring holds
        cr = 2.0 * eta_r * math.sqrt(inertia * kr)
        m0, m1, m2 = m0 - cr * w0, m1 - cr * w1, m2 - cr * w2
    spring[c, ROLL], spring[c, ROLL + 1], spring[c, ROLL + 2] = r0, r1, r2
    f_el_t[c, ROLL], f_el_t[c, ROLL + 1], f_el_t[c, ROLL + 2] = m0, m1, m2
    e_el[c, 1] += 0.5 * kr * (r0 * r0 + r1 * r1 + r2 * r2)


@njit(cache=True, inline="always")
def no_rolling(c, spring, f_el_t):
    """Contact c without rolling resistance: its rolling spring and torque are zero (when the
    arrays have the rolling columns)."""
    if spring.shape[1] >= NSPRING and f_el_t.shape[1] >= NSPRING:
        for k in range(ROLL, NSPRING):
            spring[c, k] = 0.0
            f_el_t[c, k] = 0.0


def widened(springs: np.ndarray) -> np.ndarray:
    """A spring history (K, S) as (K, :data:`NSPRING`) floats: a history of tangential springs
    only (S = 3: a checkpoint or a carried-over history of an earlier version) gets zero
    rolling springs."""
    springs = np.asarray(springs, dtype=float)
    springs = springs.reshape(springs.shape[0] if springs.ndim else 0, -1) if springs.size \
        else np.zeros((0, NSPRING))
    if springs.shape[1] >= NSPRING:
        return np.array(springs[:, :NSPRING], copy=True)
    out = np.zeros((springs.shape[0], NSPRING))
    out[:, :springs.shape[1]] = springs
    return out

"""Rolling resistance: an elastic–plastic rolling spring per contact, common to all laws
(``Interface ... RollingFriction mu_r``; the interface table's ``RF`` column).

The model is the elastic–plastic spring of Ai, Chen, Rotter & Ooi (2011, "Assessment of rolling
resistance models in discrete element simulations", Powder Technol. 206, model C, the EPSD
model of LIGGGHTS' ``epsd``) without its viscous part.  Per contact, with n the unit normal from
A towards B and the contact's rolling radius R_r:

* relative rolling velocity (the twist about n excluded)::

      ω_r = ω_rel − (ω_rel·n) n,    ω_rel = ω_B − ω_A

* the rolling spring θ (rad, a vector in the tangent plane, stored with the tangential spring
  under the contact's key, :func:`nurbsdem.dynamics.forces.match_history`) is rotated into the
  current tangent plane keeping its length, as the tangential spring, then incremented::

      θ* = θ' + h ω_r,    M* = −k_r θ*     (torque on B; A receives −M)

* the plastic limit, a return mapping as Coulomb's::

      |M| <= M_max = μ_r R_r f_n:   else θ = θ* M_max/|M*|, M = M* M_max/|M*|

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
(:func:`rolling_radius`).  For spheres both are the radii's combination; on a flat or nearly
flat face of a NURBS particle the curvature radius grows without bound, the torque a rolling
spring could hold with it exceeds what the particle's size can carry, and the lever arm
bounds it.  A contact without a radius (a contact provider that gives none) has no rolling
resistance.

Energy: the rolling torque's work enters the ledger as the tangential spring's does (the exact
discrete work of the half kicks, :func:`nurbsdem.dynamics.integrator.kick_from`), its elastic
energy ½ k_r |θ|² is booked with the tangential spring's, so the plastic part appears as
friction dissipation (:mod:`nurbsdem.dynamics.energy`); against a turning wall the torque's
work on the wall's spin is that wall's external work
(:func:`nurbsdem.dynamics.forces.add_rolling_work`).

Time step: the rolling spring is not in the time-step control's network.  Its frequency for a
sphere on a wall, √(k_r / I) with I = 2/5 m R², is 2.37 μ_r √(k_n/m): below the normal
spring's for μ_r < 0.42, the bound of the supported range (:data:`nurbsdem.ranges.RANGES`).

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
def rolling_radius(c, radius, a, b, point_a, point_b, pos, inv_mass):
    """The rolling radius R_r (m) of contact c between bodies a and b (module docstring): the
    contact's equivalent radius ``radius`` (m), at most ℓ_A ℓ_B/(ℓ_A + ℓ_B) with ℓ the
    distance from a particle's centroid (pos (B,3) m) to its contact point (point_a, point_b
    (K,3) m); a wall (inv_mass 0) has no arm of its own."""
    la = math.sqrt((point_a[c, 0] - pos[a, 0]) ** 2 + (point_a[c, 1] - pos[a, 1]) ** 2
                   + (point_a[c, 2] - pos[a, 2]) ** 2)
    lb = math.sqrt((point_b[c, 0] - pos[b, 0]) ** 2 + (point_b[c, 1] - pos[b, 1]) ** 2
                   + (point_b[c, 2] - pos[b, 2]) ** 2)
    if inv_mass[a] == 0.0:
        cap = lb
    elif inv_mass[b] == 0.0:
        cap = la
    else:
        cap = la * lb / (la + lb)
    return min(radius, cap)


@njit(cache=True, inline="always")
def rolling_result(c, mu_r, kn, fn, radius, n0, n1, n2, a, b, omg, h, spring, f_el_t, e_el):
    """The rolling spring of contact c (module docstring): updates spring[c, 3:6] (rad),
    writes the torque on B into f_el_t[c, 3:6] (N m) and adds ½ k_r |θ|² to e_el[c, 1] (J).
    mu_r (-); kn the law's tangent normal stiffness (N/m); fn the normal force (N); radius
    the rolling radius (m); n the unit normal; a, b the bodies (omg (B,3) rad/s); h (s)."""
    kr = ROLLING_STIFFNESS * mu_r * mu_r * radius * radius * kn
    r0, r1, r2 = spring_in_plane(spring, c, ROLL, n0, n1, n2)
    o0 = omg[b, 0] - omg[a, 0]
    o1 = omg[b, 1] - omg[a, 1]
    o2 = omg[b, 2] - omg[a, 2]
    on = o0 * n0 + o1 * n1 + o2 * n2
    r0, r1, r2 = r0 + h * (o0 - on * n0), r1 + h * (o1 - on * n1), r2 + h * (o2 - on * n2)
    m0, m1, m2 = -kr * r0, -kr * r1, -kr * r2
    mm = math.sqrt(m0 * m0 + m1 * m1 + m2 * m2)
    mmax = mu_r * radius * fn
    if mm > mmax:
        alpha = mmax / mm
        r0, r1, r2 = alpha * r0, alpha * r1, alpha * r2
        m0, m1, m2 = alpha * m0, alpha * m1, alpha * m2
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

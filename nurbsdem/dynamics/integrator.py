"""Explicit symplectic splitting for rigid bodies: velocity Verlet + DLM free-rigid-body rotation.

One internal step of length h (s), the kick–drift–kick (Störmer–Verlet) splitting of
``H = T_trans + T_rot + V``::

    v += (h/2) F/m ;  L += (h/2) τ                       half kick (forces of the previous eval.)
    x += h v                                             translational drift
    q  ← free rigid body flow over h (DLM splitting)      rotational drift, L (world) fixed
    F, τ ← forces(x, q, v, ω)                            one contact evaluation per step
    v += (h/2) F/m ;  L += (h/2) τ                       half kick

Why this scheme
---------------
* Translation is velocity Verlet: symplectic, second order, time reversible, and **exact for a
  constant force** (free fall: x = x0 + v0 t + g t²/2 to round-off).
* Rotation: the torque-free motion of an asymmetric body (I1 < I2 < I3) is integrated by the
  Dullweber–Leimkuhler–McLachlan (J. Chem. Phys. 107, 5840, 1997) splitting of the kinetic energy
  in the principal frame, ``T = π1²/2I1 + π2²/2I2 + π3²/2I3`` (π = Qᵀ L the body angular
  momentum).  Each term's flow is an *exact* rotation about one principal axis by the angle
  h πi / Ii, composed symmetrically ``R1(h/2) R2(h/2) R3(h) R2(h/2) R1(h/2)``.  Hence: the
  orientation stays a rotation (unit quaternion), the spatial angular momentum L is conserved
  exactly (we store L in the world frame and only the body frame moves), the kinetic energy has no
  drift (bounded O(h²) error, symplectic), and the intermediate-axis instability is reproduced.
  A body with three equal moments (a sphere) rotates at constant ω = L/I: its flow is one exact
  rotation about L, used instead (two trigonometric calls instead of ten).
  Torques enter as kicks of the world L, so the whole scheme is a symplectic splitting for
  conservative forces.  (Explicit Euler or an RK on ω with a non-diagonal inertia would drift in
  energy and in |L|.)
* Velocity-dependent (damping) forces are evaluated with the half-step velocities v(n+1/2),
  ω from L(n+1/2) at the new positions — the usual DEM choice (LAMMPS/LIGGGHTS).  Its stability
  limit for a spring–dashpot is Δt_cr = (2/ω)(√(1+ζ²) − ζ), used by the time-step
  control in :mod:`nurbsdem.dynamics.system`.

All kernels are numba functions over (N,·) arrays, deterministic: the per-body and per-contact
passes run on threads for large scenes (:data:`~nurbsdem.jit.THREADED_ROWS`), each row's
arithmetic unchanged.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from ..geometry.rotation import quat_mul
from ..jit import ROW_CHUNK, THREADED_ROWS, n_chunks
from .forces import add_rolling_work, kick_work_terms
from .rigid import omega_world


@njit(cache=True)
def _half_kick_range(v: np.ndarray, L: np.ndarray, force: np.ndarray, torque: np.ndarray,
                     inv_mass: np.ndarray, hk: float, lo: int, hi: int) -> None:
    """:func:`half_kick` of bodies lo .. hi-1."""
    for i in range(lo, hi):
        for k in range(3):
            v[i, k] += hk * force[i, k] * inv_mass[i]
            L[i, k] += hk * torque[i, k]


@njit(cache=True, parallel=True)
def _half_kick_threads(v, L, force, torque, inv_mass, hk) -> None:
    n = v.shape[0]
    for t in prange(n_chunks(n)):
        _half_kick_range(v, L, force, torque, inv_mass, hk, t * ROW_CHUNK,
                         min(n, (t + 1) * ROW_CHUNK))


@njit(cache=True)
def half_kick(v: np.ndarray, L: np.ndarray, force: np.ndarray, torque: np.ndarray,
              inv_mass: np.ndarray, hk: float) -> None:
    """v += hk F/m, L += hk τ (in place) for the N particles (force/torque rows 0..N-1);
    on threads from :data:`~nurbsdem.jit.THREADED_ROWS` bodies (the same bits)."""
    if v.shape[0] >= THREADED_ROWS:
        _half_kick_threads(v, L, force, torque, inv_mass, hk)
    else:
        _half_kick_range(v, L, force, torque, inv_mass, hk, np.int64(0), v.shape[0])


@njit(cache=True)
def _rotate_about_axis(q: np.ndarray, i: int, L: np.ndarray, inv_I: np.ndarray, axis: int,
                       h: float) -> None:
    """Exact flow of T_axis = π_axis²/(2 I_axis) over h for body i (rows of q (N,4), L, 1/I
    (N,3), read in place): q ← q ⊗ exp(θ/2 e_axis), θ = h π_axis/I_axis.

    π_axis = (Q e_axis)·L is the body-frame component of the world angular momentum L.
    """
    w, x, y, z = q[i, 0], q[i, 1], q[i, 2], q[i, 3]
    # column `axis` of Q(q)
    if axis == 0:
        c0, c1, c2 = 1.0 - 2.0 * (y * y + z * z), 2.0 * (x * y + w * z), 2.0 * (x * z - w * y)
    elif axis == 1:
        c0, c1, c2 = 2.0 * (x * y - w * z), 1.0 - 2.0 * (x * x + z * z), 2.0 * (y * z + w * x)
    else:
        c0, c1, c2 = 2.0 * (x * z + w * y), 2.0 * (y * z - w * x), 1.0 - 2.0 * (x * x + y * y)
    pi_k = c0 * L[i, 0] + c1 * L[i, 1] + c2 * L[i, 2]
    half = 0.5 * h * pi_k * inv_I[i, axis]
    sn = math.sin(half)
    q[i, 0], q[i, 1], q[i, 2], q[i, 3] = quat_mul(w, x, y, z, math.cos(half),
                                                  sn if axis == 0 else 0.0,
                                                  sn if axis == 1 else 0.0,
                                                  sn if axis == 2 else 0.0)


@njit(cache=True)
def _rotate_isotropic(q: np.ndarray, i: int, L: np.ndarray, inv_I: float, h: float) -> None:
    """Exact flow of T = |L|²/(2I) over h for body i with equal principal moments (a sphere;
    rows of q, L read in place): ω = L/I is constant, q ← exp(θ/2 L̂) ⊗ q with
    θ = h |L| / I (a rotation about the world axis L̂).  The DLM splitting would give it only
    to O(h³), at five times the cost."""
    l0, l1, l2 = L[i, 0], L[i, 1], L[i, 2]
    lm = math.sqrt(l0 * l0 + l1 * l1 + l2 * l2)
    if lm == 0.0:
        return
    half = 0.5 * h * lm * inv_I
    s = math.sin(half) / lm
    q[i, 0], q[i, 1], q[i, 2], q[i, 3] = quat_mul(math.cos(half), s * l0, s * l1, s * l2,
                                                  q[i, 0], q[i, 1], q[i, 2], q[i, 3])


@njit(cache=True)
def _rotate_range(q: np.ndarray, L: np.ndarray, inv_I: np.ndarray, h: float, lo: int,
                  hi: int) -> None:
    """:func:`free_rotation` of bodies lo .. hi-1."""
    for i in range(lo, hi):
        if inv_I[i, 0] == inv_I[i, 1] and inv_I[i, 1] == inv_I[i, 2]:
            _rotate_isotropic(q, i, L, inv_I[i, 0], h)
        else:
            _rotate_about_axis(q, i, L, inv_I, 0, 0.5 * h)
            _rotate_about_axis(q, i, L, inv_I, 1, 0.5 * h)
            _rotate_about_axis(q, i, L, inv_I, 2, h)
            _rotate_about_axis(q, i, L, inv_I, 1, 0.5 * h)
            _rotate_about_axis(q, i, L, inv_I, 0, 0.5 * h)
        nrm = math.sqrt(q[i, 0] * q[i, 0] + q[i, 1] * q[i, 1] + q[i, 2] * q[i, 2]
                        + q[i, 3] * q[i, 3])
        for k in range(4):
            q[i, k] /= nrm


@njit(cache=True)
def free_rotation(q: np.ndarray, L: np.ndarray, inv_I: np.ndarray, h: float) -> None:
    """DLM symmetric splitting R1(h/2) R2(h/2) R3(h) R2(h/2) R1(h/2) for every body (in place),
    the exact rotation for a body with equal principal moments (:func:`_rotate_isotropic`);
    the quaternion is renormalised afterwards (round-off only)."""
    _rotate_range(q, L, inv_I, h, np.int64(0), q.shape[0])


@njit(cache=True)
def _drift_range(x: np.ndarray, v: np.ndarray, q: np.ndarray, L: np.ndarray,
                 inv_I: np.ndarray, h: float, lo: int, hi: int) -> None:
    """:func:`drift` of bodies lo .. hi-1."""
    for i in range(lo, hi):
        for k in range(3):
            x[i, k] += h * v[i, k]
    _rotate_range(q, L, inv_I, h, lo, hi)


@njit(cache=True, parallel=True)
def _drift_threads(x, v, q, L, inv_I, h) -> None:
    n = x.shape[0]
    for t in prange(n_chunks(n)):
        _drift_range(x, v, q, L, inv_I, h, t * ROW_CHUNK, min(n, (t + 1) * ROW_CHUNK))


@njit(cache=True)
def drift(x: np.ndarray, v: np.ndarray, q: np.ndarray, L: np.ndarray, inv_I: np.ndarray,
          h: float) -> None:
    """x += h v and the free rotation over h (in place); on threads from
    :data:`~nurbsdem.jit.THREADED_ROWS` bodies (the same bits)."""
    if x.shape[0] >= THREADED_ROWS:
        _drift_threads(x, v, q, L, inv_I, h)
    else:
        _drift_range(x, v, q, L, inv_I, h, np.int64(0), x.shape[0])


@njit(cache=True)
def kinetic_energies(mass: np.ndarray, v: np.ndarray, q: np.ndarray, L: np.ndarray,
                     inv_I: np.ndarray) -> tuple[float, float]:
    """Translational ½ m v² and rotational ½ πᵀ I⁻¹ π (π = Qᵀ L) kinetic energies (J)."""
    et = 0.0
    er = 0.0
    for i in range(v.shape[0]):
        et += 0.5 * mass[i] * (v[i, 0] ** 2 + v[i, 1] ** 2 + v[i, 2] ** 2)
        w, x, y, z = q[i, 0], q[i, 1], q[i, 2], q[i, 3]
        # π_k = column k of Q · L
        p0 = (1.0 - 2.0 * (y * y + z * z)) * L[i, 0] + 2.0 * (x * y + w * z) * L[i, 1] \
            + 2.0 * (x * z - w * y) * L[i, 2]
        p1 = 2.0 * (x * y - w * z) * L[i, 0] + (1.0 - 2.0 * (x * x + z * z)) * L[i, 1] \
            + 2.0 * (y * z + w * x) * L[i, 2]
        p2 = 2.0 * (x * z + w * y) * L[i, 0] + 2.0 * (y * z - w * x) * L[i, 1] \
            + (1.0 - 2.0 * (x * x + y * y)) * L[i, 2]
        er += 0.5 * (p0 * p0 * inv_I[i, 0] + p1 * p1 * inv_I[i, 1] + p2 * p2 * inv_I[i, 2])
    return et, er


def state_is_finite(x: np.ndarray, v: np.ndarray, q: np.ndarray, L: np.ndarray) -> bool:
    """True when every state array is finite."""
    return bool(np.isfinite(x).all() and np.isfinite(v).all() and np.isfinite(q).all()
                and np.isfinite(L).all())


@njit(cache=True)
def _point_velocities_range(body_a: np.ndarray, body_b: np.ndarray, point: np.ndarray,
                            x: np.ndarray, v: np.ndarray, omega: np.ndarray,
                            wall_u: np.ndarray, out: np.ndarray, lo: int, hi: int) -> None:
    """:func:`_relative_point_velocities` of contacts lo .. hi-1."""
    N = x.shape[0]
    for c in range(lo, hi):
        for k in range(3):
            out[c, k] = 0.0
        for side in range(2):
            i = body_b[c] if side == 0 else body_a[c]
            sign = 1.0 if side == 0 else -1.0
            if i >= N:
                for k in range(3):
                    out[c, k] += sign * wall_u[i - N, k]
                continue
            r0, r1, r2 = point[c, 0] - x[i, 0], point[c, 1] - x[i, 1], point[c, 2] - x[i, 2]
            w0, w1, w2 = omega[i, 0], omega[i, 1], omega[i, 2]
            out[c, 0] += sign * (v[i, 0] + w1 * r2 - w2 * r1)
            out[c, 1] += sign * (v[i, 1] + w2 * r0 - w0 * r2)
            out[c, 2] += sign * (v[i, 2] + w0 * r1 - w1 * r0)


@njit(cache=True, parallel=True)
def _point_velocities_threads(body_a, body_b, point, x, v, omega, wall_u, out) -> None:
    n = body_a.shape[0]
    for t in prange(n_chunks(n)):
        _point_velocities_range(body_a, body_b, point, x, v, omega, wall_u, out,
                                t * ROW_CHUNK, min(n, (t + 1) * ROW_CHUNK))


@njit(cache=True)
def _relative_point_velocities(body_a: np.ndarray, body_b: np.ndarray, point: np.ndarray,
                               x: np.ndarray, wall_d: np.ndarray, v: np.ndarray,
                               omega: np.ndarray, wall_u: np.ndarray, out: np.ndarray) -> None:
    """out (K,3): velocity of B relative to A at each contact point (m/s); bodies >= N are
    walls (position wall_d, velocity wall_u, no rotation); on threads from
    :data:`~nurbsdem.jit.THREADED_ROWS` contacts (the same bits)."""
    if body_a.shape[0] >= THREADED_ROWS:
        _point_velocities_threads(body_a, body_b, point, x, v, omega, wall_u, out)
    else:
        _point_velocities_range(body_a, body_b, point, x, v, omega, wall_u, out, np.int64(0),
                                body_a.shape[0])


@njit(cache=True)
def kick_from(omega: np.ndarray, v: np.ndarray, L: np.ndarray, x: np.ndarray, q: np.ndarray,
              inv_I: np.ndarray, inv_mass: np.ndarray, force: np.ndarray, torque: np.ndarray,
              hk: float, body_a: np.ndarray, body_b: np.ndarray, point: np.ndarray,
              wall_d: np.ndarray, wall_u: np.ndarray, wall_w: np.ndarray, f_total: np.ndarray,
              f_damp_n: np.ndarray, f_damp_t: np.ndarray,
              f_el_t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """:func:`half_kick` of length hk (s) from angular velocities ``omega`` (N,3) rad/s
    (:func:`~nurbsdem.dynamics.rigid.omega_world` of the state before the kick) and the
    per-contact terms (K, N_TERMS) of the exact discrete work of its contact impulses
    (:func:`nurbsdem.dynamics.forces.kick_work_terms`, from the relative contact-point
    velocities before and after the kick, and the rolling torques' work from the angular
    velocities: :func:`~nurbsdem.dynamics.forces.add_rolling_work`; wall_d, wall_u, wall_w
    (W,3) the walls' displacements m, velocities m/s and angular velocities rad/s as
    body_b's wall indices see them).  Returns (terms, the angular velocities after)."""
    K = body_a.shape[0]
    w0 = np.empty((K, 3))
    w1 = np.empty((K, 3))
    _relative_point_velocities(body_a, body_b, point, x, wall_d, v, omega, wall_u, w0)
    half_kick(v, L, force, torque, inv_mass, hk)
    omega_after = omega_world(q, L, inv_I)
    _relative_point_velocities(body_a, body_b, point, x, wall_d, v, omega_after, wall_u, w1)
    terms = kick_work_terms(body_a, body_b, x.shape[0], w0, w1, wall_u, f_total, f_damp_n,
                            f_damp_t, f_el_t, hk)
    add_rolling_work(body_a, body_b, x.shape[0], omega, omega_after, f_el_t, hk, wall_w, terms)
    return terms, omega_after

"""Rigid bodies (particles) and prescribed-motion bodies (walls, a lid).

Particles
---------
State arrays over N bodies (SI units):

* ``x`` (N,3) m — centroid position in the world frame;
* ``q`` (N,4) — unit quaternion (w, x, y, z) of the *principal* frame: it maps principal-frame
  vectors to the world, ``Q = quat_to_matrix(q)`` (:mod:`nurbsdem.geometry.rotation`);
* ``v`` (N,3) m/s — centroid velocity;
* ``L`` (N,3) kg m^2/s — angular momentum about the centroid in the world frame (the integrator's
  rotational variable; the world angular velocity is ``omega = Q diag(1/I) Q^T L``).

Mass data: ``mass`` (N,) kg; ``J0`` (N,3,3) kg m^2 — inertia about the centroid in the body's
*file* frame (shape volume inertia × density, or given by the deck); it is diagonalised once,
``J0 = P diag(I) P^T`` with ``I`` ascending and ``P`` a proper rotation (columns = principal axes
in the file frame).  The body's file-frame rotation (the pose's ``R``, docs/conventions.md) is
then ``R = Q P^T``, and its pose position is ``x - R @ c`` with ``c`` the centroid in the file
frame.

Prescribed-motion bodies
------------------------
A wall moves by a translation ``d(t)`` (m) with velocity ``u(t)`` (m/s) given by a function of
time (:class:`PrescribedMotion`); a fixed wall has ``d = u = 0``.  A mesh or surface wall may
also turn about a centre that d carries (the system's ``wall_spin``, the pose of
:class:`~nurbsdem.contact.curved_walls.WallPose`); flat walls only translate.  The
solver computes the contact forces on them; the force that holds a wall on its path (its
*reaction*) is minus the sum of the contact forces the particles exert on it, and the work done by
it on the system is ``∫ reaction · u dt`` (see :mod:`nurbsdem.dynamics.energy`).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Mapping, Sequence

import numpy as np
from numba import njit, prange

from ..errors import InputError
from ..geometry.rotation import matrix_to_quat, quat_matrix, quats_to_matrices
from ..jit import ROW_CHUNK, THREADED_ROWS, n_chunks


def principal_frame(J0: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Diagonalise a symmetric positive-definite inertia tensor: ``J0 = P diag(I) P^T``.

    Returns ``I`` (3,) ascending (kg m^2) and ``P`` (3,3), a proper rotation (det +1) whose columns
    are the principal axes in the file frame.  Raises InputError when J0 is not symmetric
    positive definite.
    """
    J0 = np.asarray(J0, dtype=float)
    if J0.shape != (3, 3) or not np.all(np.isfinite(J0)):
        raise InputError(f"inertia tensor must be a finite 3x3 matrix, got shape {J0.shape}")
    scale = float(np.max(np.abs(J0)))
    if scale <= 0 or np.max(np.abs(J0 - J0.T)) > 1e-8 * scale:
        raise InputError("inertia tensor must be symmetric and non-zero")
    J0 = 0.5 * (J0 + J0.T)
    I, P = np.linalg.eigh(J0)
    if I[0] <= 0:
        raise InputError(f"inertia tensor is not positive definite (eigenvalues {I})")
    if I[0] + I[1] < I[2] * (1 - 1e-9):
        raise InputError(f"principal moments {I} violate the triangle inequality")
    if np.linalg.det(P) < 0:
        P[:, 2] = -P[:, 2]
    return I, P


# --------------------------------------------------------------------------- particles
def _vectors(particles: Sequence[Mapping], key: str) -> np.ndarray:
    """(N,3) float: each particle's ``key`` (a 3-vector; absent or None: 0)."""
    out = np.zeros((len(particles), 3))
    for i, p in enumerate(particles):
        val = p.get(key)
        if val is not None:
            out[i] = np.asarray(val, dtype=float).reshape(3)
    return out


def _principal_frames(J0: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(N,3) principal moments and (N,3,3) axes of the N inertia tensors J0 (N,3,3),
    :func:`principal_frame` once per distinct tensor (the particles of one shape and material
    share theirs)."""
    n = J0.shape[0]
    I, P = np.empty((n, 3)), np.empty((n, 3, 3))
    seen: dict[bytes, tuple[np.ndarray, np.ndarray]] = {}
    for i in range(n):
        key = J0[i].tobytes()
        if key not in seen:
            seen[key] = principal_frame(J0[i])
        I[i], P[i] = seen[key]
    return I, P


def _check_rotations(R: np.ndarray) -> None:
    """Raise InputError unless every R (N,3,3) is a proper rotation (to 1e-6)."""
    if not np.all(np.isfinite(R)):
        raise InputError("particle rotation R must be a proper rotation matrix")
    det_off = np.abs(np.linalg.det(R) - 1.0)
    orth_off = np.max(np.abs(R @ np.swapaxes(R, 1, 2) - np.eye(3)), axis=(1, 2))
    if np.any(det_off > 1e-6) or np.any(orth_off > 1e-6):
        raise InputError("particle rotation R must be a proper rotation matrix")


def particle_rows(particles: Sequence[Mapping]) -> dict[str, np.ndarray]:
    """The arrays of :class:`RigidBodies` for N particles given as mappings of
    :meth:`RigidBodies.add`'s arguments (checked: InputError on a non-positive mass, an
    inertia tensor that is not symmetric positive definite, a rotation that is not proper).

    Per particle: J0 symmetrised, ``J0 = P diag(I) Pᵀ`` (:func:`principal_frame`), the
    principal frame's rotation ``Q = R P`` as a unit quaternion q, and the angular momentum
    ``L = Q diag(I) Qᵀ ω`` (kg m²/s) with Q taken back from q (so that ω = Q diag(1/I) Qᵀ L
    holds for the integrator's Q).  Formed on stacks: O(N) NumPy work and one compiled call
    for the quaternions, not ~200 µs of Python per particle."""
    n = len(particles)
    mass = np.array([float(p["mass"]) for p in particles])
    _check_masses(mass)
    J0 = np.empty((n, 3, 3))
    for i, p in enumerate(particles):
        tensor = np.asarray(p["J0"], dtype=float)
        if tensor.shape != (3, 3):
            raise InputError(f"inertia tensor must be a finite 3x3 matrix, got shape {tensor.shape}")
        J0[i] = tensor
    I, P = _principal_frames(J0)
    R = np.empty((n, 3, 3))
    for i, p in enumerate(particles):
        rot = p.get("R")
        R[i] = np.eye(3) if rot is None else np.asarray(rot, dtype=float)
    return stacked_rows(
        mass, J0, I, P, R, _vectors(particles, "omega"), _vectors(particles, "centroid_file"),
        np.array([int(p.get("material", 0)) for p in particles], np.int64),
        np.array([float(p.get("radius", 0.0)) for p in particles]),
        np.array([np.asarray(p["x"], dtype=float).reshape(3) for p in particles]),
        _vectors(particles, "v"))


def kind_rows(kind: np.ndarray, mass: np.ndarray, J0: np.ndarray, centroid_file: np.ndarray,
              material: np.ndarray, radius: np.ndarray, R: np.ndarray, x: np.ndarray,
              v: np.ndarray, omega: np.ndarray) -> dict[str, np.ndarray]:
    """:func:`particle_rows` of N particles of K kinds (a kind: the particles that share
    their mass data), given as arrays: ``kind`` (N,) indices into the per-kind mass (K,) kg,
    J0 (K,3,3) kg m², centroid_file (K,3) m, material (K,) and bounding radius (K,) m; and
    per particle R (N,3,3), x (N,3) m, v (N,3) m/s, omega (N,3) rad/s.  One principal frame
    per kind; the rows equal :func:`particle_rows`'s bit for bit (the same stacked
    operations on the same numbers), without a mapping per particle."""
    kind = np.asarray(kind, np.int64)
    mass = np.asarray(mass, float)
    _check_masses(mass)
    J0 = np.asarray(J0, float).reshape(-1, 3, 3)
    frames = [principal_frame(J) for J in J0]
    I_k = np.array([f[0] for f in frames]).reshape(-1, 3)
    P_k = np.array([f[1] for f in frames]).reshape(-1, 3, 3)
    return stacked_rows(mass[kind], J0[kind], I_k[kind], P_k[kind], np.asarray(R, float),
                        np.asarray(omega, float), np.asarray(centroid_file, float)[kind],
                        np.asarray(material, np.int64)[kind], np.asarray(radius, float)[kind],
                        np.asarray(x, float), np.asarray(v, float))


def _check_masses(mass: np.ndarray) -> None:
    """InputError unless every mass (kg) is positive and finite."""
    bad = ~((mass > 0) & np.isfinite(mass))
    if bad.any():
        raise InputError(f"particle mass must be positive, got {mass[np.argmax(bad)]}")


def stacked_rows(mass, J0, I, P, R, omega, centroid_file, material, radius, x,
                 v) -> dict[str, np.ndarray]:
    """The rows of :func:`particle_rows` from per-particle stacks: mass (N,) kg, J0 (N,3,3)
    kg m² as given, its principal moments I (N,3) and axes P (N,3,3), R (N,3,3) (checked
    proper), omega (N,3) rad/s, and the rows kept as they are."""
    _check_rotations(R)
    Q = np.matmul(R, P)                                   # principal -> world
    q = matrix_to_quat(Q)
    Qm = quats_to_matrices(q)
    body = I * np.matmul(np.swapaxes(Qm, 1, 2), omega[:, :, None])[:, :, 0]
    L = np.matmul(Qm, body[:, :, None])[:, :, 0]
    return dict(mass=mass, J0=0.5 * (J0 + np.swapaxes(J0, 1, 2)), I=I, P=P,
                centroid_file=centroid_file, material=material, radius=radius, x=x,
                q=q, v=v, L=L)


class RigidBodies:
    """Arrays over the N particles (see the module docstring for the meaning of each array)."""

    def __init__(self) -> None:
        self.mass = np.zeros(0)
        self.J0 = np.zeros((0, 3, 3))
        self.I = np.zeros((0, 3))          # principal moments, ascending (kg m^2)
        self.P = np.zeros((0, 3, 3))       # principal axes in the file frame (columns)
        self.centroid_file = np.zeros((0, 3))
        self.material = np.zeros(0, dtype=np.int64)
        self.radius = np.zeros(0)          # bounding radius about the centroid (m); 0 = unknown
        self.x = np.zeros((0, 3))
        self.q = np.zeros((0, 4))
        self.v = np.zeros((0, 3))
        self.L = np.zeros((0, 3))

    @property
    def n(self) -> int:
        """Number of particles."""
        return int(self.mass.shape[0])

    def add(self, mass: float, J0: np.ndarray, x: np.ndarray, R: np.ndarray | None = None,
            v: np.ndarray | None = None, omega: np.ndarray | None = None, material: int = 0,
            centroid_file: np.ndarray | None = None, radius: float = 0.0) -> int:
        """Append one particle; returns its index.

        mass (kg); J0 (3,3) inertia about the centroid in the file frame (kg m^2);
        x (3,) centroid in the world (m); R (3,3) file->world rotation (default identity);
        v (3,) m/s; omega (3,) rad/s world angular velocity; material id; centroid_file (3,) m
        (the centroid in the file frame; default 0); radius (m) bounding radius about the centroid
        (used only by the time-step estimate).
        """
        self.add_many([dict(mass=mass, J0=J0, x=x, R=R, v=v, omega=omega, material=material,
                            centroid_file=centroid_file, radius=radius)])
        return self.n - 1

    def add_many(self, particles: Sequence[Mapping]) -> None:
        """Append particles given as mappings of :meth:`add`'s arguments (the arrays are
        grown once, so adding N particles costs O(N)).

        The rows are formed on stacks (:func:`particle_rows`): one principal frame per
        distinct inertia tensor, the rotations, quaternions and angular momenta of all
        particles at once, with the bits of forming each row alone (numpy's stacked
        ``matmul`` takes the 3×3 products item by item)."""
        if len(particles) == 0:
            return
        self.add_rows(particle_rows(particles))

    def add_rows(self, rows: Mapping[str, np.ndarray]) -> None:
        """Append the rows of :func:`particle_rows` or :func:`kind_rows`."""
        self.mass = np.append(self.mass, rows["mass"])
        self.J0 = np.concatenate([self.J0, rows["J0"]])
        self.I = np.concatenate([self.I, rows["I"]])
        self.P = np.concatenate([self.P, rows["P"]])
        self.centroid_file = np.concatenate([self.centroid_file, rows["centroid_file"]])
        self.material = np.append(self.material, rows["material"])
        self.radius = np.append(self.radius, rows["radius"])
        self.x = np.concatenate([self.x, rows["x"]])
        self.q = np.concatenate([self.q, rows["q"]])
        self.v = np.concatenate([self.v, rows["v"]])
        self.L = np.concatenate([self.L, rows["L"]])

    # ---------------------------------------------------------------- derived kinematics
    def principal_rotations(self) -> np.ndarray:
        """(N,3,3) principal->world rotations Q."""
        return quats_to_matrices(self.q)

    def rotations(self) -> np.ndarray:
        """(N,3,3) file->world rotations R = Q P^T (the pose rotation of docs/conventions.md)."""
        return body_poses(self.q, self.P, self.x, self.centroid_file)[0]

    def pose_positions(self, R: np.ndarray | None = None) -> np.ndarray:
        """(N,3) pose positions x - R c (m): where the file-frame origin is in the world."""
        if R is None:
            return body_poses(self.q, self.P, self.x, self.centroid_file)[1]
        return pose_positions_of(R, self.x, self.centroid_file)

    def omega(self) -> np.ndarray:
        """(N,3) world angular velocity (rad/s) from L: omega = Q diag(1/I) Q^T L."""
        return omega_world(self.q, self.L, 1.0 / self.I)

    def world_inertia(self) -> np.ndarray:
        """(N,3,3) inertia about the centroid in the world frame, Q diag(I) Q^T (kg m^2)."""
        Q = self.principal_rotations()
        return np.einsum("nij,nj,nkj->nik", Q, self.I, Q)


@njit(cache=True)
def pose_positions_of(R: np.ndarray, x: np.ndarray, centroid_file: np.ndarray) -> np.ndarray:
    """(N,3) pose positions x − R c (m) for rotations R (N,3,3) and file-frame centroids c."""
    n = x.shape[0]
    pos = np.empty((n, 3))
    for i in range(n):
        for j in range(3):
            pos[i, j] = x[i, j] - (R[i, j, 0] * centroid_file[i, 0] + R[i, j, 1] * centroid_file[i, 1]
                                   + R[i, j, 2] * centroid_file[i, 2])
    return pos


@njit(cache=True)
def _poses_range(q: np.ndarray, P: np.ndarray, x: np.ndarray, centroid_file: np.ndarray,
                 R: np.ndarray, pos: np.ndarray, lo: int, hi: int) -> None:
    """:func:`body_poses` of bodies lo .. hi-1 (the arithmetic of :func:`pose_positions_of`)."""
    for i in range(lo, hi):
        m = quat_matrix(q[i, 0], q[i, 1], q[i, 2], q[i, 3])
        for j in range(3):
            for k in range(3):
                R[i, j, k] = (m[3 * j] * P[i, k, 0] + m[3 * j + 1] * P[i, k, 1]
                              + m[3 * j + 2] * P[i, k, 2])
        for j in range(3):
            pos[i, j] = x[i, j] - (R[i, j, 0] * centroid_file[i, 0]
                                   + R[i, j, 1] * centroid_file[i, 1]
                                   + R[i, j, 2] * centroid_file[i, 2])


@njit(cache=True, parallel=True)
def _poses_threads(q, P, x, centroid_file, R, pos) -> None:
    n = q.shape[0]
    for t in prange(n_chunks(n)):
        _poses_range(q, P, x, centroid_file, R, pos, t * ROW_CHUNK, min(n, (t + 1) * ROW_CHUNK))


@njit(cache=True)
def body_poses(q: np.ndarray, P: np.ndarray, x: np.ndarray,
               centroid_file: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """File->world rotations R = Q Pᵀ (N,3,3) and pose positions x − R c (N,3) (m) from the
    quaternions q (N,4) (principal->world), principal axes P (N,3,3) and centroids c (N,3) in
    the file frame: the one kernel every path uses, so that all see the same bits (on threads
    from :data:`~nurbsdem.jit.THREADED_ROWS` bodies)."""
    n = q.shape[0]
    R = np.empty((n, 3, 3))
    pos = np.empty((n, 3))
    if n >= THREADED_ROWS:
        _poses_threads(q, P, x, centroid_file, R, pos)
    else:
        _poses_range(q, P, x, centroid_file, R, pos, np.int64(0), n)
    return R, pos


@njit(cache=True)
def _omega_range(q: np.ndarray, L: np.ndarray, inv_I: np.ndarray, out: np.ndarray, lo: int,
                 hi: int) -> None:
    """:func:`omega_world` of bodies lo .. hi-1."""
    for i in range(lo, hi):
        m = quat_matrix(q[i, 0], q[i, 1], q[i, 2], q[i, 3])
        p0 = m[0] * L[i, 0] + m[3] * L[i, 1] + m[6] * L[i, 2]
        p1 = m[1] * L[i, 0] + m[4] * L[i, 1] + m[7] * L[i, 2]
        p2 = m[2] * L[i, 0] + m[5] * L[i, 1] + m[8] * L[i, 2]
        w0, w1, w2 = p0 * inv_I[i, 0], p1 * inv_I[i, 1], p2 * inv_I[i, 2]
        for k in range(3):
            out[i, k] = m[3 * k] * w0 + m[3 * k + 1] * w1 + m[3 * k + 2] * w2


@njit(cache=True, parallel=True)
def _omega_threads(q, L, inv_I, out) -> None:
    n = q.shape[0]
    for t in prange(n_chunks(n)):
        _omega_range(q, L, inv_I, out, t * ROW_CHUNK, min(n, (t + 1) * ROW_CHUNK))


@njit(cache=True)
def omega_world(q: np.ndarray, L: np.ndarray, inv_I: np.ndarray) -> np.ndarray:
    """World angular velocity omega = Q diag(1/I) Q^T L for (N,4) q, (N,3) L, (N,3) 1/I (on
    threads from :data:`~nurbsdem.jit.THREADED_ROWS` bodies)."""
    n = q.shape[0]
    out = np.empty((n, 3))
    if n >= THREADED_ROWS:
        _omega_threads(q, L, inv_I, out)
    else:
        _omega_range(q, L, inv_I, out, np.int64(0), n)
    return out


# --------------------------------------------------------------------------- walls
MotionFunction = Callable[[float], tuple[np.ndarray, np.ndarray]]


@dataclass
class PrescribedMotion:
    """Translation of a wall as a function of time: ``f(t) -> (d (3,) m, u (3,) m/s)``.

    Use :meth:`fixed`, :meth:`linear` or :meth:`piecewise_linear`, or pass any callable (it must
    be deterministic and consistent: u = dd/dt).
    """

    function: MotionFunction | None = None
    #: the displacement (3,) m of a wall at rest (used when ``function`` is None; None: 0)
    rest: np.ndarray | None = None
    #: optional ``table(times (T,) s) -> (d (T,3) m, u (T,3) m/s)``: ``function`` at many
    #: times at once, with the same bits (:meth:`Walls.kinematics_at`)
    table: Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]] | None = None

    def __call__(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        if self.function is None:
            return (np.zeros(3) if self.rest is None else self.rest.copy()), np.zeros(3)
        d, u = self.function(float(t))
        return np.asarray(d, dtype=float).reshape(3), np.asarray(u, dtype=float).reshape(3)

    @property
    def at_rest(self) -> bool:
        """Whether the wall never moves."""
        return self.function is None

    @staticmethod
    def fixed(displacement=None) -> "PrescribedMotion":
        """A wall that does not move (held at ``displacement`` (3,) m, default 0)."""
        rest = None if displacement is None else np.array(displacement, float).reshape(3)
        return PrescribedMotion(None, rest)

    @staticmethod
    def linear(velocity: np.ndarray, t0: float = 0.0) -> "PrescribedMotion":
        """d = u (t - t0) for t > t0 (0 before), constant velocity u (m/s) after t0."""
        u = np.asarray(velocity, dtype=float).reshape(3)

        def f(t: float):
            if t <= t0:
                return np.zeros(3), np.zeros(3)
            return u * (t - t0), u.copy()
        return PrescribedMotion(f)

    @staticmethod
    def piecewise_linear(times, displacements) -> "PrescribedMotion":
        """Displacement interpolated linearly between (time, displacement (3,)) knots; held
        constant outside (velocity 0).  E.g. the paper's lid: [0, 1, 2] s, [0, -0.08 ez, 0]."""
        ts = np.asarray(times, dtype=float)
        ds = np.asarray(displacements, dtype=float).reshape(len(ts), 3)
        if np.any(np.diff(ts) <= 0):
            raise InputError("piecewise-linear motion: times must increase")

        def f(t: float):
            if t <= ts[0]:
                return ds[0].copy(), np.zeros(3)
            if t >= ts[-1]:
                return ds[-1].copy(), np.zeros(3)
            k = int(np.searchsorted(ts, t, side="right")) - 1
            s = (t - ts[k]) / (ts[k + 1] - ts[k])
            u = (ds[k + 1] - ds[k]) / (ts[k + 1] - ts[k])
            return ds[k] + s * (ds[k + 1] - ds[k]), u

        def table(times: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
            """f at each of the times, by the same operations on arrays."""
            t = np.asarray(times, dtype=float)
            inside = (t > ts[0]) & (t < ts[-1])
            k = np.clip(np.searchsorted(ts, t, side="right") - 1, 0, max(len(ts) - 2, 0))
            k1 = np.minimum(k + 1, len(ts) - 1)
            with np.errstate(divide="ignore", invalid="ignore"):    # one knot: never inside
                span = (ts[k1] - ts[k])[:, None]
                step = ds[k1] - ds[k]
                s = (t[:, None] - ts[k][:, None]) / span
                d = np.where(inside[:, None], ds[k] + s * step,
                             np.where((t <= ts[0])[:, None], ds[0], ds[-1]))
                u = np.where(inside[:, None], step / span, 0.0)
            return d, u
        return PrescribedMotion(f, table=table)


class Walls:
    """W prescribed-motion bodies, global indices N..N+W-1 in a ContactSet."""

    def __init__(self) -> None:
        self.motions: list[PrescribedMotion] = []
        self.material = np.zeros(0, dtype=np.int64)
        self.names: list[str] = []

    @property
    def n(self) -> int:
        return len(self.motions)

    def add(self, motion: PrescribedMotion | None = None, material: int = 0, name: str = "") -> int:
        """Append a wall (fixed when motion is None); returns its wall index (0-based)."""
        self.motions.append(motion if motion is not None else PrescribedMotion.fixed())
        self.material = np.append(self.material, np.int64(material))
        self.names.append(name or f"wall{self.n - 1}")
        return self.n - 1

    def kinematics_at(self, times: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(T,W,3) displacements (m) and velocities (m/s) at the times (T,) s (walls at rest are
        not called for every time)."""
        T = len(times)
        d = np.zeros((T, self.n, 3))
        u = np.zeros((T, self.n, 3))
        for k, m in enumerate(self.motions):
            if m.at_rest:
                d[:, k] = m(0.0)[0]
                continue
            if m.table is not None and T:
                d[:, k], u[:, k] = m.table(np.asarray(times, dtype=float))
                continue
            for r, t in enumerate(times):
                d[r, k], u[r, k] = m(float(t))
        return d, u

    def kinematics(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        """(W,3) displacements (m) and (W,3) velocities (m/s) at time t (s)."""
        d = np.zeros((self.n, 3))
        u = np.zeros((self.n, 3))
        for k, m in enumerate(self.motions):
            d[k], u[k] = m(t)
        return d, u

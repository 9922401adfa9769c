"""Rotations as unit quaternions: the one module for quaternion helpers.

Convention: ``q = (w, x, y, z)`` (scalar first); its matrix ``R`` maps body (file or
principal) frame vectors to the world, ``x_world = R @ x_body``.

NumPy functions (any leading shape, return new arrays):

* :func:`quat_to_matrix` — (..., 4) -> (..., 3, 3); normalises ``q`` first.
* :func:`matrix_to_quat` — (..., 3, 3) -> (..., 4), unit, ``w >= 0`` (Shepperd's method).
* :func:`quat_from_rotvec` — rotation vectors (..., 3) (rad) -> (..., 4).
* :func:`random_quaternions` — uniform random rotations (Haar measure).

Compiled functions (numba, for kernels; write into ``out``, no normalisation, ``q`` unit):

* :func:`quat_mul_into` — Hamilton product ``out = a ⊗ b``; :func:`quat_mul` the same of
  scalars.
* :func:`quat_to_matrix_into` — (4,) -> ``out`` (3, 3); :func:`quat_row_to_matrix_into` the
  same of a row of (N, 4) q; :func:`quat_matrix` the entries of scalars.
* :func:`quats_to_matrices` — (N, 4) -> new (N, 3, 3).

Kernels that loop over bodies or contacts read rows in place (``q[i, k]``) instead of taking
views (``q[i]``): numba counts the references of every view atomically, which costs several
times a quaternion product.
"""
from __future__ import annotations

import numpy as np
from numba import njit

__all__ = ["quat_to_matrix", "matrix_to_quat", "quat_from_rotvec", "random_quaternions",
           "quat_mul", "quat_mul_into", "quat_matrix", "quat_to_matrix_into",
           "quat_row_to_matrix_into", "quats_to_matrices"]


# ---------------------------------------------------------------------------- NumPy


def quat_from_rotvec(rv: np.ndarray) -> np.ndarray:
    """Unit quaternions (..., 4) (w, x, y, z) of rotation vectors (..., 3) (rad)."""
    rv = np.asarray(rv, float)
    angle = np.linalg.norm(rv, axis=-1, keepdims=True)
    half = 0.5 * angle
    # sin(a/2)/a, with its series near 0
    k = np.where(angle > 1e-8, np.sin(half) / np.where(angle > 1e-8, angle, 1.0),
                 0.5 - angle ** 2 / 48.0)
    return np.concatenate([np.cos(half), k * rv], axis=-1)


def quat_to_matrix(q: np.ndarray) -> np.ndarray:
    """Rotation matrices (..., 3, 3) of quaternions (..., 4) (w, x, y, z); normalised first."""
    q = np.asarray(q, float)
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    w, x, y, z = np.moveaxis(q, -1, 0)
    R = np.empty(q.shape[:-1] + (3, 3))
    R[..., 0, 0] = 1 - 2 * (y * y + z * z)
    R[..., 0, 1] = 2 * (x * y - w * z)
    R[..., 0, 2] = 2 * (x * z + w * y)
    R[..., 1, 0] = 2 * (x * y + w * z)
    R[..., 1, 1] = 1 - 2 * (x * x + z * z)
    R[..., 1, 2] = 2 * (y * z - w * x)
    R[..., 2, 0] = 2 * (x * z - w * y)
    R[..., 2, 1] = 2 * (y * z + w * x)
    R[..., 2, 2] = 1 - 2 * (x * x + y * y)
    return R


def matrix_to_quat(R: np.ndarray) -> np.ndarray:
    """Unit quaternions (..., 4) (w, x, y, z), w >= 0, of proper rotation matrices (..., 3, 3)
    (Shepperd's method: the branch of the largest diagonal term; compiled,
    :func:`matrices_to_quats_into`)."""
    R = np.asarray(R, float)
    flat = np.ascontiguousarray(R.reshape(-1, 3, 3))
    out = np.empty((flat.shape[0], 4))
    matrices_to_quats_into(flat, out)
    return out.reshape(R.shape[:-2] + (4,))


@njit(cache=True)
def matrices_to_quats_into(R: np.ndarray, out: np.ndarray) -> None:
    """out (n, 4) = the unit quaternions, w >= 0, of the rotations R (n, 3, 3)."""
    for i in range(R.shape[0]):
        m = R[i]
        tr = m[0, 0] + m[1, 1] + m[2, 2]
        if tr > 0:
            s = 2.0 * np.sqrt(tr + 1.0)
            w, x, y, z = 0.25 * s, (m[2, 1] - m[1, 2]) / s, (m[0, 2] - m[2, 0]) / s, (m[1, 0] - m[0, 1]) / s
        elif m[0, 0] > m[1, 1] and m[0, 0] > m[2, 2]:
            s = 2.0 * np.sqrt(1.0 + m[0, 0] - m[1, 1] - m[2, 2])
            w, x, y, z = (m[2, 1] - m[1, 2]) / s, 0.25 * s, (m[0, 1] + m[1, 0]) / s, (m[0, 2] + m[2, 0]) / s
        elif m[1, 1] > m[2, 2]:
            s = 2.0 * np.sqrt(1.0 + m[1, 1] - m[0, 0] - m[2, 2])
            w, x, y, z = (m[0, 2] - m[2, 0]) / s, (m[0, 1] + m[1, 0]) / s, 0.25 * s, (m[1, 2] + m[2, 1]) / s
        else:
            s = 2.0 * np.sqrt(1.0 + m[2, 2] - m[0, 0] - m[1, 1])
            w, x, y, z = (m[1, 0] - m[0, 1]) / s, (m[0, 2] + m[2, 0]) / s, (m[1, 2] + m[2, 1]) / s, 0.25 * s
        n = np.sqrt(w * w + x * x + y * y + z * z)
        sign = 1.0 if w / n >= 0 else -1.0
        out[i, 0] = sign * (w / n)
        out[i, 1] = sign * (x / n)
        out[i, 2] = sign * (y / n)
        out[i, 3] = sign * (z / n)


def random_quaternions(rng: np.random.Generator, n: int) -> np.ndarray:
    """n uniformly distributed random rotations (Haar measure) as unit quaternions (n, 4):
    normalised 4-D standard normal vectors, sign fixed so that w >= 0."""
    q = rng.standard_normal((n, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    q[q[:, 0] < 0] *= -1.0
    return q


# ---------------------------------------------------------------------------- compiled


@njit(cache=True)
def quat_mul(a0: float, a1: float, a2: float, a3: float, b0: float, b1: float, b2: float,
             b3: float) -> tuple[float, float, float, float]:
    """Hamilton product a ⊗ b of quaternions (w, x, y, z) given by their components."""
    return (a0 * b0 - a1 * b1 - a2 * b2 - a3 * b3,
            a0 * b1 + a1 * b0 + a2 * b3 - a3 * b2,
            a0 * b2 - a1 * b3 + a2 * b0 + a3 * b1,
            a0 * b3 + a1 * b2 - a2 * b1 + a3 * b0)


@njit(cache=True)
def quat_mul_into(a: np.ndarray, b: np.ndarray, out: np.ndarray) -> None:
    """Hamilton product ``out = a ⊗ b`` of quaternions (w, x, y, z); ``out`` may not alias."""
    out[0], out[1], out[2], out[3] = quat_mul(a[0], a[1], a[2], a[3], b[0], b[1], b[2], b[3])


@njit(cache=True)
def quat_matrix(w: float, x: float, y: float, z: float) -> tuple[float, ...]:
    """The rotation matrix of the unit quaternion (w, x, y, z): its 9 entries, row by row."""
    return (1.0 - 2.0 * (y * y + z * z), 2.0 * (x * y - w * z), 2.0 * (x * z + w * y),
            2.0 * (x * y + w * z), 1.0 - 2.0 * (x * x + z * z), 2.0 * (y * z - w * x),
            2.0 * (x * z - w * y), 2.0 * (y * z + w * x), 1.0 - 2.0 * (x * x + y * y))


@njit(cache=True)
def quat_to_matrix_into(q: np.ndarray, out: np.ndarray) -> None:
    """Rotation matrix (3,3) of the unit quaternion q = (w, x, y, z) into ``out``."""
    m = quat_matrix(q[0], q[1], q[2], q[3])
    for r in range(3):
        for c in range(3):
            out[r, c] = m[3 * r + c]


@njit(cache=True)
def quat_row_to_matrix_into(q: np.ndarray, i: int, out: np.ndarray) -> None:
    """:func:`quat_to_matrix_into` of the quaternion q[i] of (N,4) q, read in place: a view
    ``q[i]`` made in a loop over bodies costs numba two atomic reference counts, more than the
    matrix itself."""
    m = quat_matrix(q[i, 0], q[i, 1], q[i, 2], q[i, 3])
    for r in range(3):
        for c in range(3):
            out[r, c] = m[3 * r + c]


@njit(cache=True)
def quats_to_matrices(q: np.ndarray) -> np.ndarray:
    """(N,4) unit quaternions -> (N,3,3) rotation matrices (no normalisation)."""
    n = q.shape[0]
    out = np.empty((n, 3, 3))
    for i in range(n):
        m = quat_matrix(q[i, 0], q[i, 1], q[i, 2], q[i, 3])
        for r in range(3):
            for c in range(3):
                out[i, r, c] = m[3 * r + c]
    return out


@njit(cache=True)
def place_points_into(rel: np.ndarray, x: np.ndarray, R: np.ndarray, bodies: np.ndarray,
                      first: np.ndarray, out: np.ndarray) -> None:
    """Rigid placement of one point set: out[first[k] + p] = x[i] + R[i] rel[p] for each body
    i = bodies[k] (rel (P,3) m in the body frame, x (n,3) m, R (n,3,3); out (·,3) m)."""
    for k in range(bodies.shape[0]):
        i = bodies[k]
        f = first[k]
        for p in range(rel.shape[0]):
            r0, r1, r2 = rel[p, 0], rel[p, 1], rel[p, 2]
            for j in range(3):
                out[f + p, j] = x[i, j] + (R[i, j, 0] * r0 + R[i, j, 1] * r1 + R[i, j, 2] * r2)

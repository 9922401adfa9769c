"""The time-step control's exact estimate: speed and error together.

The estimate (:func:`nurbsdem.dynamics.stepcontrol.network_rates_scaled`: Lanczos on the
contact network's stiffness and damping operators, Eq. 2 of the module) is timed on dense
packs of N bodies on a jittered cubic lattice, each in contact with its lattice neighbours and
some diagonal ones (~6-9 contacts per body, random principal frames, masses and inertias,
walls on two sides), and its largest eigenvalue compared with the one of the same operator
assembled densely (6N columns of :func:`~nurbsdem.dynamics.stepcontrol.network_apply`) and
solved by LAPACK (``numpy.linalg.eigvalsh``); the Gershgorin bound (the gate that decides
without an estimate) printed beside it.  The operator itself is checked against an
independent assembly in tests/test_stepcontrol.py.

Printed per pack: bodies, contacts, time per estimate (best of the repeats), λmax relative
error, the Gershgorin bound over λmax.

Usage: .venv/bin/python benchmarks/bench_estimate.py [--quick]
"""
from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from nurbsdem.dynamics.stepcontrol import (network_apply, network_gershgorin,  # noqa: E402
                                           network_rates_scaled)
from nurbsdem.geometry.rotation import quats_to_matrices, random_quaternions  # noqa: E402


def pack(side: int, rng: np.random.Generator):
    """A network on a side³ lattice (spacing 1 cm): (a, b, point, normal, coeffs, x, Q, m, I)
    with two walls (indices N, N+1) under the bottom and beside one face."""
    g = np.stack(np.meshgrid(*[np.arange(side)] * 3, indexing="ij"), -1).reshape(-1, 3)
    N = g.shape[0]
    x = 0.01 * g + rng.normal(0.0, 2e-4, (N, 3))
    index = {tuple(c): i for i, c in enumerate(g)}
    a, b = [], []
    for i, c in enumerate(g):
        for d in ((1, 0, 0), (0, 1, 0), (0, 0, 1), (1, 1, 0), (1, 0, 1)):
            j = index.get((c[0] + d[0], c[1] + d[1], c[2] + d[2]))
            if j is not None and (sum(d) == 1 or rng.random() < 0.4):
                a.append(i)
                b.append(j)
        if c[2] == 0:
            a.append(i)
            b.append(N)
        if c[0] == 0:
            a.append(i)
            b.append(N + 1)
    a, b = np.array(a), np.array(b)
    point = np.empty((a.size, 3))
    normal = np.empty((a.size, 3))
    for c in range(a.size):
        if b[c] < N:
            xb = x[b[c]]
        else:               # a wall: its side 5 mm below (N) or beside (N+1) the body
            xb = x[a[c]].copy()
            xb[2 if b[c] == N else 0] -= 0.01
        d = xb - x[a[c]]
        normal[c] = d / np.linalg.norm(d)
        point[c] = 0.5 * (x[a[c]] + xb) + rng.normal(0.0, 5e-4, 3)
    coeffs = np.stack([rng.uniform(0.5e5, 2e5, a.size), rng.uniform(0, 1e2, a.size),
                       rng.uniform(0.5e4, 2e4, a.size), np.zeros(a.size)], axis=1)
    Q = quats_to_matrices(random_quaternions(rng, N))
    m = rng.uniform(0.04, 0.08, N)
    inertia = np.sort(rng.uniform(0.5e-6, 2e-6, (N, 3)), axis=1)
    return a, b, point, normal, coeffs, x, Q, m, inertia


def dense_lambda(a, b, point, normal, kn, kt, x, Q, m, inertia) -> float:
    """λmax of the operator assembled column by column (LAPACK)."""
    dim = 6 * x.shape[0]
    A = np.empty((dim, dim))
    e = np.zeros(dim)
    for j in range(dim):
        e[j] = 1.0
        A[:, j] = network_apply(e, a, b, point, normal, kn, kt, x, Q, np.sqrt(m),
                                np.sqrt(inertia))
        e[j] = 0.0
    return float(np.linalg.eigvalsh(0.5 * (A + A.T))[-1])


def main() -> None:
    quick = "--quick" in sys.argv
    rng = np.random.default_rng(7)
    print(f"{'bodies':>7} {'contacts':>9} {'ms per estimate':>16} {'lambda_max rel. error':>22} "
          f"{'Gershgorin / lambda_max':>24}")
    for side in ((3, 5) if quick else (3, 5, 7, 9)):
        a, b, point, normal, coeffs, x, Q, m, inertia = pack(side, rng)
        sq_m, sq_I = np.sqrt(m), np.sqrt(inertia)
        network_rates_scaled(a, b, point, normal, coeffs, x, Q, sq_m, sq_I)     # compile
        best = np.inf
        for _ in range(5):
            t0 = time.perf_counter()
            reps = 20
            for _ in range(reps):
                omega2, _, _ = network_rates_scaled(a, b, point, normal, coeffs, x, Q, sq_m, sq_I)
            best = min(best, (time.perf_counter() - t0) / reps)
        exact = dense_lambda(a, b, point, normal, coeffs[:, 0].copy(), coeffs[:, 2].copy(), x, Q,
                             m, inertia)
        g_k, _ = network_gershgorin(a, b, point, normal, coeffs, x, Q, 1 / m, 1 / inertia)
        print(f"{x.shape[0]:>7} {a.size:>9} {1e3 * best:>16.3f} "
              f"{abs(omega2 - exact) / exact:>22.2e} {g_k / exact:>24.2f}")


if __name__ == "__main__":
    main()

"""A surface wall that curves more tightly toward the particles than a NURBS particle: a
warning before the run.

A NURBS particle's contact with a ``Surface`` wall is unique where the wall's radius of
curvature toward the particles exceeds the particle's at the contact
(:mod:`nurbsdem.contact.surface_particle`, *Uniqueness*: J = (M_t + sd I) W − I negative
definite).  Where the wall is the tighter (a pocket narrower than the particle: two contact
points, or a ring), a particle that crosses it there stops the run with a one-line error.
:func:`warn_tight_surfaces` compares, before the run, each surface wall's tightest radius of
curvature toward the particles with the flattest radius of curvature of the NURBS particles
that can reach it, both sampled on every patch at :data:`SAMPLES` × :data:`SAMPLES`
parameter points (:func:`curvatures`: exact principal curvatures there), and warns when the
wall is the tighter: the particles may never reach that place (a warning, not an error),
but if they do, the run stops.  Exact spheres meet surface walls in closed form, which is unique
wherever the sphere's centre has one nearest wall point: they are not compared.
"""
from __future__ import annotations

import logging
import math
from typing import TYPE_CHECKING, Sequence

import numpy as np

if TYPE_CHECKING:  # pragma: no cover
    from .geometry.nurbs import Patch
    from .model import Model

#: Parameter samples per patch direction, evenly spaced, the patch's edges included (where
#: a wall is tightest: a cone's narrow end).
SAMPLES = 17
#: Normals shorter than this fraction of the largest on a patch: a degenerate point, skipped.
DEGENERATE = 1e-6


def curvatures(patch: "Patch", n: int = SAMPLES) -> tuple[np.ndarray, np.ndarray]:
    """Principal curvatures (m, 2) (1/m, ascending, positive where the patch curves toward
    its front S_u × S_v) and points (m, 3) (m) of ``patch`` on an ``n`` × ``n`` grid of its
    parameter rectangle, edges included, less its degenerate points (a pole: a normal
    shorter than :data:`DEGENERATE` of the grid's largest).  The eigenvalues of the shape
    operator I⁻¹ II in closed form (the vectorised form of
    :func:`nurbsdem.geometry.curvature.principal_curvatures`)."""
    u0, u1, v0, v1 = patch.domain
    s = np.linspace(0.0, 1.0, n)
    U, V = np.meshgrid(u0 + s * (u1 - u0), v0 + s * (v1 - v0), indexing="ij")
    d = np.asarray(patch.evaluate(U.ravel(), V.ravel(), order=2), float)   # (m, 6, 3)
    su, sv = d[:, 1], d[:, 2]
    front = np.cross(su, sv)
    size = np.linalg.norm(front, axis=1)
    keep = size > DEGENERATE * size.max()
    nrm = front[keep] / size[keep, None]
    d, su, sv = d[keep], su[keep], sv[keep]
    E, F, G = (su * su).sum(1), (su * sv).sum(1), (sv * sv).sum(1)
    L, M, N = (d[:, 3] * nrm).sum(1), (d[:, 4] * nrm).sum(1), (d[:, 5] * nrm).sum(1)
    det = E * G - F * F
    mean = (E * N - 2.0 * F * M + G * L) / (2.0 * det)          # H
    gauss = (L * N - M * M) / det                                # K
    root = np.sqrt(np.maximum(mean * mean - gauss, 0.0))
    return np.column_stack([mean - root, mean + root]), d[:, 0]


def tightest_concave_radius(patches: Sequence["Patch"]) -> tuple[float, np.ndarray | None]:
    """The smallest radius of curvature (m) with which ``patches`` curve toward the side
    their front S_u × S_v faces (a wall's particles' side), and a point (m) where it is;
    ``(inf, None)`` where they nowhere curve toward it (flat or convex walls)."""
    best, where = math.inf, None
    for patch in patches:
        k, x = curvatures(patch)
        i = int(np.argmax(k[:, 1]))
        if k[i, 1] > 0.0 and 1.0 / k[i, 1] < best:
            best, where = 1.0 / k[i, 1], x[i]
    return best, where


def flattest_radius(patches: Sequence["Patch"]) -> float:
    """The largest radius of curvature (m) of a convex particle's outward patches (their
    front S_u × S_v outward: the curvatures toward the inside are −k; ``inf`` where a part
    is flat)."""
    best = 0.0
    for patch in patches:
        k, _ = curvatures(patch)
        low = float(np.min(-k[:, 1]))                 # the smallest inward curvature
        best = max(best, math.inf if low <= 0.0 else 1.0 / low)
    return best


def tight_surface_problems(model: "Model") -> list[tuple[int, str]]:
    """(deck line, text) of each surface wall that curves more tightly toward the particles
    than the flattest NURBS particle the run holds."""
    from .wall_checks import used_shapes
    shapes = sorted(s for s in used_shapes(model) if model.shapes[s].kind != "sphere")
    walls = [w for w in model.curved_walls if w.kind == "surface"]
    if not shapes or not walls:
        return []
    from .io.deck_curved import surface_patches
    from .wall_checks import _where
    flat = {s: flattest_radius(model.shapes[s].shape.patches) for s in shapes}
    sid = max(flat, key=flat.get)
    out = []
    for spec in walls:
        tight, at = tightest_concave_radius(surface_patches(spec, _where(model, spec)))
        if tight < flat[sid]:
            point = ", ".join(f"{x:.4g}" for x in at)
            out.append((spec.line, f"Surface {spec.id} ({spec.name!r}) curves toward the "
                        f"particles with a radius of {tight:.3g} m (near ({point}) m), tighter "
                        f"than shape {sid}'s flattest part ({flat[sid]:.3g} m): where a particle "
                        f"touches it there its contact is not unique and the run stops (a "
                        f"wider wall or smaller particles avoid it)"))
    return out


def warn_tight_surfaces(model: "Model") -> None:
    """:func:`tight_surface_problems` on the ``nurbsdem`` logger, ``deck:line: message``."""
    log = logging.getLogger("nurbsdem")
    for line, text in tight_surface_problems(model):
        loc = f"{model.path}:{line}: " if model.path and line else ""
        log.warning(f"{loc}{text}")

"""Shared helpers of the benchmarks and of the verification report (``report.py``).

* :func:`machine_info` — CPU model, cores, nurbsdem / Python / NumPy / numba versions, date:
  the stamp every table and figure of the report carries.
* :func:`sweep_shapes` (with :func:`nurbsdem.contact.reference.random_pair_poses`) — the randomised sweep of
  ``tests/test_contact_sweep.py`` (same shapes, same placement: B translated along the computed
  normal until the signed distance hits a target).
* :func:`feature_points`, :func:`probe_poses`, :func:`wall_poses` — hard cases with an *exact*
  reference by construction: a sphere (the probe) whose centre lies at distance rB + sd from a
  chosen surface point p of a convex body along its outward normal n has signed distance
  exactly sd and contact normal n (the distance from an outside point to a convex body is
  attained at the point whose normal points at it; the ball's penetration is rB minus that
  distance). A body whose point p with outward normal −n_wall lies at height sd above a flat
  wall has signed distance sd to the wall (p is its support point along −n_wall).
  The surface point and normal come from the vectorised NURBS evaluator
  (:mod:`nurbsdem.geometry.nurbs`), which shares no code with the compiled LCP.

Lengths in metres.
"""
from __future__ import annotations

import datetime as _dt
import os
import platform
import sys
import time
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

BENCH_DIR = Path(__file__).resolve().parent
REPO = BENCH_DIR.parent


# --------------------------------------------------------------------------- machine
def cpu_model() -> str:
    """CPU model name (``/proc/cpuinfo``; else :func:`platform.processor`)."""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.lower().startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine() or "unknown CPU"


def machine_info() -> dict:
    """The stamp of a measurement: machine, versions, date."""
    import numba
    import numpy
    try:
        from nurbsdem import __version__ as ver
    except Exception:  # pragma: no cover
        ver = "unknown"
    try:
        cores = len(os.sched_getaffinity(0))
    except AttributeError:  # pragma: no cover - not Linux
        cores = os.cpu_count() or 1
    return dict(cpu=cpu_model(), cores=cores, os=f"{platform.system()} {platform.release()}",
                nurbsdem=ver, python=platform.python_version(), numpy=numpy.__version__,
                numba=numba.__version__, numba_threads=numba.get_num_threads(),
                date=_dt.datetime.now().strftime("%Y-%m-%d %H:%M"))


def stamp(info: dict) -> str:
    """One line naming machine, version and date."""
    return (f"{info['cpu']}, {info['cores']} cores; nurbsdem {info['nurbsdem']}; "
            f"{info['date']}")


# --------------------------------------------------------------------------- random sweep
SWEEP_R = 0.01
SWEEP_AXES = (0.03, 0.02, 0.012)
SWEEP_NAMES = ("sphere (6 patches)", "sphere (1 patch)", "ellipsoid", "particle A",
               "particle B", "particle C")


def sweep_shapes() -> list:
    """The shapes of ``tests/test_contact_sweep.py``: 6-patch sphere, single-patch sphere
    (poles and seam), ellipsoid, the paper's particles A, B, C."""
    from nurbsdem.geometry.generators import ellipsoid, single_patch_sphere_patches, sphere
    from nurbsdem.geometry.particles import paper_particle_shape
    from nurbsdem.geometry.shape import Shape
    return [sphere(SWEEP_R), Shape(single_patch_sphere_patches(SWEEP_R), check=False),
            ellipsoid(*SWEEP_AXES), paper_particle_shape("A"), paper_particle_shape("B"),
            paper_particle_shape("C")]


# --------------------------------------------------------------------------- features
FEATURES = ("seam", "pole", "corner", "edge", "face", "random")


def _point_normal(shape, ip: int, u: float, v: float) -> tuple[np.ndarray, np.ndarray]:
    """Surface point and unit outward normal (file frame) at (u, v) of patch ip, from the
    vectorised evaluator. At a collapsed edge (pole) the normal is taken a hair inside."""
    pt = shape.patches[ip]
    u0, u1, v0, v1 = pt.domain
    ev = pt.evaluate(np.array([u]), np.array([v]), 1)[0]
    x = ev[0]
    n = np.cross(ev[1], ev[2])
    if np.linalg.norm(n) < 1e-9 * shape.bounding_radius ** 2:
        # pole (collapsed edge): the normal's limit, by Richardson extrapolation of the
        # normals a small parameter step inside (error O(eps^2))
        def n_at(eps):
            uu = u + (eps if u < 0.5 * (u0 + u1) else -eps) * (u1 - u0)
            vv = v + (eps if v < 0.5 * (v0 + v1) else -eps) * (v1 - v0)
            e2 = pt.evaluate(np.array([uu]), np.array([vv]), 1)[0]
            m = np.cross(e2[1], e2[2])
            return m / np.linalg.norm(m)
        n1, n2 = n_at(1e-6), n_at(2e-6)
        if n1 @ n2 < 0:
            n2 = -n2
        n = 2 * n1 - n2
    n = n / np.linalg.norm(n)
    if n @ (x - np.asarray(shape.centroid)) < 0:
        n = -n
    return x, n


def feature_points(shape, kind: str, rng, k: int) -> list[tuple[np.ndarray, np.ndarray, int]]:
    """k surface points of a given kind (``FEATURES``) with their outward normals:
    list of (point, normal, patch) in the file frame; [] if the shape has no such feature.

    seam: an edge glued to its own patch (single-patch sphere); pole: a collapsed edge;
    corner: a node where 3+ patches meet; edge: an edge between two different patches;
    face: the centre of a patch's parameter rectangle (the flattest part of the paper's
    particles); random: a random parameter point of a random patch."""
    nb = shape.connectivity.neighbours
    P = len(shape.patches)
    out = []
    if kind == "corner":
        corners = shape.connectivity.corners
        if not corners:
            return []
        for _ in range(k):
            c = corners[rng.integers(len(corners))]
            ip, u, v = c.members[rng.integers(len(c.members))]
            x, n = _point_normal(shape, ip, u, v)
            out.append((x, n, ip))
        return out
    if kind in ("seam", "pole", "edge"):
        if kind == "seam":
            sel = [(i, e) for i in range(P) for e in range(4) if nb[i, e, 0] == i]
        elif kind == "pole":
            sel = [(i, e) for i in range(P) for e in range(4) if nb[i, e, 0] == -2]
        else:
            sel = [(i, e) for i in range(P) for e in range(4) if nb[i, e, 0] >= 0 and nb[i, e, 0] != i]
        if not sel:
            return []
        for _ in range(k):
            i, e = sel[rng.integers(len(sel))]
            u0, u1, v0, v1 = shape.patches[i].domain
            s = rng.uniform(0.05, 0.95)
            if e in (0, 1):
                u, v = (u0 if e == 0 else u1), v0 + s * (v1 - v0)
            else:
                u, v = u0 + s * (u1 - u0), (v0 if e == 2 else v1)
            x, n = _point_normal(shape, i, u, v)
            out.append((x, n, i))
        return out
    for _ in range(k):
        i = int(rng.integers(P))
        u0, u1, v0, v1 = shape.patches[i].domain
        if kind == "face":
            u, v = 0.5 * (u0 + u1), 0.5 * (v0 + v1)
        else:
            u, v = rng.uniform(u0, u1), rng.uniform(v0, v1)
        x, n = _point_normal(shape, i, u, v)
        out.append((x, n, i))
    return out


def _rotation_taking(a: np.ndarray, b: np.ndarray, rng) -> np.ndarray:
    """A rotation R with R a = b, with a random twist about b."""
    a = a / np.linalg.norm(a)
    b = b / np.linalg.norm(b)
    v = np.cross(a, b)
    s, c = np.linalg.norm(v), float(a @ b)
    if s < 1e-12:
        if c > 0:
            R0 = np.eye(3)
        else:
            t = np.eye(3)[int(np.argmin(np.abs(a)))]
            t = t - (t @ a) * a
            R0 = Rotation.from_rotvec(np.pi * t / np.linalg.norm(t)).as_matrix()
    else:
        R0 = Rotation.from_rotvec(v / s * np.arctan2(s, c)).as_matrix()
    tw = Rotation.from_rotvec(b * rng.uniform(0, 2 * np.pi)).as_matrix()
    return tw @ R0


def probe_poses(shape, point_normals, probe_radius: float, sds, rng):
    """Poses of body A (``shape``) and a probe sphere B (centred at its pose position) such
    that the exact signed distance is sds[k] with A's contact point point_normals[k].

    Returns (pa, Ra, pb, Rb, n_ref (K, 3) world normal from A to B, pa_ref (K, 3) world
    contact point on A)."""
    K = len(point_normals)
    Ra = Rotation.random(K, random_state=rng).as_matrix()
    Rb = Rotation.random(K, random_state=rng).as_matrix()
    pa = rng.normal(size=(K, 3)) * 0.01
    n_ref = np.einsum("kij,kj->ki", Ra, np.array([pn[1] for pn in point_normals]))
    x_ref = pa + np.einsum("kij,kj->ki", Ra, np.array([pn[0] for pn in point_normals]))
    pb = x_ref + (probe_radius + np.asarray(sds))[:, None] * n_ref
    return pa, Ra, pb, Rb, n_ref, x_ref


def wall_poses(shape, point_normals, sds, rng):
    """Poses of a body above the wall z = 0 (normal +z) with its point p (outward normal n)
    the support point along −z, at height sds[k]: exact signed distance sds[k].
    Returns (pos, R)."""
    K = len(point_normals)
    R = np.empty((K, 3, 3))
    pos = np.empty((K, 3))
    for k, (x, n, _) in enumerate(point_normals):
        R[k] = _rotation_taking(n, np.array([0.0, 0.0, -1.0]), rng)
        xw = R[k] @ x
        pos[k] = [rng.uniform(-0.01, 0.01), rng.uniform(-0.01, 0.01), sds[k] - xw[2]]
    return pos, R


def ensure_repo_on_path() -> None:
    """Make ``benchmarks`` importable as plain modules (``import bench_facets``)."""
    if str(BENCH_DIR) not in sys.path:
        sys.path.insert(0, str(BENCH_DIR))


def best_per_item(fn, items, repeat: int = 3) -> tuple[float, list]:
    """The best time (s) per item of fn over items, and the last results."""
    best, res = np.inf, []
    for _ in range(repeat):
        t = time.perf_counter()
        res = [fn(*it) for it in items]
        best = min(best, (time.perf_counter() - t) / len(items))
    return best, res


def write_paper_shapes(folder: Path, radii) -> list[tuple[str, float]]:
    """The paper's particles A, B and C (:func:`nurbsdem.shapes.paper_particle`) scaled to
    the volumes of the spheres of ``radii`` (m, one each), as shape files ``paper_1.yaml`` …
    in ``folder`` (their control points scaled about the origin of the file's frame): each
    file's name and the scaled particle's bounding radius (m)."""
    import math
    import yaml
    from nurbsdem.io.shapefile import load_yaml
    from nurbsdem.shapes import paper_particle_shape
    out = []
    for k, (kind, r) in enumerate(zip("ABC", radii)):
        entry = paper_particle_shape(kind)
        scale = (4.0 / 3.0 * math.pi * r ** 3 / float(entry.volume)) ** (1.0 / 3.0)
        data = load_yaml(REPO / "inputs" / "shapes" / f"{kind}.yaml")
        for patch in data["patches"]:
            patch["control_points"] = (np.asarray(patch["control_points"], float)
                                       * scale).tolist()
        data["name"] = f"{kind} scaled to d {2 * r * 1e3:.1f} mm"
        (folder / f"paper_{k + 1}.yaml").write_text(yaml.safe_dump(data))
        out.append((f"paper_{k + 1}.yaml", float(entry.bounding_radius) * scale))
    return out

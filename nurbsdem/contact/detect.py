"""Public API of the local contact search (paper Sec. 3.2): one body pair or a batch.

* :func:`detect` — one pair of shapes in given poses -> :class:`ContactResult`
  (thin wrapper over the compiled kernel :func:`nurbsdem.contact.lcp.solve_pair`).
* :class:`ContactTable` + :func:`detect_batch` — many pairs of bodies whose shapes are packed
  in one table; the loop over pairs runs in compiled code, in parallel (numba ``prange``
  over thread chunks, one workspace per thread). Warm-start state is the previous result
  row of the same pair.
* :func:`closest_points` — stage 1 alone (:func:`nurbsdem.contact.stage1.stage1`, the
  distance of two surfaces, Eq. 4–5) -> :class:`Stage1Result`.

Poses map the file frame to the world: ``x_world = position + R @ x_file``. Lengths in
metres. The algorithm is described in :mod:`nurbsdem.contact.lcp` and
:mod:`nurbsdem.contact.support`.
"""
from __future__ import annotations

import weakref
from dataclasses import dataclass, field
from typing import Iterable, Sequence

import numpy as np
import numba
from numba import njit, prange

from ..geometry.analytic import exact_sphere
from ..geometry.connectivity import POLE
from ..geometry.kernel import make_workspace, power_form
from ..jit import fetch_add, fill_lazy_kernels, kernel
from . import lcp
from .lcp import (F_IT1, F_N, F_PA, F_PAR, F_PB, F_SD, I_ACTIVE, I_BROAD, I_DEG, I_FAIL,
                  I_IT, I_PA, I_PB, I_STAGE, I_VALID, NF, NI, full_rows, make_work,
                  solve_pair, solve_pair_ptr)
from .stage1 import (CLASS_NAMES as S1_CLASS_NAMES, DELTA0 as S1_DELTA0, MAX_IT as S1_MAX_IT,
                     N_OUT as S1_N_OUT, O_F1, O_GL, O_LMIN, O_LREF, S1_PAW, S1_PBW, S1_ROW,
                     make_w4, stage1 as stage1_kernel)
from .support import make_seeds


# --------------------------------------------------------------------------- result
@dataclass
class ContactResult:
    """Outcome of the LCP of one body pair (see ``docs/conventions.md``).

    Attributes
    ----------
    active: the bodies penetrate (signed_distance < 0).
    signed_distance: m; < 0: minus the maximum penetration depth, > 0: separation. For pairs
        rejected by the bounding spheres (paper Eq. 3) it is the sphere gap, a lower bound.
    normal: unit vector, outward normal of A at its contact point, pointing towards B.
    point_a, point_b: contact points on A and B (world, m).
    gap: point_a − point_b (paper Eq. 4); normal · gap = −signed_distance.
    patch_a, patch_b: patch indices (−1 when no LCP was solved).
    params: (ζA, θA, ζB, θB) surface parameters of the contact points.
    degenerated: degeneration level (number of fixed parameters, paper Eq. 10–11), 0 = none.
    iterations: Newton iterations of both stages (stage-1 trust-region iterations on f1,
        paper Eq. 5, plus iterations on the direction sphere, Eq. 6–9).
    failed: the LCP did not converge (the best iterate, or the previous solution, is returned).
    evaluations: patch evaluations spent (cost measure).
    broad_rejected: the bounding spheres do not overlap; nothing else was computed.
    stage: which stage produced the result: 1 = the minimum of f1 (separated; certified by one
        support mapping per body), 2 = the minimisation over directions (penetration, or a
        stage-1 fallback), 0 = none (broad phase).
    stage1_iterations: the stage-1 part of ``iterations``.
    row_f, row_i: the raw result rows; pass the result back as ``previous`` for a warm start.
    """

    active: bool
    signed_distance: float
    normal: np.ndarray
    point_a: np.ndarray
    point_b: np.ndarray
    gap: np.ndarray
    patch_a: int
    patch_b: int
    params: np.ndarray
    degenerated: int
    iterations: int
    failed: bool
    evaluations: int = 0
    broad_rejected: bool = False
    stage: int = 0
    stage1_iterations: int = 0
    row_f: np.ndarray = field(default=None, repr=False)  # type: ignore[assignment]
    row_i: np.ndarray = field(default=None, repr=False)  # type: ignore[assignment]

    @property
    def depth(self) -> float:
        """Penetration depth (m), 0 when separated."""
        return max(0.0, -self.signed_distance)

    @classmethod
    def from_rows(cls, rf: np.ndarray, ri: np.ndarray) -> "ContactResult":
        """Build from the kernel's result rows (copies)."""
        rf = np.array(rf, dtype=float)
        ri = np.array(ri, dtype=np.int64)
        pa = rf[F_PA:F_PA + 3].copy()
        pb = rf[F_PB:F_PB + 3].copy()
        return cls(active=bool(ri[I_ACTIVE]), signed_distance=float(rf[F_SD]),
                   normal=rf[F_N:F_N + 3].copy(), point_a=pa, point_b=pb, gap=pa - pb,
                   patch_a=int(ri[I_PA]), patch_b=int(ri[I_PB]), params=rf[F_PAR:F_PAR + 4].copy(),
                   degenerated=int(ri[I_DEG]), iterations=int(ri[I_IT]), failed=bool(ri[I_FAIL]),
                   evaluations=int(ri[lcp.I_NEV]), broad_rejected=bool(ri[I_BROAD]),
                   stage=int(ri[I_STAGE]), stage1_iterations=int(rf[F_IT1]), row_f=rf, row_i=ri)


# --------------------------------------------------------------------------- packed shapes
def _nonconvexity(shape) -> float:
    """Non-convexity height of a shape (m) for the LCP: 0 without a measurement or when it is
    convex up to round-off (its height, ~1e-18 m for a sphere, is no non-convexity)."""
    cv = getattr(shape, "convexity", None)
    if cv is None or getattr(cv, "convex", False):
        return 0.0
    return float(getattr(cv, "height", 0.0) or 0.0)


class ContactTable:
    """Shapes packed for the compiled LCP: one pool of patches with global indices.

    Attributes
    ----------
    tab: (deg, ncp, koff, coff, knots, cpw, dom, nbr, pw, poff) — the pool arrays
        (:class:`~nurbsdem.geometry.kernel.PatchPool`), the connectivity with global
        patch indices and the patches' power form (:func:`~nurbsdem.geometry.kernel.power_form`,
        what the LCP evaluates; ``poff`` -1 for a patch with a pole, evaluated by A2.3).
    info: int64 (S, 4) per shape (first patch, patch count, first seed, seed count).
    centroid: (S, 3) file-frame centroids (m).  radius: (S,) bounding radii (m, Eq. 3).
    seeds: (x (N, 3), patch (N,), uv (N, 2)) surface samples for cold starts.
    """

    def __init__(self, shapes: Sequence) -> None:
        shapes = list(shapes)
        pools = [s.pool for s in shapes]
        deg, ncp, koff, coff, dom, nbr, pw, poff = [], [], [], [], [], [], [], []
        knots, cpw = [], []
        sx, sp, suv = [], [], []
        info = np.zeros((len(shapes), 4), np.int64)
        kofs = cofs = pofs = sofs = rofs = 0
        for k, (s, pl) in enumerate(zip(shapes, pools)):
            P = pl.deg.shape[0]
            deg.append(pl.deg)
            ncp.append(pl.ncp)
            koff.append(pl.koff + kofs)
            coff.append(pl.coff + cofs)
            knots.append(pl.knots)
            cpw.append(pl.cpw)
            dom.append(pl.dom)
            nb = np.array(s.connectivity.neighbours, dtype=np.int64, copy=True)
            nb[:, :, 0] = np.where(nb[:, :, 0] >= 0, nb[:, :, 0] + pofs, nb[:, :, 0])
            nbr.append(nb)
            rows, first = power_form(pl)
            pw.append(rows)
            # patches with a pole keep A2.3 (poff -1): there the Taylor form's round-off
            # turned the LCP's normal by 1e-10 rad instead of 1e-12 (test_contact_spheres)
            poff.append(np.where((nb[:, :, 0] == POLE).any(axis=1), -1, first + rofs))
            rofs += rows.shape[0]
            x, p, uv = make_seeds(s)
            sx.append(x)
            sp.append(p + pofs)
            suv.append(uv)
            info[k] = pofs, P, sofs, len(p)
            kofs += pl.knots.shape[0]
            cofs += pl.cpw.shape[0]
            pofs += P
            sofs += len(p)
        cat = lambda a, dt: np.ascontiguousarray(np.concatenate(a).astype(dt))  # noqa: E731
        self.tab = (cat(deg, np.int64), cat(ncp, np.int64), cat(koff, np.int64),
                    cat(coff, np.int64), cat(knots, float), cat(cpw, float), cat(dom, float),
                    cat(nbr, np.int64), cat(pw, float), cat(poff, np.int64))
        self.info = info
        self.centroid = np.ascontiguousarray([np.asarray(s.centroid, float) for s in shapes]).reshape(-1, 3)
        self.radius = np.array([float(s.bounding_radius) for s in shapes])
        self.seeds = (cat(sx, float), cat(sp, np.int64), cat(suv, float))
        #: (S,) non-convexity height of each shape (m; exactly 0 for shapes convex up to
        #: round-off): how far its surface rises above its own tangent planes
        #: (:mod:`nurbsdem.geometry.connectivity`); the LCP kernel gets h_A + h_B of each pair
        #: (saddle stalls, :func:`lcp.solve_pair`; 0 turns them off)
        self.nonconvexity = np.array([_nonconvexity(s) for s in shapes])
        self.shapes = shapes
        #: per shape: (centre (3,) m, radius m) of an exact sphere, None for other shapes
        #: (:func:`~nurbsdem.geometry.analytic.exact_sphere`)
        self.spheres = [exact_sphere(s) for s in shapes]
        if any(sp is None for sp in self.spheres):
            fill_lazy_kernels()              # the LCP kernels: a scene of spheres needs none
            if any(sp is not None for sp in self.spheres):
                fill_lazy_kernels("sphere_nurbs")    # the sphere–particle pairs' solver

    def __len__(self) -> int:
        return len(self.shapes)


_TABLES: "weakref.WeakKeyDictionary" = weakref.WeakKeyDictionary()


def table_of(shape) -> ContactTable:
    """The (cached) single-shape :class:`ContactTable` of a shape."""
    t = _TABLES.get(shape)
    if t is None:
        t = ContactTable([shape])
        _TABLES[shape] = t
    return t


_WORK: dict = {}


def _work():
    """Workspaces of the single-pair path (one set per process)."""
    if not _WORK:
        _WORK["ws"] = make_workspace()
        _WORK["w"] = make_work()
    return _WORK["ws"], _WORK["w"]


def _pose(pose) -> tuple[np.ndarray, np.ndarray]:
    pos, R = pose
    return (np.ascontiguousarray(np.asarray(pos, dtype=float).reshape(3)),
            np.ascontiguousarray(np.asarray(R, dtype=float).reshape(3, 3)))


def _mask(P: int, patches: Iterable[int] | None) -> np.ndarray:
    if patches is None:
        return np.zeros(0, np.bool_)
    m = np.zeros(P, np.bool_)
    for p in patches:
        if 0 <= int(p) < P:
            m[int(p)] = True
    return m if m.any() else np.zeros(0, np.bool_)


def _prev_rows(previous: ContactResult | None) -> tuple[np.ndarray, np.ndarray]:
    if previous is None or previous.row_f is None or previous.failed or previous.broad_rejected:
        return np.zeros(NF), np.zeros(NI, np.int64)
    return full_rows(previous.row_f), np.ascontiguousarray(previous.row_i, dtype=np.int64)


def detect(shape_a, pose_a, shape_b, pose_b, previous: ContactResult | None = None,
           candidates: Sequence[tuple[int, int]] | None = None) -> ContactResult:
    """Maximum penetration (or distance) of two convex NURBS bodies (paper Sec. 3.2).

    Parameters
    ----------
    shape_a, shape_b: :class:`~nurbsdem.geometry.shape.Shape` (closed, convex).
    pose_a, pose_b: (position (3,) m, rotation matrix (3, 3)); x_world = position + R x_file.
    previous: the result of the same pair at the last step (warm start), or None.
    candidates: optional (patch_a, patch_b) pairs from the patch-box test (paper 3.1); their
        patches are the only ones used to pick the starting points of a cold start.

    Returns
    -------
    :class:`ContactResult`. Never raises on a numerical failure: ``failed`` is set instead.
    """
    ta, tb = table_of(shape_a), table_of(shape_b)
    pa, Ra = _pose(pose_a)
    pb, Rb = _pose(pose_b)
    ma = mb = np.zeros(0, np.bool_)
    if candidates is not None:
        cand = list(candidates)
        ma = _mask(ta.info[0, 1], [c[0] for c in cand])
        mb = _mask(tb.info[0, 1], [c[1] for c in cand])
    pf, pi = _prev_rows(previous)
    rf = np.zeros(NF)
    ri = np.zeros(NI, np.int64)
    ws, (wf, wi, wfs, w4) = _work()
    try:
        solve_pair(ta.tab, ta.info[0], ta.centroid[0], float(ta.radius[0]),
                   tb.tab, tb.info[0], tb.centroid[0], float(tb.radius[0]),
                   pa, Ra, pb, Rb, pf, pi, ma, mb, ta.seeds, tb.seeds, ws, wf, wi, wfs, w4, rf, ri,
                   float(ta.nonconvexity[0] + tb.nonconvexity[0]))
    except Exception:  # pragma: no cover - never abort the simulation
        if previous is not None and previous.row_f is not None:
            rf, ri = np.array(previous.row_f), np.array(previous.row_i)
        ri[I_FAIL] = 1
        ri[I_VALID] = 0
    if ri[I_FAIL] == 1 and within_nonconvexity(rf.reshape(1, -1), ri.reshape(1, -1), 0,
                                               float(ta.nonconvexity[0] + tb.nonconvexity[0])):
        ri[I_FAIL] = 0
    return ContactResult.from_rows(rf, ri)


# --------------------------------------------------------------------------- batch
#: Below this many pairs the batch runs on the calling thread: launching the parallel
#: region costs more than it saves for a handful of LCPs.
PARALLEL_MIN_PAIRS = 32
#: pairs a thread of a parallel batch takes at a time (:func:`next_chunk`): enough LCPs that
#: the shared counter's atomic add is negligible, few enough that the threads end together
CHUNK_PAIRS = 8


@kernel
def _solve_range(tab, info, cen, rad, seeds, nc, shape, pos, rot, body_a, body_b, rows,
                 mask_a, mask_b, res_f, res_i, k0, k1, ws, wf, wi, wfs, w4, prev_f, prev_i):
    """The loop of :func:`_solve_chunk` over its workspaces: pair j = rows[k] for k in
    k0..k1-1, bodies body_a[j], body_b[j] (shape[·], pos[·], rot[·]), candidate patches
    mask_a[j], mask_b[j]; its rows res_f[j], res_i[j] hold the previous solution (warm
    start) and receive the new one in place, the previous one copied into prev_f (NF,),
    prev_i (NI,) first: a pair that fails keeps it (:func:`kept_on_failure`).  Without
    reference counting (:func:`nurbsdem.jit.kernel`): the rows
    it hands to ``solve_pair`` are views of arrays that every thread shares, whose reference
    counts were updated atomically by all threads (8 % of the LCP time of a compaction)."""
    for k in range(k0, k1):
        j = rows[k]
        ia = body_a[j]
        ib = body_b[j]
        a = shape[ia]
        b = shape[ib]
        for c in range(prev_f.shape[0]):
            prev_f[c] = res_f[j, c]
        for c in range(prev_i.shape[0]):
            prev_i[c] = res_i[j, c]
        solve_pair_ptr(tab, info[a], cen[a], rad[a], tab, info[b], cen[b], rad[b],
                       pos[ia], rot[ia], pos[ib], rot[ib], prev_f, prev_i, mask_a[j],
                       mask_b[j], seeds, seeds, ws, wf, wi, wfs, w4, res_f[j], res_i[j],
                       nc[a] + nc[b])
        kept_on_failure(res_f, res_i, j, prev_f, prev_i, nc[a] + nc[b])


@kernel(inline="always")
def kept_on_failure(res_f, res_i, j: int, prev_f, prev_i, tol: float) -> None:
    """After the solve of row j: a failed one (``I_FAIL``) whose valid result lies within the
    shapes' non-convexity heights tol = h_A + h_B (m) of touching is accepted
    (:func:`within_nonconvexity`); any other failed row gets its previous solution
    prev_f (NF,), prev_i (NI,) back, flagged failed.  That is the solution a scene falls back
    on, moved rigidly (:mod:`nurbsdem.contact.scene`), so it needs no copy of the rows
    before a solve, and a cold retry that fails too leaves it in place."""
    if res_i[j, I_FAIL] == 0:
        return
    if within_nonconvexity(res_f, res_i, j, tol):
        res_i[j, I_FAIL] = 0
        return
    for c in range(prev_f.shape[0]):
        res_f[j, c] = prev_f[c]
    for c in range(prev_i.shape[0]):
        res_i[j, c] = prev_i[c]
    res_i[j, I_FAIL] = 1


@njit(cache=True, inline="always")
def _solve_chunk(tab, info, cen, rad, seeds, nc, shape, pos, rot, body_a, body_b, rows,
                 mask_a, mask_b, res_f, res_i, k0, k1):
    """LCPs of the pairs rows[k0:k1] (:func:`_solve_range`) with one set of workspaces (one
    thread). ``mask_a/b`` (L, P) candidate patches per pair for cold starts (P = 0: no
    candidates given); ``nc`` (S,) non-convexity heights of the shapes (m)."""
    ws = make_workspace()
    wf, wi, wfs, w4 = make_work()
    _solve_range(tab, info, cen, rad, seeds, nc, shape, pos, rot, body_a, body_b, rows, mask_a,
                 mask_b, res_f, res_i, k0, k1, ws, wf, wi, wfs, w4, np.empty(NF),
                 np.empty(NI, np.int64))


@njit(cache=True)
def next_chunk(taken: np.ndarray, n: int) -> tuple[int, int]:
    """The next CHUNK_PAIRS items (k0, k1) of n that the shared counter ``taken`` (1,) hands
    out (k0 >= n: none left).  Threads that take their work this way share it out as they
    go: one slowed down (by the output writer or another process on the same core) leaves
    its share to the others instead of holding the whole batch up at the end of the
    parallel loop."""
    k0 = fetch_add(taken, CHUNK_PAIRS)
    return k0, min(n, k0 + CHUNK_PAIRS)


@njit(cache=True, inline="always")
def _solve_chunks(tab, info, cen, rad, seeds, nc, shape, pos, rot, body_a, body_b, rows,
                  mask_a, mask_b, res_f, res_i, taken):
    """:func:`_solve_chunk` of the chunks :func:`next_chunk` hands this thread, with one set
    of workspaces (every pair's result is independent of the workspaces' history)."""
    ws = make_workspace()
    wf, wi, wfs, w4 = make_work()
    prev_f, prev_i = np.empty(NF), np.empty(NI, np.int64)
    k0, k1 = next_chunk(taken, rows.shape[0])
    while k0 < k1:
        _solve_range(tab, info, cen, rad, seeds, nc, shape, pos, rot, body_a, body_b, rows,
                     mask_a, mask_b, res_f, res_i, k0, k1, ws, wf, wi, wfs, w4, prev_f, prev_i)
        k0, k1 = next_chunk(taken, rows.shape[0])


@njit(cache=True, parallel=True)
def _batch_kernel(tab, info, cen, rad, seeds, nc, shape, pos, rot, body_a, body_b, rows,
                  mask_a, mask_b, res_f, res_i, nt):
    """The LCPs of the pairs ``rows`` (:func:`_solve_range`, in place) on nt threads, which
    take chunks of pairs as they go."""
    K = rows.shape[0]
    if nt > K:
        nt = max(K, 1)
    taken = np.zeros(1, np.int64)
    for t in prange(nt):
        _solve_chunks(tab, info, cen, rad, seeds, nc, shape, pos, rot, body_a, body_b, rows,
                      mask_a, mask_b, res_f, res_i, taken)


@njit(cache=True, inline="always")
def solve_rows(tab, info, cen, rad, seeds, nc, shape, pos, rot, body_a, body_b, rows, mask_a,
               mask_b, res_f, res_i, nt) -> None:
    """The LCPs of the pairs ``rows`` in place (:func:`_solve_range`: a failed pair keeps its
    previous row, flagged, unless accepted within the shapes' non-convexity): on nt threads
    from :data:`PARALLEL_MIN_PAIRS` pairs, else on this one."""
    K = rows.shape[0]
    if K >= PARALLEL_MIN_PAIRS:
        _batch_kernel(tab, info, cen, rad, seeds, nc, shape, pos, rot, body_a, body_b, rows,
                      mask_a, mask_b, res_f, res_i, nt)
    elif K:
        _solve_chunk(tab, info, cen, rad, seeds, nc, shape, pos, rot, body_a, body_b, rows,
                     mask_a, mask_b, res_f, res_i, np.int64(0), K)


def detect_batch(table: ContactTable, shape_a: np.ndarray, pos_a: np.ndarray, rot_a: np.ndarray,
                 shape_b: np.ndarray, pos_b: np.ndarray, rot_b: np.ndarray,
                 prev_f: np.ndarray | None = None, prev_i: np.ndarray | None = None,
                 out: tuple[np.ndarray, np.ndarray] | None = None,
                 mask_a: np.ndarray | None = None, mask_b: np.ndarray | None = None
                 ) -> tuple[np.ndarray, np.ndarray]:
    """LCPs of K body pairs in compiled code (parallel over pairs).

    Parameters
    ----------
    table: the packed shapes.
    shape_a, shape_b: int64 (K,) shape index (into ``table``) of each pair's bodies.
    pos_a, pos_b: (K, 3) positions (m); rot_a, rot_b: (K, 3, 3) rotation matrices.
    prev_f, prev_i: previous result rows of the same pairs (K, NF), (K, NI) for warm starts
        (a row that is no warm start, :func:`~nurbsdem.contact.lcp.warm_start`, starts
        cold); None: all cold.
    out: optional preallocated (res_f, res_i).
    mask_a, mask_b: optional bool (K, P) candidate patches of each pair from the patch-box
        test (paper 3.1): a cold start begins on them ("the LCP is directed to them").

    Returns
    -------
    (res_f (K, NF), res_i (K, NI)); columns: :mod:`nurbsdem.contact.lcp` constants
    (``F_SD`` signed distance, ``F_N`` normal, ``F_PA``/``F_PB`` points, ``F_PAR`` params,
    ``I_ACTIVE``, ``I_PA``/``I_PB`` patches, ``I_DEG``, ``I_IT``, ``I_FAIL``, ``I_VALID``).
    A pair whose LCP failed has its previous row (zeros after a cold start) with ``I_FAIL``
    set (:func:`kept_on_failure`).
    """
    K = len(shape_a)
    sa = np.ascontiguousarray(shape_a, dtype=np.int64)
    sb = np.ascontiguousarray(shape_b, dtype=np.int64)
    pos_a = np.ascontiguousarray(pos_a, dtype=float).reshape(K, 3)
    pos_b = np.ascontiguousarray(pos_b, dtype=float).reshape(K, 3)
    rot_a = np.ascontiguousarray(rot_a, dtype=float).reshape(K, 3, 3)
    rot_b = np.ascontiguousarray(rot_b, dtype=float).reshape(K, 3, 3)
    if prev_f is None or prev_i is None:
        prev_f = np.zeros((K, NF))
        prev_i = np.zeros((K, NI), np.int64)
    if out is None:
        out = (np.zeros((K, NF)), np.zeros((K, NI), np.int64))
    out[0][:] = full_rows(prev_f)           # solved in place from the previous rows
    out[1][:] = prev_i
    no_mask = np.zeros((K, 0), np.bool_)
    mask_a = no_mask if mask_a is None else np.ascontiguousarray(mask_a, dtype=np.bool_)
    mask_b = no_mask if mask_b is None else np.ascontiguousarray(mask_b, dtype=np.bool_)
    k = np.arange(K, dtype=np.int64)        # pair k: bodies k (A) and K + k (B), row k
    solve_rows(table.tab, table.info, table.centroid, table.radius, table.seeds,
               table.nonconvexity, np.concatenate((sa, sb)), np.concatenate((pos_a, pos_b)),
               np.concatenate((rot_a, rot_b)), k, K + k, k, mask_a, mask_b, out[0], out[1],
               numba.get_num_threads())
    return out


@kernel(inline="always")
def within_nonconvexity(res_f, res_i, j: int, tol: float) -> bool:
    """Whether the failed row j of res_f (·, NF), res_i (·, NI) is accepted: a direction
    search that stalls on a *nearly* convex shape (a saddle at a CAD patch corner makes the
    support function non-smooth there) whose valid result lies within the two shapes'
    non-convexity heights of touching, |signed distance| <= tol = h_A + h_B (m).  The contact
    is then grazing to within the geometric tolerance the shapes were accepted with (a force
    of at most εn (h_A + h_B)); stalls at deeper contacts are handled in the kernel
    (:func:`lcp.solve_pair`, "saddle stall").  Convex shapes have h = 0: nothing is accepted
    for them."""
    return tol > 0.0 and res_i[j, I_VALID] == 1 and abs(res_f[j, F_SD]) <= tol


# --------------------------------------------------------------------------- stage 1 alone
@dataclass
class Stage1Result:
    """Outcome of :func:`closest_points` (stage 1 alone).

    classification: "separated" (strict positive minimum: distance and closest points),
        "intersecting" (f1 ≈ 0), "saddle", "degenerate" or "not converged".
    f1: ½|g|² (m²); distance: |g| (m); gap: g = point_a − point_b (m, paper Eq. 4).
    point_a, point_b: world points (m); patch_a, patch_b: local patch indices;
    params: (ζA, θA, ζB, θB); iterations: trust-region iterations; evaluations: patch
    evaluations; lambda_max, lambda_min: extreme eigenvalues of the reduced scaled Hessian.
    """

    classification: str
    code: int
    f1: float
    distance: float
    gap: np.ndarray
    point_a: np.ndarray
    point_b: np.ndarray
    patch_a: int
    patch_b: int
    params: np.ndarray
    iterations: int
    evaluations: int
    lambda_max: float
    lambda_min: float


def closest_points(shape_a, pose_a, shape_b, pose_b, start=None, max_it: int = S1_MAX_IT,
                   delta0: float = S1_DELTA0) -> Stage1Result:
    """Run stage 1 (minimise f1, paper Eq. 5) for two shapes in world poses.

    ``start``: (patch_a, ζA, θA, patch_b, ζB, θB) local patch indices and parameters; None:
    the nearest pair of surface samples (seed from A's sample farthest along the centroid
    direction, then alternating nearest samples)."""
    ta, tb = table_of(shape_a), table_of(shape_b)
    pa, Ra = _pose(pose_a)
    pb, Rb = _pose(pose_b)
    ist = np.zeros((2, 4), np.int64)
    fst = np.zeros((2, 3))
    if start is None:
        ca = pa + Ra @ ta.centroid[0]
        cb = pb + Rb @ tb.centroid[0]
        d = cb - ca
        d = d / np.linalg.norm(d) if np.linalg.norm(d) > 0 else np.array([0.0, 0.0, 1.0])
        xa = ta.seeds[0] @ Ra.T + pa
        xb = tb.seeds[0] @ Rb.T + pb
        ka = int(np.argmax(xa @ d))
        for _ in range(2):
            kb = int(np.argmin(np.sum((xb - xa[ka]) ** 2, axis=1)))
            ka = int(np.argmin(np.sum((xa - xb[kb]) ** 2, axis=1)))
        ist[0, 0] = ta.seeds[1][ka]
        fst[0, :2] = ta.seeds[2][ka]
        ist[1, 0] = tb.seeds[1][kb]
        fst[1, :2] = tb.seeds[2][kb]
    else:
        ist[0, 0], fst[0, 0], fst[0, 1] = int(start[0]), start[1], start[2]
        ist[1, 0], fst[1, 0], fst[1, 1] = int(start[3]), start[4], start[5]
    wf = np.zeros((lcp.WORK_ROWS, 3))
    w4 = make_w4()
    out = np.zeros(S1_N_OUT)
    scale = float(ta.radius[0] + tb.radius[0])
    cls, it, nev = stage1_kernel(ta.tab, pa, Ra, tb.tab, pb, Rb, scale, ist, fst, max_it, delta0,
                          make_workspace(), wf, w4, out)
    pA = wf[S1_ROW + S1_PAW].copy()
    pB = wf[S1_ROW + S1_PBW].copy()
    return Stage1Result(classification=S1_CLASS_NAMES[int(cls)], code=int(cls), f1=float(out[O_F1]),
                        distance=float(out[O_GL]), gap=pA - pB, point_a=pA, point_b=pB,
                        patch_a=int(ist[0, 0]), patch_b=int(ist[1, 0]),
                        params=np.array([fst[0, 0], fst[0, 1], fst[1, 0], fst[1, 1]]),
                        iterations=int(it), evaluations=int(nev), lambda_max=float(out[O_LREF]),
                        lambda_min=float(out[O_LMIN]))

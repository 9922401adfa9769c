"""Contact detection for a whole scene: the hierarchy of paper Section 3 for N bodies and W
flat walls, as a *contact provider* of :class:`nurbsdem.dynamics.DemSystem`.

Per force evaluation (:meth:`SceneContacts.__call__`):

1. level 0/1 — bounding spheres (paper Eq. 3) on a cell grid
   (:func:`~nurbsdem.contact.broadphase.sphere_pairs`), bodies against wall rectangles
   (:func:`~nurbsdem.contact.broadphase.sphere_wall_pairs`);
2. level 2 — oriented patch boxes by the separating-axis test
   (:func:`~nurbsdem.contact.boxes.candidate_patch_pairs_batch`); a body pair with no
   overlapping patch boxes cannot touch and is dropped;
3. the LCP of every remaining pair in compiled code, in parallel
   (:func:`~nurbsdem.contact.detect_batch`, :func:`~nurbsdem.contact.detect_wall_batch`),
   warm-started from the same pair's previous solution.

The counters follow the paper's Fig. 5: ``monitored`` = LCPs solved (pairs left by the global
search), ``active`` = penetrating pairs, ``degenerated`` = active pairs solved with the
degeneration technique (Eq. 10–15), ``failed`` = LCPs that did not converge.

A failed LCP never acts for more than one evaluation (never abort, never linger): a pair whose
LCP fails right after a converged solution reuses that solution once, **moved rigidly with the
two bodies** (the surface points follow their bodies, the normal turns with body A, the depth is
measured again between the moved points); if the next LCP of that pair fails too, or there was
no converged solution to move, the pair is left out of the force evaluation (and its tangential
history ends).  Each case is logged once per pair, naming the pair.

Besides the active contacts, each ContactSet reports the separated pairs it solved
(``near_*``: their closest points, normal and gap) so that the time-step control can see the
contacts about to close.

Units: metres, seconds. Global body indices: particles 0..N-1, walls N..N+W-1 (DEVNOTES).
"""
from __future__ import annotations

import logging
import time
from dataclasses import dataclass, field
from typing import Sequence

import numpy as np

from .boxes import candidate_patch_pairs_batch, candidate_patches_wall_batch, pack_boxes
from .broadphase import sphere_pairs, sphere_wall_pairs, wall_geometry
from .detect import ContactTable, detect_batch
from .lcp import F_N, F_PA, F_PB, F_SD, I_ACTIVE, I_DEG, I_FAIL, I_VALID, NF, NI
from .wall import detect_wall_batch, wall_frame

log = logging.getLogger("nurbsdem")


@dataclass
class ContactSet:
    """Active contacts of one evaluation (DEVNOTES): arrays over K contacts, plus counters."""

    body_a: np.ndarray
    body_b: np.ndarray
    point_a: np.ndarray
    point_b: np.ndarray
    normal: np.ndarray
    depth: np.ndarray
    key: np.ndarray
    degenerated: np.ndarray
    monitored: int = 0
    active: int = 0
    degenerated_count: int = 0
    failed: int = 0
    #: failed LCPs answered by the previous solution moved rigidly (one evaluation at most)
    reused: int = 0
    #: failed LCPs whose pair was left out of the force evaluation
    dropped: int = 0
    #: keys of the pairs left out (their elastic energy is booked as dissipated by the system)
    dropped_keys: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    near_a: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    near_b: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    near_point: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    near_normal: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    near_gap: np.ndarray = field(default_factory=lambda: np.zeros(0))

    @classmethod
    def empty(cls) -> "ContactSet":
        z = np.zeros(0, np.int64)
        e3 = np.zeros((0, 3))
        return cls(z, z.copy(), e3, e3.copy(), e3.copy(), np.zeros(0), z.copy(), z.copy())


@dataclass
class SceneTimers:
    """Wall-clock seconds spent in each part of the contact search."""

    global_search: float = 0.0
    lcp: float = 0.0
    calls: int = 0
    lcps: int = 0

    def as_dict(self) -> dict[str, float]:
        return {"global_search": self.global_search, "lcp": self.lcp,
                "calls": float(self.calls), "lcps": float(self.lcps)}


class SceneContacts:
    """Contact provider for N particles of given shapes and W flat walls.

    Parameters
    ----------
    shapes: the distinct shapes (index = shape index used in ``body_shape``).
    body_shape: int (N,) shape index of each particle.
    walls: W flat wall patches (degree 1, 2×2 control points) in the world at zero
        displacement; their displacements come with the kinematics.
    margin: skin added to the bounding volumes (m).
    """

    def __init__(self, shapes: Sequence, body_shape: np.ndarray, walls: Sequence = (),
                 margin: float = 0.0) -> None:
        self.shapes = list(shapes)
        self.table = ContactTable(self.shapes)
        self.boxes, self.box_offsets = pack_boxes(self.shapes)
        self.body_shape = np.ascontiguousarray(body_shape, dtype=np.int64)
        self.radius = np.asarray(self.table.radius, float)[self.body_shape]
        self.margin = float(margin)
        self.n = int(self.body_shape.shape[0])
        self.walls = list(walls)
        W = len(self.walls)
        self.wall_center = np.zeros((W, 3))
        self.wall_axes = np.zeros((W, 3, 3))
        self.wall_half = np.zeros((W, 2))
        self.wall_origin = np.zeros((W, 3))
        self.wall_a = np.zeros((W, 3))
        self.wall_b = np.zeros((W, 3))
        self.wall_dom = np.zeros((W, 4))
        for k, w in enumerate(self.walls):
            self.wall_center[k], self.wall_axes[k], self.wall_half[k] = wall_geometry(w)
            self.wall_origin[k], self.wall_a[k], self.wall_b[k], self.wall_dom[k] = wall_frame(w)
        self.depth_wall = 2.0 * float(self.radius.max()) if self.n else 0.0
        #: warm-start rows of the last solution of each pair: key -> (row_f, row_i)
        self.cache: dict[int, tuple[np.ndarray, np.ndarray]] = {}
        #: keys whose cached row is a failed LCP's moved previous solution (not a converged one)
        self.reused: frozenset[int] = frozenset()
        #: poses of the previous call: pose positions (N,3), rotations (N,3,3), walls (W,3)
        self.prev_pose: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None
        self.warned: set[tuple[int, str]] = set()
        self.timers = SceneTimers()
        self.totals = {"monitored": 0, "active": 0, "degenerated": 0, "failed": 0}
        self.last: ContactSet = ContactSet.empty()

    # ------------------------------------------------------------------ warm starts
    def _previous(self, keys: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        K = keys.shape[0]
        pf = np.zeros((K, NF))
        pi = np.zeros((K, NI), np.int64)
        for r, k in enumerate(keys.tolist()):
            hit = self.cache.get(k)
            if hit is not None:
                pf[r], pi[r] = hit
        return pf, pi

    def _store(self, keys: np.ndarray, rf: np.ndarray, ri: np.ndarray) -> dict:
        return {k: (rf[r].copy(), ri[r].copy()) for r, k in enumerate(keys.tolist())}

    def state(self) -> dict[str, np.ndarray]:
        """The warm-start cache, the reused keys and the previous poses as arrays (for
        checkpoints: restarts stay bit-for-bit)."""
        keys = np.array(sorted(self.cache), dtype=np.int64)
        rf = np.array([self.cache[k][0] for k in keys.tolist()]).reshape(-1, NF)
        ri = np.array([self.cache[k][1] for k in keys.tolist()], dtype=np.int64).reshape(-1, NI)
        st = {"keys": keys, "rows_f": rf, "rows_i": ri,
              "reused": np.array(sorted(self.reused), dtype=np.int64)}
        if self.prev_pose is not None:
            st.update(prev_pos=self.prev_pose[0], prev_R=self.prev_pose[1],
                      prev_wall=self.prev_pose[2])
        return st

    def set_state(self, st: dict) -> None:
        """Restore :meth:`state`."""
        self.cache = {int(k): (np.array(f), np.array(i)) for k, f, i in
                      zip(st["keys"], st["rows_f"], st["rows_i"])}
        self.reused = frozenset(int(k) for k in st.get("reused", ()))
        self.prev_pose = ((np.array(st["prev_pos"]), np.array(st["prev_R"]),
                           np.array(st["prev_wall"])) if "prev_pos" in st else None)

    def snapshot(self):
        """What a rolled-back time step must restore (cheap: the call replaces, never mutates,
        these objects)."""
        return self.cache, self.reused, self.prev_pose, self.last

    def restore(self, snap) -> None:
        """Undo the calls made since :meth:`snapshot`."""
        self.cache, self.reused, self.prev_pose, self.last = snap

    def _directed(self, pairs: np.ndarray, cand: np.ndarray):
        """Keep the body pairs with overlapping patch boxes, and their candidate patches as
        (K, P) masks that direct the LCP's cold starts (paper 3.1)."""
        keep = np.unique(cand[:, 0])
        row = np.searchsorted(keep, cand[:, 0])
        P = int(np.diff(self.box_offsets).max())
        mask_a = np.zeros((keep.shape[0], P), np.bool_)
        mask_b = np.zeros((keep.shape[0], P), np.bool_)
        mask_a[row, cand[:, 1]] = True
        mask_b[row, cand[:, 2]] = True
        return pairs[keep], mask_a, mask_b

    # ------------------------------------------------------------------ the provider
    def __call__(self, kin) -> ContactSet:
        """Active contacts for the kinematics of a :class:`~nurbsdem.dynamics.DemSystem`."""
        t0 = time.perf_counter()
        N = self.n
        nb = N + len(self.walls)
        pos, R = np.ascontiguousarray(kin.position), np.ascontiguousarray(kin.R)
        # particle pairs: bounding spheres (Eq. 3), then patch boxes (Sec. 3.1)
        pairs = sphere_pairs(kin.x, self.radius, self.margin) if N > 1 else np.zeros((0, 2), np.int64)
        mask_a = mask_b = None
        if pairs.shape[0]:
            cand = candidate_patch_pairs_batch(self.boxes, self.box_offsets, self.body_shape,
                                               pos, R, pairs, self.margin)
            pairs, mask_a, mask_b = self._directed(pairs, cand)
        # particle-wall pairs
        wpairs = np.zeros((0, 2), np.int64)
        if self.walls and N:
            wc = self.wall_center + kin.wall_displacement
            wpairs = sphere_wall_pairs(kin.x, self.radius, wc, self.wall_axes, self.wall_half,
                                       self.margin)
            if wpairs.shape[0]:
                cand = candidate_patches_wall_batch(self.boxes, self.box_offsets, self.body_shape,
                                                    pos, R, wc, self.wall_axes, self.wall_half,
                                                    wpairs, self.margin, self.depth_wall)
                wpairs = wpairs[np.unique(cand[:, 0])] if cand.shape[0] else wpairs[:0]
        t1 = time.perf_counter()
        # LCPs
        a = pairs[:, 0]
        b = pairs[:, 1]
        keys_p = a * nb + b
        pf, pi = self._previous(keys_p)
        def solve_pairs(k, prev_f, prev_i):
            return detect_batch(self.table, self.body_shape[a[k]], pos[a[k]], R[a[k]],
                                self.body_shape[b[k]], pos[b[k]], R[b[k]], prev_f, prev_i,
                                mask_a=None if mask_a is None else mask_a[k],
                                mask_b=None if mask_b is None else mask_b[k])
        rf, ri = _retry_failed_cold(solve_pairs, pf, pi)
        wb_idx = wpairs[:, 1]
        wa = wpairs[:, 0]
        keys_w = wa * nb + (N + wb_idx)
        wf, wi = self._previous(keys_w)
        d = kin.wall_displacement[wb_idx] if len(self.walls) else np.zeros((0, 3))

        def solve_walls(k, prev_f, prev_i):
            w = wb_idx[k]
            return detect_wall_batch(self.table, self.body_shape[wa[k]], pos[wa[k]], R[wa[k]],
                                     self.wall_origin[w] + d[k], self.wall_a[w], self.wall_b[w],
                                     self.wall_dom[w], prev_f, prev_i)
        rwf, rwi = _retry_failed_cold(solve_walls, wf, wi)
        t2 = time.perf_counter()
        cs = self._assemble(np.concatenate([a, wa]), np.concatenate([b, N + wb_idx]),
                            np.concatenate([keys_p, keys_w]), np.concatenate([rf, rwf]),
                            np.concatenate([ri, rwi]), pf_all=np.concatenate([pf, wf]),
                            pi_all=np.concatenate([pi, wi]),
                            pose=(pos, R, np.array(kin.wall_displacement, float)))
        self.timers.global_search += t1 - t0
        self.timers.lcp += t2 - t1
        self.timers.calls += 1
        self.timers.lcps += int(keys_p.shape[0] + keys_w.shape[0])
        self.last = cs
        return cs

    def _assemble(self, a, b, keys, rf, ri, pf_all, pi_all, pose) -> ContactSet:
        """The ContactSet of this call from the LCP rows; failed rows are answered by the
        previous solution moved rigidly (once) or left out (module docstring)."""
        failed = ri[:, I_FAIL].astype(bool)
        reused, dropped = [], []
        for r in np.nonzero(failed)[0].tolist():
            k = int(keys[r])
            if pi_all[r, I_VALID] and k not in self.reused and self.prev_pose is not None:
                rf[r], ri[r] = self._moved(pf_all[r], pi_all[r], int(a[r]), int(b[r]), pose)
                reused.append(k)
                self._warn(k, int(a[r]), int(b[r]), "its last converged solution, moved rigidly "
                           "with the two bodies, is used for this evaluation only")
            else:
                ri[r, I_ACTIVE] = 0
                ri[r, I_VALID] = 0
                dropped.append(k)
                self._warn(k, int(a[r]), int(b[r]), "no fresh converged solution to fall back on: "
                           "the pair is left out of the force evaluation")
        self.reused = frozenset(reused)
        self.prev_pose = pose
        self.cache = self._store(keys, rf, ri)
        valid = ri[:, I_VALID] == 1
        act = (ri[:, I_ACTIVE] == 1) & valid
        sel = np.nonzero(act)[0]
        near = np.nonzero(valid & ~act & (rf[:, F_SD] > 0))[0]
        deg = ri[sel, I_DEG]
        n_failed = int(failed.sum())
        cs = ContactSet(body_a=a[sel].astype(np.int64), body_b=b[sel].astype(np.int64),
                        point_a=rf[sel, F_PA:F_PA + 3].copy(), point_b=rf[sel, F_PB:F_PB + 3].copy(),
                        normal=rf[sel, F_N:F_N + 3].copy(), depth=-rf[sel, F_SD],
                        key=keys[sel].astype(np.int64), degenerated=deg.astype(np.int64),
                        monitored=int(keys.shape[0]), active=int(sel.shape[0]),
                        degenerated_count=int(np.count_nonzero(deg)), failed=n_failed,
                        reused=len(reused), dropped=len(dropped),
                        dropped_keys=np.array(dropped, np.int64),
                        near_a=a[near].astype(np.int64), near_b=b[near].astype(np.int64),
                        near_point=0.5 * (rf[near, F_PA:F_PA + 3] + rf[near, F_PB:F_PB + 3]),
                        near_normal=rf[near, F_N:F_N + 3].copy(), near_gap=rf[near, F_SD].copy())
        return cs

    def _moved(self, row_f: np.ndarray, row_i: np.ndarray, a: int, b: int, pose):
        """A previous LCP row moved rigidly from the previous call's poses to ``pose``: the
        surface points follow their bodies (walls translate), the normal turns with body A and
        the signed distance is measured again between the moved points, (p_B − p_A)·n."""
        N = self.n
        pos, R, wall = pose
        ppos, pR, pwall = self.prev_pose

        def move(i: int, p: np.ndarray) -> np.ndarray:
            if i < N:
                return R[i] @ (pR[i].T @ (p - ppos[i])) + pos[i]
            return p + (wall[i - N] - pwall[i - N])
        f, iv = row_f.copy(), row_i.copy()
        f[F_PA:F_PA + 3] = move(a, row_f[F_PA:F_PA + 3])
        f[F_PB:F_PB + 3] = move(b, row_f[F_PB:F_PB + 3])
        n = row_f[F_N:F_N + 3]
        f[F_N:F_N + 3] = R[a] @ (pR[a].T @ n) if a < N else n
        f[F_SD] = float((f[F_PB:F_PB + 3] - f[F_PA:F_PA + 3]) @ f[F_N:F_N + 3])
        iv[I_ACTIVE] = 1 if f[F_SD] < 0 else 0
        iv[I_VALID] = 1
        iv[I_FAIL] = 1
        return f, iv

    def _warn(self, key: int, a: int, b: int, what: str) -> None:
        """Log a failed LCP once per pair and kind of answer."""
        if (key, what) in self.warned:
            return
        self.warned.add((key, what))
        pair = (f"particles {a} and {b}" if b < self.n else f"particle {a} and wall {b - self.n}")
        log.warning("the contact problem (LCP) of %s did not converge: %s (counted as failed in "
                    "monitors/contacts.csv)", pair, what)


def _retry_failed_cold(solve, prev_f: np.ndarray, prev_i: np.ndarray):
    """Solve all pairs (warm where a previous solution exists); pairs whose warm-started LCP
    did not converge are solved once more from a cold start before they count as failed.

    ``solve(index, prev_f, prev_i)`` solves the pairs ``index`` (an index array) and returns
    their result rows. A warm start can stall where a cold one does not (e.g. in the flat
    valley of a near-touching pair), so the cold retry removes most spurious failures at the
    cost of one more LCP for the rare failed pair.
    """
    K = prev_f.shape[0]
    rf, ri = solve(np.arange(K), prev_f, prev_i)
    again = np.nonzero((ri[:, I_FAIL] == 1) & (prev_i[:, I_VALID] == 1))[0]
    if again.size:
        cf, ci = solve(again, np.zeros((again.size, NF)), np.zeros((again.size, NI), np.int64))
        ok = ci[:, I_FAIL] == 0
        rf[again[ok]], ri[again[ok]] = cf[ok], ci[ok]
    return rf, ri

"""The Python driver of the internal step: the compiled parts of :mod:`nurbsdem.dynamics.step`
around one contact-provider call per internal step.

The compiled deck steps (:mod:`nurbsdem.dynamics.deck_steps`) drive the same parts for a scene
on one rank; this driver runs the rest: several MPI ranks (the ghosts' loads exchanged after
the contact part, each rank booking the kicks' work of its counted contacts, the guards
reduced over the ranks), walls that turn (each contact with a turning wall kicks against
that wall's point velocity), contact providers other than a scene, and each deck step the
compiled loop hands back.  Units: SI; global body indices particles 0..N-1, walls N..N+W-1.
"""
from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np

from ..errors import InputError
from ..jit import seconds_per_cycle
from .contact_state import ContactState
from .energy import EnergySample
from .images import ImageBodies
from .integrator import state_is_finite
from .periodic_steps import wrap_work
from .rigid import body_poses, omega_world
from .step import (L_DISS_N, L_EXTERNAL, book_terms, interfaces_defined, kick_part,
                   spun_contacts, step_start)
from .stepcontrol import ALTERNATION_STEPS


@dataclass(frozen=True)
class Kinematics:
    """What a contact provider is given (SI units, world frame).

    t (s); x (N,3) centroids; R (N,3,3) file->world rotations; pose_origin (N,3) where each
    shape's file origin lies (x − R c with c the centroid in the file frame,
    docs/conventions.md: the pose the contact kernels take); v (N,3) and omega (N,3)
    velocities (the half-step values of the integrator); wall_displacement, wall_velocity
    (W,3); n_particles N, n_bodies N+W.
    """

    t: float
    x: np.ndarray
    R: np.ndarray
    pose_origin: np.ndarray
    v: np.ndarray
    omega: np.ndarray
    wall_displacement: np.ndarray
    wall_velocity: np.ndarray
    n_particles: int
    n_bodies: int


class ContactProvider(Protocol):
    def __call__(self, kin: Kinematics) -> Any:  # a ContactSet (docs/conventions.md) or None
        ...


class _Unstable(Exception):
    pass


def _unpack(cs: Any, n_bodies: int):
    """Contiguous typed arrays from a ContactSet (duck-typed, docs/conventions.md); None or
    K=0 -> empty."""
    if cs is None or len(np.asarray(cs.body_a)) == 0:
        e3 = np.zeros((0, 3))
        ei = np.zeros(0, dtype=np.int64)
        return ei, ei.copy(), e3, e3.copy(), e3.copy(), np.zeros(0), ei.copy()
    a = np.ascontiguousarray(cs.body_a, dtype=np.int64)
    b = np.ascontiguousarray(cs.body_b, dtype=np.int64)
    key = getattr(cs, "key", None)
    key = a * n_bodies + b if key is None else np.ascontiguousarray(key, dtype=np.int64)
    return (a, b, np.ascontiguousarray(cs.point_a, dtype=float),
            np.ascontiguousarray(cs.point_b, dtype=float),
            np.ascontiguousarray(cs.normal, dtype=float),
            np.ascontiguousarray(cs.depth, dtype=float), key)


class InternalSteps:
    """The internal steps of one deck step driven from Python, one provider call each (a base
    class of :class:`~nurbsdem.dynamics.system.DemSystem`): what runs on several MPI ranks,
    with the curved or turning walls the compiled loop does not take, and the deck steps the
    compiled loop hands back (:mod:`nurbsdem.dynamics.deck_steps`): the step's start (half
    kick with its exact work, the period-2 watch, drift), the provider's contacts, the contact
    part (paper Eq. 16–17) and the second half kick, the compiled loop's parts in its order."""

    def _kinematics(self, t: float) -> Kinematics:
        b = self.bodies
        R, position = body_poses(b.q, b.P, b.x, b.centroid_file)
        return Kinematics(t=t, x=b.x.copy(), R=R, pose_origin=position, v=b.v.copy(),
                          omega=omega_world(b.q, b.L, self._inv_I),
                          wall_displacement=self.wall_d.copy(), wall_velocity=self.wall_u.copy(),
                          n_particles=b.n, n_bodies=self.n_bodies)

    def _all_kinematics(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Positions, velocities and angular velocities (B,3) of particles then walls."""
        b = self.bodies
        pos = np.concatenate([b.x, self.wall_d])
        vel = np.concatenate([b.v, self.wall_u])
        omg = np.concatenate([omega_world(b.q, b.L, self._inv_I), np.zeros((self.walls.n, 3))])
        if self.wall_spin is not None:   # a turning wall: its points move at u + ω × (p − c − d)
            pos[b.n:] += self.wall_spin[:, 3:]
            omg[b.n:] = self.wall_spin[:, :3]
        return pos, vel, omg

    def _spun_contacts(self, wall_u: np.ndarray) -> tuple:
        """(body_b, wall_d, wall_u, wall_w) for the kick's work terms when walls turn: each
        contact with a turning wall gets a wall of its own (index W + j) that moves at that
        wall's point velocity and turns at its angular velocity
        (:func:`~nurbsdem.dynamics.step.spun_contacts`)."""
        c = self.contacts
        return spun_contacts(c.a, c.b, np.ascontiguousarray(c.point, float),
                             self.bodies.n, np.ascontiguousarray(self.wall_spin, float),
                             np.ascontiguousarray(self.wall_d, float), wall_u)

    def _evaluate(self, t: float, h: float) -> None:
        """Walls to time t, contact detection by the provider, then the internal step's contact
        part (:func:`~nurbsdem.dynamics.step.contact_part`: Eq. 16–17 or Hertz–Mindlin, the
        implicit dashpots, gravity); with MPI the owners' loads of this rank's ghosts."""
        b = self.bodies
        t0 = time.perf_counter()
        self.wall_d, self.wall_u = self.walls.kinematics(t)
        kinematics = self._kinematics(t)
        t1 = time.perf_counter()
        cs = self.provider(kinematics)          # the search and the LCPs (the scene's timers)
        t2 = time.perf_counter()
        self.last_contacts = cs
        self._book_dropped(cs)
        self._apply_wrap(cs)
        a, bb, pa, pb, nrm, dep, key = _unpack(cs, self.n_bodies)
        K = a.shape[0]
        if K and not interfaces_defined(self._bc, a, bb):
            raise InputError("a contact occurred between materials with no contact interface")
        pos, vel, omg = self._all_kinematics()
        if self.needs_radius:   # the contacts' exact curvature radii (Hertz, rolling)
            from ..geometry.curvature import contact_radii_for
            radius, self.hertz_fallback = contact_radii_for(self.provider, cs, b, K)
        else:
            radius = np.zeros(K)
        solves = np.zeros(4, np.int64)
        dashpot = np.zeros(0)
        image = getattr(cs, "image", None)
        image = (np.ascontiguousarray(image, float) if image is not None and len(image) == K
                 else np.zeros((K, 3)))
        if self.implicit_damping and h > 0.0 and self.domain is not None:
            dashpot = self.domain.implicit_dashpots(
                a, bb, pa, pb, nrm, dep, key, radius, h, solves,
                image if self.domain.periodic else None)
        im = ImageBodies.of(b.n, bb, image)
        bc, b_part, q, L = self._bc, bb, b.q, b.L
        if im is not None:                   # contacts with periodic images (.images)
            bc, b_part, q, L = im.const(bc), im.b, im.particles(q), im.particles(L)
            pos, vel, omg = im.bodies(pos, True), im.bodies(vel), im.bodies(omg)
        (force, torque, point, ftot, fdn, fdt, fet, fn, eel, stick, coeffs,
         self.last_slip_work, keys, springs, repeated) = self._kernels.contact_part(
             bc, self.implicit_damping, a, b_part, pa, pb, nrm, dep, key, radius,
             self.hist_keys, self.hist_springs, pos, vel, omg, q, L, h, solves, dashpot,
             np.zeros(0, np.int64) if im is None else im.own)
        if im is not None:
            force, torque = im.fold(force), im.fold(torque)
        if repeated:
            raise ValueError("ContactSet has duplicate keys: one contact per body pair expected")
        self.hist_keys, self.hist_springs = keys, springs
        dashpots = float(solves[3]) * seconds_per_cycle()
        self.dashpot_solves += solves[:3]
        self.split["implicit dashpots"] += dashpots
        if self.domain is not None:          # the owners' loads of this rank's ghosts
            self.domain.exchange_loads(force, torque)
        self.force, self.torque = force, torque
        self.contacts = ContactState(a, bb, key, point, nrm, ftot, fdn, fdt, fet, fn, eel, stick,
                                     coeffs, radius, image)
        self.split["contact forces"] += (t1 - t0) + (time.perf_counter() - t2) - dashpots

    def _apply_wrap(self, cs: Any) -> None:
        """The wrap into the periodic cell that the provider's list build made (its
        ``wrap`` (N,3) m, :class:`~nurbsdem.contact.contactset.ContactSet`), applied to the
        centroids.  The potential's jump Σ m g·Δx (J; Δx the translation taken off,
        :func:`~nurbsdem.dynamics.periodic_steps.wrap_work`, as the compiled loop) is booked
        as external work, as an inlet's particles are (:mod:`nurbsdem.flow_run`), so that the
        balance stays closed; at the first evaluation, before the initial mechanical energy
        is taken, it is kept in ``initial_wrap_work`` for the run's ledger
        (:meth:`~nurbsdem.energy_ledger.EnergyLedger.book_external`)."""
        shift = getattr(cs, "wrap", None)
        if shift is None or len(shift) == 0 or not np.any(shift != 0.0):
            return
        b = self.bodies
        jump = wrap_work(b.mass, np.ascontiguousarray(shift, float),
                         np.ascontiguousarray(self.gravity, float))
        b.x -= shift
        if self.initial_mechanical != self.initial_mechanical:   # NaN
            self.initial_wrap_work += jump
        elif self.domain is None or self.domain.books():   # every rank takes the same wrap
            self._book(L_EXTERNAL, np.array([jump]))

    def _images(self) -> "ImageBodies | None":
        """The image bodies of the stored contacts (:mod:`nurbsdem.dynamics.images`)."""
        return ImageBodies.of(self.bodies.n, self.contacts.b, self.contacts.image)

    def _book_dropped(self, cs: Any) -> None:
        """A pair the provider left out after a failed contact problem takes its normal elastic
        energy with it: book it as dissipated (normal), so the energy balance stays closed
        (several MPI ranks: each its counted pairs')."""
        dropped = getattr(cs, "dropped_keys", None)
        if dropped is None or len(dropped) == 0:
            return
        c = self.contacts
        gone = np.isin(c.key, dropped)
        if self.domain is not None:
            gone &= self.domain.counted(c.a)
        if gone.any():
            self._book(L_DISS_N, np.ascontiguousarray(c.eel[gone, 0], float))

    def _book(self, row: int, amounts: np.ndarray) -> None:
        """Book the amounts (J) exactly in the ledger's accumulator ``row``
        (:func:`~nurbsdem.dynamics.step.book_terms`)."""
        book_terms(self.exact_ledger, row, amounts)

    def _counted(self) -> np.ndarray:
        """The stored contacts whose kicks' work this rank books (:meth:`Domain.counted
        <nurbsdem.parallel.domain.Domain.counted>`); empty on one rank: every contact."""
        if self.domain is None:
            return np.zeros(0, np.bool_)
        return self.domain.counted(self.contacts.a)

    def _kick_walls(self, u_mean: np.ndarray) -> tuple:
        """(body_b, wall_d, wall_u, wall_w) of the stored contacts for a half kick's work
        terms: the walls' mean velocity over the internal step, u_mean (W,3) = (d(t+h) −
        d(t))/h, so that the external work adds up to force × the walls' exact displacement
        (trapezoidal in the force, no error at kinks of a piecewise-linear motion), and their
        angular velocities (zero); a turning wall's contacts at its point velocities and
        spin (:meth:`_spun_contacts`)."""
        if self.wall_spin is not None and self.contacts.a.shape[0]:
            return self._spun_contacts(np.ascontiguousarray(u_mean))
        return (self.contacts.b, self.wall_d, np.ascontiguousarray(u_mean),
                np.zeros((self.walls.n, 3)))

    def _kick_arguments(self, im: "ImageBodies | None" = None) -> tuple:
        """The stored contacts' arrays and loads as the step's parts take them (with image
        bodies ``im``: theirs too, each image loaded as its owner)."""
        c = self.contacts
        if im is not None:
            return (im.const(self._bc), c.a, im.b, c.point, c.ftot, c.fdn, c.fdt, c.fet,
                    im.bodies(self.force), im.bodies(self.torque))
        return self._bc, c.a, c.b, c.point, c.ftot, c.fdn, c.fdt, c.fet, self.force, self.torque

    def _internal_step(self, t_new: float, h: float) -> None:
        """One internal step of length h (s) ending at t_new (s): the parts of
        :mod:`nurbsdem.dynamics.step` around the provider's contact search."""
        b = self.bodies
        d_new, _ = self.walls.kinematics(t_new)
        u_mean = (d_new - self.wall_d) / h
        t0 = time.perf_counter()
        im = self._images()
        if im is not None:
            worst, run = self._step_start_images(im, u_mean, h)
        else:
            _, worst, run = step_start(
                *self._kick_arguments(), b.x, b.v, b.q, b.L, omega_world(b.q, b.L, self._inv_I),
                *self._kick_walls(u_mean), h, self.exact_ledger, self._counted(),
                self.alt_prev_v, self.alt_prev_L, self.alt_count, self.watch_period2)
        self._watch_alternation(int(worst), int(run), h)
        t1 = time.perf_counter()
        self._evaluate(t_new, h)
        t2 = time.perf_counter()
        im = self._images()
        if im is not None:
            v, L = im.particles(b.v), im.particles(b.L)
            kick_part(*self._kick_arguments(im), im.positions(b.x), v, im.particles(b.q), L,
                      omega_world(im.particles(b.q), L, im.particles(self._inv_I)), im.b,
                      self.wall_d, np.ascontiguousarray(u_mean), np.zeros((self.walls.n, 3)),
                      0.5 * h, self.exact_ledger, self._counted())
            b.v[:], b.L[:] = v[:b.n], L[:b.n]
        else:
            kick_part(*self._kick_arguments(), b.x, b.v, b.q, b.L,
                      omega_world(b.q, b.L, self._inv_I),   # ghosts may be re-synced
                      *self._kick_walls(u_mean), 0.5 * h, self.exact_ledger, self._counted())
        self.split["integration"] += (t1 - t0) + (time.perf_counter() - t2)

    def _step_start_images(self, im: "ImageBodies", u_mean: np.ndarray,
                           h: float) -> tuple[int, int]:
        """:func:`~nurbsdem.dynamics.step.step_start` with the stored contacts' image bodies
        (walls that do not turn): the particles and their images kicked, watched and
        drifted together, the particles' rows kept.  Returns (worst, run) as step_start
        does, ``worst`` an owner."""
        b, n = self.bodies, self.bodies.n
        x, v, q, L = (im.positions(b.x), im.particles(b.v), im.particles(b.q),
                      im.particles(b.L))
        pv, pL, count = (im.particles(a) for a in (self.alt_prev_v, self.alt_prev_L,
                                                     self.alt_count))
        _, worst, run = step_start(
            *self._kick_arguments(im), x, v, q, L, omega_world(q, L, im.particles(self._inv_I)),
            im.b, self.wall_d, np.ascontiguousarray(u_mean), np.zeros((self.walls.n, 3)), h,
            self.exact_ledger, self._counted(), pv, pL, count, self.watch_period2)
        b.x[:], b.v[:], b.q[:], b.L[:] = x[:n], v[:n], q[:n], L[:n]
        self.alt_prev_v[:], self.alt_prev_L[:], self.alt_count[:] = pv[:n], pL[:n], count[:n]
        worst = int(worst)
        return (int(im.own[worst - n]) if worst >= n else worst), int(run)

    def _watch_alternation(self, worst: int, run: int, h: float) -> None:
        """The period-2 guard (:mod:`nurbsdem.dynamics.system`) on the watch of the step's start:
        the particle ``worst`` with the longest run of reversals (−1: none), over all ranks."""
        b = self.bodies
        if b.n == 0 or not self.watch_period2:
            return
        amp = float(np.linalg.norm(b.v[worst])) * h if worst >= 0 else 0.0
        if self.domain is not None:
            worst, run, amp = self.domain.worst_alternation(worst, run, amp)
        if worst >= 0 and run >= ALTERNATION_STEPS:
            raise _Unstable(f"period-2 motion of particle {worst}: its motion reversed at each "
                            f"of the last {run} internal steps (displacement "
                            f"{amp:.3g} m per step), a mode beyond the stability limit")

    def _try_step(self) -> EnergySample:
        """The internal steps of one deck step and the guards; raises _Unstable."""
        t_start = self.time
        n = self.substeps * self.acc_refine
        h = self.dt / n
        self.failed_in_step = 0
        if self.domain is not None:
            self.domain.begin_deck_step()
        for k in range(1, n + 1):
            t_new = t_start + self.dt * k / n
            with np.errstate(all="ignore"):
                self._internal_step(t_new, h)
            self.failed_in_step += int(getattr(self.last_contacts, "failed", 0) or 0)
            b = self.bodies
            finite = state_is_finite(b.x, b.v, b.q, b.L) and bool(np.isfinite(self.force).all())
            if self.domain is not None:
                finite = self.domain.all(finite)
            if not finite:
                raise _Unstable(f"non-finite state at t = {t_new:.6g} s")
        self.step_count += 1
        if self.domain is not None:
            self.domain.end_of_deck_step()     # every rank: the serial state
        e = self.energy()
        self._check_energy(e)
        return e

"""The time-step control of a DEM system: the sub-step count of each deck step.

See :mod:`nurbsdem.dynamics.system` for the method (the a-priori estimate over the possible
pairs and the contact network's estimate, Eq. (1) of :mod:`nurbsdem.dynamics.stepcontrol`);
the compiled kernels it calls live in :mod:`nurbsdem.dynamics.stepcontrol`.  Units: SI.
"""
from __future__ import annotations

import logging
import math
import time
from dataclasses import dataclass

import numpy as np

from ..errors import InputError
from .laws.table import CN, CT, EN, ET
from .rigid import omega_world
from .stepcontrol import (FALL_HYSTERESIS, HEAVY_SUBSTEPS, NETWORK_BOUND_SLACK,
                          NETWORK_RECHECK_STEPS, body_speeds, contact_network, critical_step,
                          critical_step_from_rates, needed_substeps, network_count_stands,
                          network_gershgorin, network_rates, periodic_recheck)

log = logging.getLogger("nurbsdem")

@dataclass(frozen=True)
class ModeLimit:
    """Critical step of one contact mode: interface (mat_a, mat_b, 'pp'|'pw'), 'normal'|'tangential'."""

    interface: tuple
    mode: str
    m_eff: float
    omega: float
    zeta: float
    dt_cr: float


def _smallest_pair(m_i: np.ndarray, m_j: np.ndarray | None) -> float:
    """Smallest reduced mass of a pair drawn from m_i (same group: two distinct) and m_j."""
    if m_j is None:
        if m_i.size < 2:
            return math.inf
        s = np.sort(m_i)
        return float(s[0] * s[1] / (s[0] + s[1]))
    if m_i.size == 0 or m_j.size == 0:
        return math.inf
    a, b = float(m_i.min()), float(m_j.min())
    return a * b / (a + b)


class SubstepControl:
    """The time-step control of a :class:`~nurbsdem.dynamics.system.DemSystem` (a base class
    of it; see that module's docstring): the a-priori critical step over the possible pairs,
    the contact network's bound and exact estimate, and the choice of the sub-step count with
    its log, warning or error.  It reads the system's bodies, interface table and last
    evaluation and sets ``substeps``, ``dt_internal``, ``dt_apriori``, ``dt_bound``,
    ``dt_network`` and ``dt_critical`` (s)."""

    #: the exact estimate the compiled deck steps took before returning for a change of the
    #: count (:data:`~nurbsdem.dynamics.deck_steps.CONTROL`): (deck step, Gershgorin bound s,
    #: ω² 1/s², γ 1/s, the mode's body), taken by the next :meth:`_control_step` of that deck
    #: step instead of the same estimate again; None otherwise
    loop_rates: tuple | None = None
    #: the control's state (:meth:`control_state`) of the system this one replaces within a
    #: running step (inlets and outlets changed the particles, :mod:`nurbsdem.flow_run`);
    #: None: a fresh start
    carried_control: tuple | None = None

    def critical_time_step(self) -> tuple[float, list[ModeLimit]]:
        """Estimated explicit critical step (s) over every possible interface and mode (module
        docstring), and the per-mode details."""
        b = self.bodies
        mats_p = sorted(set(int(m) for m in b.material))
        mats_w = sorted(set(int(m) for m in self.walls.material))
        m_n, m_t = self._effective_masses()
        limits: list[ModeLimit] = []
        pairs = []
        for i, ma in enumerate(mats_p):
            for mb in mats_p[i:]:
                pairs.append(((ma, mb, "pp"), ma, mb, False))
            for mw in mats_w:
                pairs.append(((ma, mw, "pw"), ma, mw, True))
        for iface, ma, mb, wall in pairs:
            sel_a = b.material == ma
            if wall:
                mn, mtn = float(m_n[sel_a].min()), float(m_t[sel_a].min())
            elif ma == mb:
                mn, mtn = _smallest_pair(m_n[sel_a], None), _smallest_pair(m_t[sel_a], None)
            else:
                sel_b = b.material == mb
                mn = _smallest_pair(m_n[sel_a], m_n[sel_b])
                mtn = _smallest_pair(m_t[sel_a], m_t[sel_b])
            if not math.isfinite(mn):
                continue          # no such pair can occur (e.g. a single particle)
            try:
                law = self.interfaces.get(ma, mb)
            except InputError:
                continue          # undefined interface: an error if such a contact ever occurs
            row = law.as_row()      # its EN..CT columns: the law's linearisation
            cn = 0.0 if self.implicit_damping else float(row[CN])
            for mode, k, c, m in (("normal", float(row[EN]), cn, mn),
                                  ("tangential", float(row[ET]), float(row[CT]), mtn)):
                if not math.isfinite(m):
                    continue
                w, z, dtc = critical_step(k, c, m)
                limits.append(ModeLimit(iface, mode, m, w, z, dtc))
        dt_cr = min((lim.dt_cr for lim in limits), default=math.inf)
        return dt_cr, limits

    def _effective_masses(self) -> tuple[np.ndarray, np.ndarray]:
        """(N,) worst normal and tangential effective masses (kg) of each particle's contacts."""
        b = self.bodies
        r = b.radius
        rot = np.where(r > 0, r * r / b.I[:, 0], 2.5 / b.mass)      # r²/I_min (sphere if unknown)
        g_n = 1.0 / b.mass
        g_t = 1.0 / b.mass + rot
        for i, g in enumerate(self._compliance):
            if g is not None:
                g_n[i], g_t[i] = g
        return 1.0 / g_n, 1.0 / g_t

    def _apriori_limit(self) -> None:
        """The a-priori critical step over the possible pairs (computed once per system)."""
        self.dt_apriori, self.mode_limits = self.critical_time_step()
        worst = min(self.mode_limits, key=lambda m: m.dt_cr) if self.mode_limits else None
        self._apriori_why = (
            f"{worst.mode} mode of interface {worst.interface} (m*={worst.m_eff:.4g} kg, "
            f"omega={worst.omega:.4g} rad/s, zeta={worst.zeta:.3g})") if worst else "no contact modes"
        self._apriori_zeta = worst.zeta if worst else 0.0

    def _network(self):
        """The contacts of the last evaluation plus the separated pairs that can close within
        one deck step (:func:`~nurbsdem.dynamics.stepcontrol.contact_network`): (a, b, point,
        normal, coeffs (K,4)), or None when there is none.  The contacts keep their own
        (tangent) coefficients from the force evaluation (Hertz: they grow with the overlap)."""
        c = self.contacts
        a, bb = c.a, c.b
        k = a.shape[0]
        coeffs = c.coeffs
        if coeffs.ndim != 2 or coeffs.shape[0] != k:
            coeffs = np.ascontiguousarray(self._table[self._mat_all[a], self._mat_all[bb]][:, :4])
        cs = self.last_contacts
        if getattr(cs, "near_gap", None) is not None and len(cs.near_gap):
            near = (np.asarray(cs.near_a, np.int64), np.asarray(cs.near_b, np.int64),
                    np.asarray(cs.near_point, float), np.asarray(cs.near_normal, float),
                    np.asarray(cs.near_gap, float))
        else:
            near = (np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros((0, 3)),
                    np.zeros((0, 3)), np.zeros(0))
        b = self.bodies
        speed = body_speeds(b.v, omega_world(b.q, b.L, self._inv_I), self._ell, self.wall_u)
        net = contact_network(a, bb, c.point, c.normal, coeffs, *near, speed, self.dt,
                              self._g_norm, self._table, self._mat_all)
        self._net_image = self._network_images(net, cs)
        if self.implicit_damping:
            net[4][:, 1] = 0.0      # implicit normal dashpots do not limit the step
        return net if net[0].shape[0] else None

    def _network_images(self, net, cs) -> tuple:
        """(image,): the translation (K,3) m of the periodic image of B for each pair of the
        network (:mod:`nurbsdem.contact.periodic`; zeros where no pair touches an image, which
        subtract nothing from a lever arm), as the network's kernels take it: always given,
        as the compiled loop gives it, so that both call the same compiled kernels."""
        near_image = getattr(cs, "near_image", None)
        c = self.contacts
        image = c.image
        if near_image is None or not (np.any(image != 0.0) or np.any(near_image != 0.0)):
            return (np.zeros((net[0].shape[0], 3)),)
        nb = self.n_bodies
        keys = np.concatenate([c.a * nb + c.b,
                               np.asarray(cs.near_a, np.int64) * nb + np.asarray(cs.near_b)])
        table = np.concatenate([image, near_image])
        order = np.argsort(keys)
        rows = order[np.searchsorted(keys[order], net[0] * nb + net[1])]
        return (np.ascontiguousarray(table[rows]),)

    def _network_bound(self, net) -> float:
        """A lower bound (s) of the network's critical step, from the Gershgorin bounds of its
        frequency and damping rate (O(K), every deck step)."""
        if net is None:
            return math.inf
        b = self.bodies
        omega2, gamma = network_gershgorin(*net, b.x, b.principal_rotations(), self._inv_mass,
                                           self._inv_I, False,   # the compiled loop's types
                                           *self._net_image)
        return critical_step_from_rates(omega2, gamma)

    def _count_stands(self, net) -> bool:
        """The gate: whether the present sub-step count stands without the exact estimate
        (:func:`~nurbsdem.dynamics.stepcontrol.network_count_stands`; no network: it does)."""
        if net is None:
            return True
        b = self.bodies
        return bool(network_count_stands(*net, b.x, b.principal_rotations(), self._inv_mass,
                                         self._inv_I, self.dt, self.safety, self.dt_apriori,
                                         self.dt_bound, NETWORK_BOUND_SLACK, self.refine,
                                         self.substeps, *self._net_image))

    def _network_limit(self, net, rates=None) -> tuple[float, str]:
        """Critical step (s) of the network ``net`` (:meth:`_network`) by Lanczos, and why;
        ``rates``: the compiled loop's estimate of this network (:attr:`loop_rates`), taken
        instead of computing it again."""
        if net is None:
            return math.inf, "no contacts"
        b = self.bodies
        a, bb, p, n, coeffs = net
        if rates is not None:
            omega2, gamma, body = rates[2], rates[3], rates[4]
        else:
            args = (a, bb, p, n, coeffs, b.x, b.principal_rotations(), b.mass, b.I,
                    *self._net_image)
            omega2, gamma, body = (network_rates(*args) if self.domain is None
                                   else self.domain.on_root(network_rates, *args))
        dt = critical_step_from_rates(omega2, gamma)
        self._network_zeta = gamma / (2.0 * math.sqrt(omega2)) if omega2 > 0 else 0.0
        n_contacts = int(np.count_nonzero(a == body) + np.count_nonzero(bb == body))
        why = (f"contact network of {a.shape[0]} pairs ({self.contacts.a.shape[0]} in contact): "
               f"highest frequency {math.sqrt(omega2):.4g} rad/s, damping rate {gamma:.4g} 1/s, "
               f"centred on particle {body} with {n_contacts} contacts")
        return dt, why

    def _needed_substeps(self, dt_safe: float) -> int:
        """Sub-steps that keep the internal step within the safe step dt_safe (s)."""
        return int(needed_substeps(self.dt, dt_safe))

    def control_state(self) -> tuple:
        """What a system built anew for the same running step carries over of the control
        (:attr:`carried_control`): the sub-steps, the guard's refinement and calm count, and
        the a-priori, bound, network and critical steps (s)."""
        return (self.substeps, self.refine, self.calm_steps, self.dt_apriori, self.dt_bound,
                self.dt_network, self.dt_critical)

    def _first_control_step(self) -> None:
        """The control step of :meth:`initialize`: the exact estimate, or, for a system that
        replaces another within a running step (:attr:`carried_control`), that system's
        state taken over and the ordinary gated control step, as if the run had gone on in
        one system: the Gershgorin gate decides whether the new network needs the exact
        estimate again (the particles an inlet adds are placed apart; those an outlet takes
        away soften the network).  A fresh start when the new bodies allow a smaller a-priori
        step (a new, lighter kind of particle) or the count is forced.  A checkpoint holds
        the control's state, so a restart continues with the same bits either way."""
        carried = self.carried_control
        if (carried is None or self.forced_substeps is not None
                or self.dt_apriori < carried[3]):
            self._control_step(initial=True)
            return
        (self.substeps, self.refine, self.calm_steps, _, self.dt_bound, self.dt_network,
         self.dt_critical) = carried
        self.dt_internal = self.dt / self.substeps
        self._control_step()

    def _control_step(self, initial: bool = False) -> None:
        """Choose the sub-steps of the next deck step from both limits (module docstring);
        its time is added to ``split``."""
        if not initial and self.forced_substeps is not None:
            return
        t0 = time.perf_counter()
        try:
            self._choose_substeps(initial)
        finally:
            self.split["time-step control"] += time.perf_counter() - t0

    def _choose_substeps(self, initial: bool) -> None:
        """:meth:`_control_step` (the sub-step count and its log or error)."""
        rates, self.loop_rates = self.loop_rates, None
        net = self._network()
        if not initial and not periodic_recheck(self.step_count, NETWORK_RECHECK_STEPS,
                                                self.refine, FALL_HYSTERESIS, self.substeps):
            if self._count_stands(net):
                return      # no stiffer than at the last exact estimate, or allowed anyway
        if rates is not None and (initial or rates[0] != self.step_count or net is None):
            rates = None
        self.dt_bound = self._network_bound(net) if rates is None else rates[1]
        self.dt_network, net_why = self._network_limit(net, rates)
        self.network_estimates += 1
        self.dt_critical = min(self.dt_apriori, self.dt_network)
        dt_safe = self.safety * self.dt_critical
        why = (f"critical step {self.dt_critical:.3g} s from the "
               + (self._apriori_why if self.dt_apriori <= self.dt_network else net_why)
               + f", safety {self.safety}")
        if self.forced_substeps is not None:
            self.substeps = self.forced_substeps
            self.dt_internal = self.dt / self.substeps
            if self.dt_internal > dt_safe:
                log.warning("substeps forced to %d: internal step %.3g s exceeds the safe step "
                            "%.3g s (%s)", self.substeps, self.dt_internal, dt_safe, why)
            log.info("time step: deck dt %.4g s, %d sub-step(s) of %.4g s (forced); %s", self.dt,
                     self.substeps, self.dt_internal, why)
            return
        need = self._needed_substeps(dt_safe) * self.refine
        if need > self.max_substeps:
            raise InputError(f"time step {self.dt} s would need {need} sub-steps "
                             f"(> {self.max_substeps}); {why}")
        old = self.substeps
        if initial or need > old or need < FALL_HYSTERESIS * old:
            self.substeps = need
        self.dt_internal = self.dt / self.substeps
        if self.substeps >= HEAVY_SUBSTEPS and not self._warned_heavy:
            self._warned_heavy = True
            self._warn_heavy(why)
        if initial:
            log.info("time step: deck dt %.4g s, %d sub-step(s) of %.4g s; %s", self.dt,
                     self.substeps, self.dt_internal, why)
        elif self.substeps != old:
            log.info("time step at t = %.6g s: %d -> %d sub-step(s) of %.4g s (%s); %s",
                     self.time, old, self.substeps, self.dt_internal,
                     "the contact network stiffened" if self.substeps > old else "the pack loosened",
                     why + (f", refined x{self.refine} by the guard" if self.refine > 1 else ""))

    def _warn_heavy(self, why: str) -> None:
        """One warning per system when the deck step is sub-stepped heavily: what limits the
        step and what the user could change (like LIGGGHTS' and Yade's step-size warnings)."""
        zeta = self._apriori_zeta if self.dt_apriori <= self.dt_network else self._network_zeta
        if zeta > 1.0:
            lever = (f"the damping limits it (zeta {zeta:.3g} > 1: the dashpots' rate, not the "
                     f"springs, sets the step): less damping (NormalDamping / TangentialDamping; "
                     f"Hertz-Mindlin: a higher Restitution) would allow a larger one"
                     + ("" if self.implicit_damping else
                        ", and so would implicit normal dashpots (Damping Implicit on the step, "
                        "with Accuracy to keep impacts accurate)"))
        else:
            lever = ("the stiffness limits it: softer contacts (NormalPenalty / "
                     "TangentialPenalty; Hertz-Mindlin: YoungModulus) or heavier particles would "
                     "allow a larger one")
        log.warning("the time step %.4g s is sub-stepped %d times (internal step %.4g s, "
                    "%.2f of the critical step): %s; %s", self.dt, self.substeps,
                    self.dt_internal, self.dt_internal / self.dt_critical, lever, why)
